"""Mesh graph tables on tiny hand-built meshes."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.graph import (
    build_graph,
    directed_edges,
    match_clusters,
    neighbour_table,
    pool_graph,
)
from cloth_usd.errors import ArgumentError


def _neighbours(table, i):
    return set(table.nbr[i][table.mask[i]].tolist())


def quad_strip(n: int = 4):
    """2 x (n + 1) vertices, 2n triangles, unit squares along x."""
    top = np.arange(n + 1)
    bottom = top + n + 1
    faces = np.concatenate([np.stack([top[:-1], top[1:], bottom[1:]], 1),
                            np.stack([top[:-1], bottom[1:], bottom[:-1]], 1)])
    pos = np.concatenate([np.stack([top, np.zeros(n + 1), np.zeros(n + 1)], 1),
                          np.stack([top, np.ones(n + 1), np.zeros(n + 1)], 1)]).astype(float)
    return faces, pos


def fan(spokes: int):
    """Vertex 0 at the centre, ``spokes`` rim vertices at growing distance 1 + k / 100."""
    k = np.arange(spokes)
    angle = 2 * np.pi * k / spokes
    radius = 1.0 + k / 100.0
    pos = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([radius * np.cos(angle), radius * np.sin(angle),
                                                       np.zeros(spokes)], 1)])
    faces = np.stack([np.zeros(spokes, int), 1 + k, 1 + (k + 1) % spokes], 1)
    return faces, pos


def test_single_triangle():
    edges = directed_edges(np.array([[0, 1, 2]]), 3)
    assert edges.tolist() == [[0, 1], [0, 2], [1, 0], [1, 2], [2, 0], [2, 1]]
    table = neighbour_table(edges, 3)
    assert table.nbr.shape == (3, 2) and table.mask.all()
    assert [_neighbours(table, i) for i in range(3)] == [{1, 2}, {0, 2}, {0, 1}]
    assert table.nbr.dtype == np.int64 and table.mask.dtype == bool


def test_quad_strip_valences():
    faces, pos = quad_strip(4)
    table = neighbour_table(directed_edges(faces, 10), 10, positions=pos)
    valence = table.mask.sum(1)
    assert table.nbr.shape == (10, 4)
    assert valence.tolist() == [3, 4, 4, 4, 2, 2, 4, 4, 4, 3]  # diagonals run top[k]-bottom[k+1]
    assert _neighbours(table, 1) == {0, 2, 6, 7}


def test_edges_are_symmetric_and_unique():
    faces, _ = quad_strip(3)
    edges = directed_edges(faces, 8)
    as_set = set(map(tuple, edges.tolist()))
    assert len(as_set) == len(edges)
    assert all((j, i) in as_set for i, j in as_set)


def test_high_valence_fan_keeps_nearest():
    faces, pos = fan(20)
    table = neighbour_table(directed_edges(faces, 21), 21, positions=pos, k_max=16)
    assert table.nbr.shape == (21, 16)
    assert table.truncated == 1
    assert _neighbours(table, 0) == set(range(1, 17))  # rim vertices 1..16 are the nearest
    assert table.mask[1:].sum(1).max() == 3  # rim vertices keep all of theirs


def test_isolated_vertex_row_is_empty_and_in_range():
    faces = np.array([[0, 1, 2]])
    table = neighbour_table(directed_edges(faces, 4), 4)
    assert not table.mask[3].any()
    assert (table.nbr[3] == 3).all()  # padding points at the row itself


def test_dangling_edge_gives_valence_one():
    faces = np.array([[0, 1, 2], [2, 3, 3]])  # degenerate triangle = edge 2-3
    edges = directed_edges(faces, 4)
    assert not (edges[:, 0] == edges[:, 1]).any()
    table = neighbour_table(edges, 4)
    assert _neighbours(table, 3) == {2}
    assert _neighbours(table, 2) == {0, 1, 3}


@pytest.mark.parametrize("mesh", ["triangle", "strip", "fan", "isolated", "grid"])
def test_pooling_covers_every_vertex_once(mesh):
    if mesh == "triangle":
        faces, pos = np.array([[0, 1, 2]]), np.eye(3)
    elif mesh == "strip":
        faces, pos = quad_strip(5)
    elif mesh == "fan":
        faces, pos = fan(20)
    elif mesh == "isolated":
        faces, pos = np.array([[0, 1, 2]]), np.eye(4, 3)
    else:
        faces, pos = quad_strip(30)
    graph = build_graph(faces, pos)
    pool = graph.pooling
    n = len(pos)
    n2 = pool.members.shape[0]
    assert pool.cluster.shape == (n,) and pool.cluster.min() == 0 and pool.cluster.max() == n2 - 1
    listed = np.sort(pool.members[pool.members_mask])
    assert listed.tolist() == list(range(n))  # every vertex in exactly one cluster
    assert (pool.cluster[pool.members] == np.arange(n2)[:, None]).all()  # padding stays in-cluster
    assert n2 >= (n + 1) // 2  # matching merges pairs at most
    assert pool.table.nbr.shape[0] == n2 and pool.table.nbr.max() < n2


def test_pooling_roughly_halves_a_grid():
    faces, pos = quad_strip(50)
    pool = build_graph(faces, pos).pooling
    assert pool.members.shape[0] <= 0.6 * len(pos)


def test_pooled_neighbours_are_cluster_adjacency():
    faces, pos = quad_strip(5)
    edges = directed_edges(faces, len(pos))
    pool = pool_graph(edges, pos)
    expected = {(a, b) for a, b in pool.cluster[edges].tolist() if a != b}
    got = {(i, j) for i in range(len(pool.table.nbr)) for j in _neighbours(pool.table, i)}
    assert got == expected


def test_clusters_are_deterministic():
    faces, pos = quad_strip(20)
    edges = directed_edges(faces, len(pos))
    a = match_clusters(edges, len(pos), pos)
    b = match_clusters(edges[::-1].copy(), len(pos), pos)
    np.testing.assert_array_equal(a, b)


def test_bad_faces_raise():
    with pytest.raises(ArgumentError, match="outside"):
        directed_edges(np.array([[0, 1, 5]]), 3)
    with pytest.raises(ArgumentError, match=r"\(M, 3\)"):
        directed_edges(np.array([[0.0, 1.0, 2.0]]), 3)
