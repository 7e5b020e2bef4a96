"""GAT block, padded table, softmax over slots, pooling: padded tables against the scatter reference."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="cloth_usd.nn needs torch (pip install 'cloth-usd[train]')")

from meshes import grid, icosphere  # noqa: E402

from cloth_usd.core.graph import build_graph, directed_edges, neighbour_table  # noqa: E402
from cloth_usd.nn.layers import (  # noqa: E402
    GATBlock,
    EXP_FLOOR,
    MASKED_LOGIT,
    gat_scatter_reference,
    pad_table,
    pool_mean,
    slot_softmax,
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


def test_pad_table_points_masked_slots_at_the_pad_node():
    nbr = torch.tensor([[1, 2, 0], [0, 0, 0], [1, 0, 0]])
    mask = torch.tensor([[True, True, False], [False, False, False], [True, False, False]])
    assert pad_table(nbr, mask, 3).tolist() == [[1, 2, 3], [3, 3, 3], [1, 3, 3]]


def test_slot_softmax_rows():
    scores = torch.tensor([[1.0, 2.0], [5.0, 7.0], [0.0, MASKED_LOGIT]])
    w = slot_softmax(scores, dim=1)
    torch.testing.assert_close(w[0], torch.tensor([1 / (1 + np.e), np.e / (1 + np.e)]))
    torch.testing.assert_close(w.sum(1), torch.ones(3))
    assert w[2, 0] == 1.0 and 0 < w[2, 1] <= np.exp(-EXP_FLOOR)  # floored: tiny, never an underflowing exp


def test_slot_softmax_along_slots_of_a_slot_major_tensor():
    torch.manual_seed(4)
    scores = torch.randn(2, 5, 7, 3, dtype=torch.float64)  # (B, K, N, H)
    torch.testing.assert_close(slot_softmax(scores, dim=1), torch.softmax(scores, dim=1))


def test_slot_softmax_extreme_scores_stay_finite():
    scores = torch.tensor([[1e30, -1e30, 3e38], [-3e38, -3e38, 0.0]])
    w = slot_softmax(scores, dim=1)
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
