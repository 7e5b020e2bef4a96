"""GAT block, masked softmax, pooling: padded tables against the scatter reference."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="cloth_usd.nn needs torch (pip install 'cloth-usd[train]')")

from meshes import grid, icosphere  # noqa: E402

from cloth_usd.core.graph import build_graph, directed_edges, neighbour_table  # noqa: E402
from cloth_usd.nn.layers import (  # noqa: E402
    GATBlock,
    gat_scatter_reference,
    masked_softmax,
    pool_mean,
    unpool,
)


def _tables(faces, pos, k_max=16):
    edges = directed_edges(faces, len(pos))
    table = neighbour_table(edges, len(pos), positions=pos, k_max=k_max)
    return edges, torch.from_numpy(table.nbr), torch.from_numpy(table.mask)


@pytest.mark.parametrize("mesh", [grid(6, 5), icosphere(1)], ids=["grid", "icosphere"])
def test_gat_padded_equals_scatter(mesh):
    torch.manual_seed(0)
    faces, pos = mesh
    edges, nbr, mask = _tables(faces, pos)
    block = GATBlock(5, 6, 3, 4)
    x = torch.randn(2, len(pos), 5, dtype=torch.float64)
    block = block.double()
    got = block(x, nbr, mask)
    ref = gat_scatter_reference(block, x, torch.from_numpy(edges))
    assert got.shape == (2, len(pos), 6 + 3 * 4)
    torch.testing.assert_close(got, ref, atol=1e-12, rtol=1e-10)


def test_gat_capped_table_equals_scatter_on_kept_edges():
    torch.manual_seed(1)
    k = np.arange(20)
    pos = np.concatenate([[[0, 0, 0]], np.stack([np.cos(k), np.sin(k), k / 100.0], 1)])
    faces = np.stack([np.zeros(20, int), 1 + k, 1 + (k + 1) % 20], 1)
    _, nbr, mask = _tables(faces, pos, k_max=16)
    kept = torch.stack([torch.arange(len(pos))[:, None].expand_as(nbr)[mask], nbr[mask]], 1)
    block = GATBlock(4, 4, 2, 3).double()
    x = torch.randn(1, len(pos), 4, dtype=torch.float64)
    torch.testing.assert_close(block(x, nbr, mask), gat_scatter_reference(block, x, kept))


def test_isolated_vertex_output_is_finite_and_self_only():
    torch.manual_seed(2)
    faces, pos = np.array([[0, 1, 2]]), np.eye(4, 3)
    _, nbr, mask = _tables(faces, pos)
    block = GATBlock(3, 4, 2, 2)
    x = torch.randn(2, 4, 3)
    out = block(x, nbr, mask)
    assert torch.isfinite(out).all()
    torch.testing.assert_close(out[:, 3, 4:], block.bias.expand(2, 4))  # aggregates nothing


def test_masked_softmax_rows():
    scores = torch.tensor([[1.0, 2.0, 3.0], [5.0, -1e30, 7.0], [1.0, 2.0, 3.0]])
    mask = torch.tensor([[True, True, False], [True, False, True], [False, False, False]])
    w = masked_softmax(scores, mask, dim=1)
    torch.testing.assert_close(w[0], torch.tensor([1 / (1 + np.e), np.e / (1 + np.e), 0.0]))
    assert w[1, 1] == 0 and torch.isclose(w[1].sum(), torch.tensor(1.0))
    assert (w[2] == 0).all()


def test_masked_softmax_extreme_scores_stay_finite():
    scores = torch.tensor([[1e30, -1e30, 3e38], [-3e38, -3e38, 0.0]])
    w = masked_softmax(scores, torch.ones(2, 3, dtype=torch.bool), dim=1)
    assert torch.isfinite(w).all()
    torch.testing.assert_close(w.sum(1), torch.ones(2))


def test_gat_extreme_inputs_finite():
    torch.manual_seed(3)
    faces, pos = grid(5, 4)
    _, nbr, mask = _tables(faces, pos)
    block = GATBlock(3, 4, 2, 4)
    out = block(1e4 * torch.randn(2, len(pos), 3), nbr, mask)
    assert torch.isfinite(out).all()


def test_pool_then_unpool():
    faces, pos = grid(6, 6)
    pool = build_graph(faces, pos).pooling
    x = torch.randn(2, len(pos), 3, dtype=torch.float64)
    members, members_mask = torch.from_numpy(pool.members), torch.from_numpy(pool.members_mask)
    cluster = torch.from_numpy(pool.cluster)
    pooled = pool_mean(x, members, members_mask)
    ref = torch.zeros(2, pool.members.shape[0], 3, dtype=torch.float64).index_add_(1, cluster, x)
    ref /= torch.bincount(cluster).to(x.dtype)[:, None]
    torch.testing.assert_close(pooled, ref)
    back = unpool(pooled, cluster)
    assert back.shape == x.shape
    torch.testing.assert_close(back, ref[:, cluster])
