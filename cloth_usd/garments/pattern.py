"""Sewing patterns as data: flat panels bounded by named edges, seams joining edges, and
the triangulation of the whole pattern at a target resolution.

A panel lives in its own 2D plane [m] and is placed flat in 3D by a rigid map, so a
placed panel has the pattern's metric exactly and no curvature (rest dihedral angle 0).
Seams pair two edges of equal length; both are resampled with the same number of points,
so a seam is a list of vertex pairs. Shape letters: N pattern vertices (before seams are
merged), M triangles, S seam vertex pairs, P panels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay

from ..errors import ClothUsdError

__all__ = ["PatternError", "Panel", "Seam", "Pattern", "PatternMesh", "polyline", "line", "bezier", "arc",
           "triangulate_pattern"]


class PatternError(ClothUsdError):
    """A sewing pattern is malformed (an open outline, a seam naming a missing edge, ...)."""


def line(a, b) -> np.ndarray:
    """(2, 2) a straight edge from a to b."""
    return np.array([a, b], dtype=np.float64)


def bezier(*control, samples: int = 24) -> np.ndarray:
    """(samples, 2) a Bezier curve from its first to its last control point."""
    c = np.asarray(control, dtype=np.float64)
    t = np.linspace(0.0, 1.0, samples)[:, None, None]
    pts = np.broadcast_to(c, (samples, *c.shape)).copy()
    while pts.shape[1] > 1:  # de Casteljau
        pts = (1.0 - t) * pts[:, :-1] + t * pts[:, 1:]
    return pts[:, 0]


def arc(center, radius: float, start: float, stop: float, samples: int = 32) -> np.ndarray:
    """(samples, 2) a circular arc [angles in rad, counter-clockwise from +X]."""
    a = np.linspace(start, stop, samples)
    return np.asarray(center, dtype=np.float64) + radius * np.stack([np.cos(a), np.sin(a)], axis=1)


def polyline(points) -> np.ndarray:
    """(k, 2) float64 points of an edge."""
    return np.asarray(points, dtype=np.float64).reshape(-1, 2)


@dataclass(frozen=True)
class Panel:
    """One flat piece of cloth: a closed outline of named edges, and where it is placed."""

    name: str
    edges: tuple[tuple[str, np.ndarray], ...]
    """``(edge name, (k, 2) polyline [m])`` in outline order, counter-clockwise; each edge
    starts where the previous one ends."""
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """(3,) where the panel's 2D origin is placed [m] (canonical body frame)."""
    axes: np.ndarray = field(default_factory=lambda: np.eye(3)[:2])
    """(2, 3) orthonormal: the 3D directions of the panel's u and v axes."""
    outward: float = 1.0
    """+1: the panel's front (counter-clockwise side) faces away from the body; -1: it
    faces the body (a back panel drawn as seen from the front), its triangles are flipped."""
    conform: bool = False
    """Placed on the body's front (``outward`` +1) or back (-1) surface seen along Z rather
    than in a plane (:func:`cloth_usd.garments.sew.conform_placement`): for panels whose
    seams could not close round the body from a plane (trousers, between the legs)."""

    def edge(self, name: str) -> np.ndarray:
        for n, e in self.edges:
            if n == name:
                return e
        raise PatternError(f"panel '{self.name}' has no edge '{name}' (edges: {', '.join(n for n, _ in self.edges)})")

    def place(self, uv: np.ndarray) -> np.ndarray:
        """(k, 3) the placed 3D points of (k, 2) panel points."""
        return self.origin + uv @ self.axes


@dataclass(frozen=True)
class Seam:
    """Two panel edges sewn together: ``(panel, edge)`` and ``(panel, edge)``."""

    a: tuple[str, str]
    b: tuple[str, str]


@dataclass(frozen=True)
class Pattern:
    """A garment's panels and seams."""

    category: str
    panels: tuple[Panel, ...]
    seams: tuple[Seam, ...]
    held: tuple[str, ...] = ()
    """Panels held where they were sewn while the garment drapes: a waistband, which holds
    trousers at the waist (an elastic or a belt) where otherwise they slide down the body
    until the band is stretched over the hips."""

    def panel(self, name: str) -> Panel:
        for p in self.panels:
            if p.name == name:
                return p
        raise PatternError(f"pattern has no panel '{name}' (panels: {', '.join(p.name for p in self.panels)})")


@dataclass(frozen=True)
class PatternMesh:
    """A triangulated pattern, panels placed in 3D, seams as vertex pairs (not yet merged)."""

    uv: np.ndarray
    """(N, 2) float64 pattern coordinates [m], each panel in its own plane."""
    placed: np.ndarray
    """(N, 3) float64 the panels placed around the body [m], canonical frame."""
    faces: np.ndarray
    """(M, 3) int64 triangles, counter-clockwise seen from outside the garment."""
    panel: np.ndarray
    """(N,) int64 index of each vertex's panel."""
    seams: np.ndarray
    """(S, 2) int64 vertex pairs to be sewn together."""
    panel_names: tuple[str, ...]
    spacing: float
    """The target edge length [m] it was triangulated at."""
    conform: np.ndarray | None = None
    """(N,) int8: +1 / -1 a vertex of a panel placed on the body's front / back surface,
    0 a vertex of a flat-placed panel; None: all flat."""
    held: tuple[str, ...] = ()
    """The pattern's :attr:`Pattern.held` panels."""


def _resample(edge: np.ndarray, segments: int) -> np.ndarray:
    """(segments + 1, 2) points evenly spaced by arc length along a polyline."""
    seg = np.linalg.norm(np.diff(edge, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], segments + 1)
    return np.stack([np.interp(t, s, edge[:, 0]), np.interp(t, s, edge[:, 1])], axis=1)


def _length(edge: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(edge, axis=0), axis=1).sum())


def _inside(points: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """(k,) bool: points inside a closed ring (even-odd rule)."""
    a, b = ring, np.roll(ring, -1, axis=0)
    px, py = points[:, 0:1], points[:, 1:2]
    crosses = (a[:, 1] > py) != (b[:, 1] > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[:, 0] + (py - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.count_nonzero(crosses & (px < x_at), axis=1) % 2) == 1


def _distance_to_ring(points: np.ndarray, ring: np.ndarray) -> np.ndarray:
    a, b = ring, np.roll(ring, -1, axis=0)
    ab = b - a
    ap = points[:, None] - a[None]
    t = np.clip((ap * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=1)


def _triangulate_panel(ring: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangles over a closed ring of boundary points and an equilateral lattice inside.

    Returns:
        ``(points (k, 2), triangles (m, 3))``, the ring's points first, in order.
    """
    lo, hi = ring.min(0), ring.max(0)
    dy = spacing * np.sqrt(3.0) / 2.0
    rows = []
    for r, y in enumerate(np.arange(lo[1] + dy / 2, hi[1], dy)):
        xs = np.arange(lo[0] + (spacing / 2 if r % 2 else 0.0), hi[0], spacing)
        rows.append(np.stack([xs, np.full_like(xs, y)], axis=1))
    grid = np.concatenate(rows) if rows else np.zeros((0, 2))
    if grid.size:
        grid = grid[_inside(grid, ring)]
        grid = grid[_distance_to_ring(grid, ring) > 0.55 * spacing]
    points = np.concatenate([ring, grid])
    tri = Delaunay(points, qhull_options="QJ Qbb Qc").simplices.astype(np.int64)
    centroid = points[tri].mean(axis=1)
    keep = _inside(centroid, ring)
    d = points[tri]
    area = 0.5 * ((d[:, 1, 0] - d[:, 0, 0]) * (d[:, 2, 1] - d[:, 0, 1])
                  - (d[:, 2, 0] - d[:, 0, 0]) * (d[:, 1, 1] - d[:, 0, 1]))
    keep &= np.abs(area) > 1e-4 * spacing ** 2
    tri = tri[keep]
    flip = area[keep] < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    used = np.zeros(len(points), dtype=bool)
    used[tri.ravel()] = True
    if not used[: len(ring)].all():
        raise PatternError(f"triangulation left {np.count_nonzero(~used[:len(ring)])} outline points unused "
                           f"(spacing {spacing:.4f} m too coarse for the outline?)")
    # Interior lattice points a boundary triangle swallowed: drop them.
    index = np.cumsum(used) - 1
    return points[used], index[tri]


def triangulate_pattern(pattern: Pattern, spacing: float) -> PatternMesh:
    """Resample every edge (a seam's two edges with the same count) and triangulate each panel.

    Args:
        spacing: target edge length [m].
    """
    if not spacing > 0:
        raise PatternError(f"spacing must be positive, got {spacing}")
    counts: dict[tuple[str, str], int] = {}
    for seam in pattern.seams:
        ea, eb = pattern.panel(seam.a[0]).edge(seam.a[1]), pattern.panel(seam.b[0]).edge(seam.b[1])
        n = max(1, int(round(max(_length(ea), _length(eb)) / spacing)))
        for key in (seam.a, seam.b):
            if key in counts:
                raise PatternError(f"edge {key[0]}.{key[1]} is in two seams")
            counts[key] = n
    uv, placed, faces, panel_of = [], [], [], []
    edge_vertices: dict[tuple[str, str], np.ndarray] = {}
    offset = 0
    for p_index, panel in enumerate(pattern.panels):
        ring_parts, starts = [], []
        for name, edge in panel.edges:
            n = counts.get((panel.name, name), max(1, int(round(_length(edge) / spacing))))
            pts = _resample(edge, n)
            starts.append(sum(len(r) for r in ring_parts))
            ring_parts.append(pts[:-1])
        ring = np.concatenate(ring_parts)
        ends = [e[-1] for _, e in panel.edges]
        firsts = [e[0] for _, e in panel.edges]
        gap = max(float(np.linalg.norm(ends[i - 1] - firsts[i])) for i in range(len(firsts)))
        if gap > 1e-6:
            raise PatternError(f"panel '{panel.name}': its edges do not form a closed outline (gap {gap:.3g} m)")
        signed = 0.5 * np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])
        if signed <= 0:
            raise PatternError(f"panel '{panel.name}': its outline must run counter-clockwise")
        pts, tri = _triangulate_panel(ring, spacing)
        k = len(ring)
        for e_index, (name, _) in enumerate(panel.edges):
            n = len(ring_parts[e_index])
            ids = (starts[e_index] + np.arange(n + 1)) % k
            edge_vertices[(panel.name, name)] = offset + ids
        if panel.outward < 0:
            tri = tri[:, [0, 2, 1]]
        uv.append(pts)
        placed.append(panel.place(pts))
        faces.append(tri + offset)
        panel_of.append(np.full(len(pts), p_index, dtype=np.int64))
        offset += len(pts)
    uv_all, placed_all = np.concatenate(uv), np.concatenate(placed)
    pairs = []
    for seam in pattern.seams:
        a, b = edge_vertices[seam.a], edge_vertices[seam.b]
        # Sew end to end in the direction that joins the placed edges' nearer ends.
        same = np.linalg.norm(placed_all[a[[0, -1]]] - placed_all[b[[0, -1]]], axis=1).sum()
        flip = np.linalg.norm(placed_all[a[[0, -1]]] - placed_all[b[[-1, 0]]], axis=1).sum()
        pairs.append(np.stack([a, b if same <= flip else b[::-1]], axis=1))
    return PatternMesh(uv=uv_all, placed=placed_all, faces=np.concatenate(faces), panel=np.concatenate(panel_of),
                       seams=np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64),
                       panel_names=tuple(p.name for p in pattern.panels), spacing=float(spacing),
                       conform=np.concatenate([np.full(np.count_nonzero(np.concatenate(panel_of) == i),
                                                       int(p.outward) if p.conform else 0, dtype=np.int8)
                                               for i, p in enumerate(pattern.panels)]),
                       held=tuple(pattern.held))
