"""docs/method.md's post-process: push garment vertices out of the body.

A garment vertex that penetrates the body, or sits closer than ``margin`` to it, is moved
out along the normal of a body vertex ``b`` until it is ``margin`` in front of that
vertex's tangent plane: ``s = dot(p - b, n)``; if ``s < margin``: ``p += (margin - s) n``.
The body vertex is the one nearest to the garment vertex in that frame, among the body
under the garment (:func:`nearest_body_points`; the candidates are
:attr:`~cloth_usd.core.pipeline.BodyPatch.contact`): a vertex that slid along the body, or
a skirt swung into the other thigh, is measured against the body under it, not against the
body vertex it was bound to at rest. A tangent plane is the body's surface only near its
vertex: where an arm lies against the torso, or the body folds (an armpit), a vertex in
front of its nearest body vertex's plane can still be inside the body, so
:func:`push_out_of_surface` then measures it against the surface itself (the closest point
of the triangles around its nearest body vertices, and the normal interpolated there). Shape
letters: T frames, N garment vertices, K candidate body vertices, V' the posed body vertices
the candidates are taken from, M' their triangles.
"""

from __future__ import annotations

import numpy as np

from ..errors import ArgumentError
from .association import closest_point_on_triangles, incident_faces
from .graph import directed_edges, neighbour_table
from .mesh import boundary_vertices, cross, vector_lengths

__all__ = ["push_out", "push_out_of_surface", "StrainLimiter", "check_strain_limit", "mesh_edges", "STRAIN_LIMIT",
           "STRAIN_ITERATIONS", "STRAIN_ANCHOR", "nearest_vertex", "nearest_body_points", "search_tree",
           "garment_margin", "DEFAULT_MARGIN", "LIMB_RADIUS", "SEARCH_REACH", "SURFACE_CANDIDATES", "SURFACE_ROUNDS",
           "PLANE_REACH", "limit_slides", "LIMIT_CHECK_QUANTILE", "LIMIT_CHECK_TOLERANCE", "LIMIT_MOVE_BOUND",
           "TriangleLift", "inner_triangles", "body_ahead", "covered_at_rest", "LIFT_REACH",
           "LIFT_MARGIN", "LIFT_STRETCH", "COVER_REACH", "edge_midpoints"]

#: Default clearance from the body surface [m] (2 mm).
DEFAULT_MARGIN = 0.002
#: The radius of the thinnest body part a garment wraps [m] (a shin, a forearm): what
#: :func:`garment_margin` sizes the clearance for.
LIMB_RADIUS = 0.045


def push_out(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
             margin: float = DEFAULT_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Push penetrating (or too close) garment vertices out along the body normal.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, N, 3) each garment vertex's associated posed body vertex [m].
        body_normals: (T, N, 3) unit outward normals at those body vertices (a zero
            normal leaves its vertex unmoved).
        margin: clearance [m] to keep in front of the body's tangent plane.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the corrected points (a new
        array) and how many vertices moved in each frame.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or b.shape != p.shape or n.shape != p.shape:
        raise ArgumentError(f"points, body_points and body_normals must all be (T, N, 3), got "
                            f"{p.shape}, {b.shape}, {n.shape}")
    if not margin >= 0:
        raise ArgumentError(f"margin must be >= 0 [m], got {margin}")
    s = np.einsum("tnc,tnc->tn", p - b, n)
    live = np.einsum("tnc,tnc->tn", n, n) > 0
    push = np.where(live & (s < margin), margin - s, 0.0)
    return p + push[..., None] * n, np.count_nonzero(push > 0, axis=1).astype(np.int64)


#: A garment vertex further than this [m] from every candidate body vertex is neither inside
#: the body nor near it (:func:`nearest_body_points` does not search further: the search
#: costs a third as much).
SEARCH_REACH = 0.05


def search_tree(points: np.ndarray):
    """A ``scipy.spatial.cKDTree`` over (K, 3) posed body vertices [m], built as every body search
    here builds it (unbalanced, leaves of 32: a fifth faster for these queries)."""
    from scipy.spatial import cKDTree

    return cKDTree(points, leafsize=32, balanced_tree=False, compact_nodes=False)


def nearest_vertex(points: np.ndarray, candidates: np.ndarray, *, reach: float = np.inf,
                   trees: list | None = None) -> np.ndarray:
    """(T, N) int64 each point's nearest candidate in its frame; ``K`` (one past the last
    candidate) where none lies within ``reach`` [m] or the point is not finite.

    Args:
        points: (T, N, 3) garment points [m].
        candidates: (T, K, 3) the posed body vertices searched [m].
        trees: T :func:`search_tree` over each frame's ``candidates``, when the caller built
            them already; made here when None.
    """
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(candidates, dtype=np.float64)
    index = np.full(p.shape[:2], c.shape[1], dtype=np.int64)
    for t in range(p.shape[0]):
        finite = np.isfinite(p[t]).all(axis=1)  # a non-finite vertex stays so (the guard catches it)
        if finite.any():
            tree = trees[t] if trees is not None else search_tree(c[t])
            index[t, finite] = tree.query(p[t, finite], distance_upper_bound=reach)[1]
    return index


def nearest_body_points(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray, *,
                        reach: float = SEARCH_REACH) -> tuple[np.ndarray, np.ndarray]:
    """Each garment vertex's nearest body vertex in its frame, and that vertex's normal.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, K, 3) the candidate posed body vertices [m].
        body_normals: (T, K, 3) their unit outward normals.
        reach: a vertex with no candidate within this distance [m] gets a zero normal, which
            :func:`push_out` leaves unmoved.
    Returns:
        ``(body_points (T, N, 3), body_normals (T, N, 3))`` float64, what :func:`push_out` takes.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    if p.ndim != 3 or b.ndim != 3 or b.shape != n.shape or b.shape[0] != p.shape[0] or b.shape[1] == 0:
        raise ArgumentError(f"points (T, N, 3), body_points and body_normals (T, K, 3) with K > 0 expected, got "
                            f"{p.shape}, {b.shape}, {n.shape}")
    index = nearest_vertex(p, b, reach=reach)
    found = index < b.shape[1]
    rows, index = np.arange(p.shape[0])[:, None], np.where(found, index, 0)
    return b[rows, index], n[rows, index] * found[..., None]


#: Body vertices nearest to a garment vertex whose tangent planes and triangles
#: :func:`push_out_of_surface` tests it against.
SURFACE_CANDIDATES = 4
#: Times :func:`push_out_of_surface` measures a vertex it moved against the surface again:
#: where an arm overlaps the torso, a vertex pushed out of one can land in the other.
SURFACE_ROUNDS = 3
#: [m] how far from its body vertex a tangent plane stands for the body's surface: a garment
#: vertex further than this from its nearest body vertex is measured against the surface
#: itself. (A MakeHuman sleeve's hem 38 mm outside the upper arm lay 39 mm behind its nearest
#: body vertex's plane, and the plane's push moved it 41 mm, stretching a 1 mm hem edge 42x.)
PLANE_REACH = 0.01


def push_out_of_surface(points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray,
                        body_faces: np.ndarray, candidates: np.ndarray, *, margin: float = DEFAULT_MARGIN,
                        reach: float = SEARCH_REACH, neighbours: int = SURFACE_CANDIDATES,
                        rounds: int = SURFACE_ROUNDS, plane_reach: float = PLANE_REACH,
                        rings: np.ndarray | None = None,
                        trees: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The post-process: push garment vertices out of the body's surface, to ``margin`` in front of it.

    Per frame, each garment vertex's ``neighbours`` nearest candidate body vertices within
    ``reach`` are found. The vertex is pushed in front of the nearest one's tangent plane
    (:func:`push_out`) when it lies within ``plane_reach`` of that vertex (further off, a plane
    says little: a vertex outside the body can lie behind it). Where it then still lies
    behind the tangent plane of one of them (an arm against the torso, an armpit, a thigh
    raised into the belly: places where a plane is not the surface; the belly's vertices can
    be the nearer, the thigh's 2 cm off), the
    closest point of the triangles around those vertices is found and the vertex pushed out
    along the normal interpolated there, to ``margin`` in front of the surface, and measured
    again, up to ``rounds`` times.

    Args:
        points: (T, N, 3) garment points [m].
        body_points: (T, V', 3) posed body vertices [m] (all of ``body_faces``' corners).
        body_normals: (T, V', 3) their unit outward normals.
        body_faces: (M', 3) int triangles over ``body_points``: every triangle around each
            candidate.
        candidates: (K,) int the vertices of ``body_points`` searched (the body under the
            garment), K > 0.
        margin: clearance [m] to keep in front of the body.
        reach: a vertex further than this [m] from every candidate is left alone, and its
            nearest candidates are looked for this far.
        neighbours: candidate vertices tested per garment vertex.
        rounds: surface tests of a vertex, at most (one the test moved is tested again).
        plane_reach: a vertex further than this [m] from its nearest candidate is not pushed
            along that candidate's normal, only by the surface test.
        rings: (V', D) int the rows of ``body_faces`` around each body vertex, padded with -1
            (:func:`~cloth_usd.core.association.incident_faces`); made here when None.
        trees: T :func:`search_tree` over each frame's candidates (``body_points[t,
            candidates]``), when the caller built them already; made here when None.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the corrected points (a new
        array; a non-finite vertex is left as it is, for the guard) and how many vertices
        moved in each frame.
    """
    p = np.array(points, dtype=np.float64)
    b = np.asarray(body_points, dtype=np.float64)
    n = np.asarray(body_normals, dtype=np.float64)
    faces = np.asarray(body_faces, dtype=np.int64)
    cand = np.asarray(candidates, dtype=np.int64)
    if p.ndim != 3 or p.shape[-1] != 3 or b.ndim != 3 or b.shape != n.shape or b.shape[0] != p.shape[0] \
            or cand.ndim != 1 or cand.size == 0 or faces.ndim != 2 or faces.shape[1] != 3 \
            or (trees is not None and len(trees) != p.shape[0]):
        raise ArgumentError(f"points (T, N, 3), body_points and body_normals (T, V', 3), body_faces (M', 3), "
                            f"candidates (K,) with K > 0 (and T trees) expected, got {p.shape}, {b.shape}, {n.shape}, "
                            f"{faces.shape}, {cand.shape}")
    if not margin >= 0:
        raise ArgumentError(f"margin must be >= 0 [m], got {margin}")
    k = max(1, min(int(neighbours), cand.size))
    frames, rows, near = [], [], []
    for t in range(p.shape[0]):  # the search per frame; the tests below over every frame at once
        r = np.flatnonzero(np.isfinite(p[t]).all(axis=1))  # a non-finite vertex stays so (the guard catches it)
        if r.size:
            tree = trees[t] if trees is not None else search_tree(b[t, cand])
            index = tree.query(p[t, r], k=k, distance_upper_bound=reach)[1].reshape(r.size, k)
            keep = index[:, 0] < cand.size  # near the body at all
            frames.append(np.full(np.count_nonzero(keep), t))
            rows.append(r[keep])
            near.append(index[keep])
    moved = np.zeros(p.shape[0], dtype=np.int64)
    if not frames:
        return p, moved
    frame, row, index = np.concatenate(frames), np.concatenate(rows), np.concatenate(near)
    found = index < cand.size
    near = cand[np.where(found, index, 0)]  # (R, k) indices into body_points
    flat_b, flat_n = b.reshape(-1, 3), n.reshape(-1, 3)  # indexed by frame * V' + vertex: one gather, not two
    offset = frame * b.shape[1]
    flat = near + offset[:, None]
    # np.take, not fancy indexing, and the normals zeroed in place: a quarter of the time
    q = np.take(p.reshape(-1, 3), frame * p.shape[1] + row, axis=0)
    bp, bn = np.take(flat_b, flat, axis=0), np.take(flat_n, flat, axis=0)
    bn[~found] = 0.0
    s = np.einsum("rc,rc->r", q - bp[:, 0], bn[:, 0])
    plane = (np.einsum("rc,rc->r", bn[:, 0], bn[:, 0]) > 0) & (vector_lengths(q - bp[:, 0]) <= plane_reach)
    push = np.where(plane, np.maximum(margin - s, 0.0), 0.0)
    q += push[:, None] * bn[:, 0]
    hit = push > 0
    check = np.flatnonzero((np.einsum("rkc,rkc->rk", q[:, None] - bp, bn) < 0.0).any(axis=1))
    if check.size:
        ring = incident_faces(faces, b.shape[1]) if rings is None else np.asarray(rings, dtype=np.int64)
        for _ in range(max(int(rounds), 0)):
            closest, normal = _closest_surface(q[check], offset[check], near[check], found[check], flat_b, flat_n,
                                               faces, ring)
            s = np.einsum("rc,rc->r", q[check] - closest, normal)
            out = (s < margin) & (np.einsum("rc,rc->r", normal, normal) > 0)
            q[check[out]] += (margin - s[out])[:, None] * normal[out]
            hit[check[out]] = True
            check = check[out]
            if not check.size:
                break
    p[frame, row] = q
    np.add.at(moved, frame[hit], 1)
    return p, moved


def _closest_surface(q: np.ndarray, offset: np.ndarray, near: np.ndarray, found: np.ndarray, points: np.ndarray,
                     normals: np.ndarray, faces: np.ndarray, ring: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each of ``q`` (R, 3)'s closest point on the triangles around its ``near`` (R, k) vertices
    (where ``found``) of its frame, and the unit normal interpolated there (zero where it
    cancels). ``points`` and ``normals`` are (T * V', 3), a frame's vertex ``v`` at ``offset + v``
    (``offset`` (R,) its frame times V')."""
    closest, bary, corners = _closest_triangle(q, offset, near, found, points, faces, ring)
    normal = np.einsum("ik,ikc->ic", bary, normals[corners])
    length = vector_lengths(normal)[:, None]
    return closest, np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)


def _closest_triangle(q: np.ndarray, offset: np.ndarray, near: np.ndarray, found: np.ndarray, points: np.ndarray,
                      faces: np.ndarray, ring: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_closest_surface`'s search: ``(closest (R, 3), barycentric (R, 3), corners (R, 3))``,
    each of ``q``'s closest point, its weights and the triangle's corners (rows of ``points``)."""
    tri = np.where(found[..., None], ring[near], -1).reshape(q.shape[0], -1)  # (R, k * D), -1 padded
    # neighbouring body vertices share triangles: each is measured once, at its first place (so that a tie
    # goes where it went before)
    order = np.argsort(tri, axis=1, kind="stable")
    ranked = np.take_along_axis(tri, order, axis=1)
    ranked[:, 1:][ranked[:, 1:] == ranked[:, :-1]] = -1
    np.put_along_axis(tri, order, ranked, axis=1)
    r, c = np.nonzero(tri >= 0)
    corners = faces[tri[r, c]] + offset[r][:, None]
    closest, bary = closest_point_on_triangles(points[corners], q[r])
    d2 = np.full(tri.shape, np.inf)
    d2[r, c] = np.einsum("ic,ic->i", closest - q[r], closest - q[r])
    slot = np.full(tri.shape, -1, dtype=np.int64)
    slot[r, c] = np.arange(r.size)
    pick = slot[np.arange(q.shape[0]), np.argmin(d2, axis=1)]
    return closest[pick], bary[pick], corners[pick]


#: The longest an edge may be after the post-process, over its rest length: Newton's shirts
#: keep 99% of their edges within 1.09 of rest on real clips (their longest at 1.25), where a
#: learned garment stretches its armpits and shoulders as skinning does (1.2-1.4). On the sample
#: shirt's Newton test set (``sample-tshirt-own``'s detail tier, 16 rounds;
#: ``bench/bench_strain_limit.py``) limits of 1.10, 1.07, 1.05, 1.03 and 1.02 measured 13.88, 13.62,
#: 13.47, 13.37 and 13.38 mm; 1.03 let more specks of skin through a taut shoulder in a close-up.
STRAIN_LIMIT = 1.05
#: Rounds of :class:`StrainLimiter` (each a local step over the edges and one sparse solve): on the
#: same test set at the limit 1.05, 8, 12, 16 and 32 rounds measured 13.66, 13.54, 13.47 and 13.38 mm
#: (1.10: 8 rounds 13.92, 16 rounds 13.88). Each round costs about half a millisecond a frame on a
#: 4000-vertex shirt.
STRAIN_ITERATIONS = 16
#: The quantile of a frame's edge stretch by which the post-process judges the strain limit
#: (:func:`~cloth_usd.core.pipeline.post_process`): a frame that the limit and the push leave more
#: stretched, at this quantile, than the models made it is pushed again without the limit. The
#: sample trousers on a martial-arts clip (CMU martial 04, legs spread in kicks, where skinning
#: itself stretches their 99th percentile to 2.18 x rest) showed why: limited to 1.05, 36% of the
#: vertices were pulled into the body (2.0% before), and the push out of it tore edges, the median
#: frame's 99th percentile 1.48 before the post-process and 2.06 after it (0.11% of the vertices
#: deeper than 1 mm in the body after it, against 0.63%); pushed alone, 1.48. The check measures
#: each batch twice (:meth:`StrainLimiter.stretch`): 2.3 ms for four frames of a 4000-vertex shirt
#: (11952 edges) on the 2-core CPU with a test run beside it, about 1.2 ms a frame. The same quantile
#: of the limit's moves is held to :data:`LIMIT_MOVE_BOUND`.
LIMIT_CHECK_QUANTILE = 0.99
#: How much more stretched than the models made it (that quantile, over rest) a frame must be
#: left for the post-process to push it again without the limit: more than the float32 solve's
#: rounding of a garment the limit leaves as it is.
LIMIT_CHECK_TOLERANCE = 0.01
#: How far [m] the strain limit may move a garment's vertices: a frame where it would move more
#: than 1% of them (above :data:`LIMIT_CHECK_QUANTILE`) further than this is pushed out of the body
#: without it (:func:`~cloth_usd.core.pipeline.post_process`). The limit's solve does not see the
#: body and holds each vertex only weakly (:data:`STRAIN_ANCHOR`), so it can slide a whole region
#: of cloth: the sample trousers' own bundle on CMU martial arts 04, a knee raised to the chest
#: (time code 1040), had a leg slid off the thigh, the limit moving 425 of their 897 vertices past
#: 10 cm (233 mm at most). With this bound the detail tier stays within 55 mm of the coarse tier
#: on that clip (237 without it) and the guard replaces none of its frames there (15 without it;
#: `trousers-v2` 41). A spike the models made is another matter: one frame of the sample shirt's
#: own bundle on CMU salsa 10 had an edge at 10.8 x rest, which the limit pulls back, moving 5 of
#: 3516 vertices past 10 cm; judged by the largest move instead of the quantile, that frame lost
#: the limit and kept the spike. Judged by the largest move, 0.15 m left a frame of martial 04
#: 144 mm from the coarse tier, and 0.05 m changed 58 frames of the trousers' Newton test set for
#: `trousers-v2`, 23.07 -> 23.61 mm; at 0.10 no frame of the dress's or the trousers' test set
#: moves that far.
LIMIT_MOVE_BOUND = 0.10
#: How strongly :class:`StrainLimiter` holds each vertex where the models put it, against an
#: edge's pull (1: as strongly as one edge). On the same test set (limit 1.03, 16 rounds) 1e-2 and
#: 1e-4 measured 13.66 and 14.43 mm, where 1e-3 measured 13.37.
STRAIN_ANCHOR = 1.0e-3


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """(E, 2) int64 the undirected edges of triangles ``faces`` (M, 3), each once."""
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def check_strain_limit(limit) -> None:
    """Raise :class:`~cloth_usd.errors.ArgumentError` unless ``limit`` (a :class:`StrainLimiter`'s)
    is a number > 1."""
    if not (isinstance(limit, (int, float)) and limit > 1):
        raise ArgumentError(f"the strain limit must be a number > 1, got {limit!r}")


class StrainLimiter:
    """Shorten a garment's edges stretched past ``limit`` times their rest length, the garment
    as a whole (strain limiting as a projective-dynamics solve, Bouaziz et al. 2014).

    Each round, every edge gets a target: its own vector, shortened to ``limit`` times its rest
    length where it is longer (an edge may fold or bunch, not stretch); then the points that
    meet all targets best, held to where the models put them with weight ``anchor``, are
    solved for at once: ``(D^T D + anchor I) x = D^T targets + anchor x0``, ``D`` the edge
    difference matrix, factored once per garment. One edge at a time (Provot's projection,
    Jacobi or Gauss-Seidel) takes tens of rounds to shorten a stretched armpit; the solve moves
    the whole region in three or four. Computed in float32, frames side by side, on one BLAS
    thread: SuperLU's solve calls OpenBLAS, whose second thread gained the solve nothing and,
    spinning after it, took a core from onnxruntime's next run (``tshirt-v6``'s detail tier on a
    4041-vertex shirt, two threads: a median 69 ms a frame, 56 with the solve on one thread).
    """

    def __init__(self, rest_points: np.ndarray, faces: np.ndarray, *, limit: float = STRAIN_LIMIT,
                 iterations: int = STRAIN_ITERATIONS, anchor: float = STRAIN_ANCHOR) -> None:
        """
        Args:
            rest_points: (N, 3) the rest garment [m]; faces: (M, 3) int its triangles.
            limit: the longest an edge may be over its rest length (> 1).
            iterations: rounds (>= 1).
            anchor: the weight holding each vertex to the models' point (> 0).
        """
        from scipy import sparse
        from scipy.sparse.linalg import splu
        from threadpoolctl import ThreadpoolController

        rest = np.asarray(rest_points, dtype=np.float64)
        check_strain_limit(limit)
        if not (isinstance(iterations, int) and iterations >= 1) or not anchor > 0:
            raise ArgumentError(f"the strain limiter needs iterations >= 1 and anchor > 0, got {iterations!r}, "
                                f"{anchor!r}")
        self.limit, self.iterations, self.anchor = float(limit), int(iterations), float(anchor)
        self.edges = mesh_edges(faces)
        self.num_vertices = n = rest.shape[0]
        m = len(self.edges)
        rows = np.r_[np.arange(m), np.arange(m)]
        self._d = sparse.csr_matrix((np.r_[-np.ones(m), np.ones(m)], (rows, self.edges.T.ravel())), shape=(m, n),
                                    dtype=np.float32)
        self._dt = self._d.T.tocsr()
        self.rest_lengths = np.linalg.norm(rest[self.edges[:, 1]] - rest[self.edges[:, 0]], axis=1)
        self._per_rest = 1.0 / np.maximum(self.rest_lengths, 1e-9)
        self._longest = (self.limit * self.rest_lengths).astype(np.float32)[:, None]
        system = (self._dt @ self._d + self.anchor * sparse.identity(n, dtype=np.float32, format="csr")).tocsc()
        # symmetric positive definite: ordered as a symmetric matrix, factored without pivoting (half
        # the factor's entries of the default ordering's; a solve 1.4 ms instead of 2.1 on a
        # 4000-vertex shirt's four frames)
        self._solve = splu(system.astype(np.float32), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True}).solve if m else None
        self._blas = ThreadpoolController()  # after scipy's imports: it finds the BLAS libraries loaded

    def __call__(self, points: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
        """(T, N, 3) float64 ``points`` (T, N, 3) [m] limited (a new array; a frame with a
        non-finite point is left as it is, for the guard). ``free`` (T, E) bool: per frame, the
        :attr:`edges` left as long as the models made them (None: none)."""
        p = np.array(points, dtype=np.float64)
        if p.ndim != 3 or p.shape[1:] != (self.num_vertices, 3):
            raise ArgumentError(f"the strain limiter expected points (T, {self.num_vertices}, 3), got {p.shape}")
        if free is not None and np.shape(free) != (p.shape[0], len(self.edges)):
            raise ArgumentError(f"the strain limiter expected free edges ({p.shape[0]}, {len(self.edges)}), "
                                f"got {np.shape(free)}")
        live = np.flatnonzero(np.isfinite(p).all(axis=(1, 2)))
        if self._solve is None or not live.size:
            return p
        n, frames, m = self.num_vertices, live.size, len(self.edges)
        longest = self._longest if free is None else np.where(np.asarray(free)[live].T, np.float32(np.inf),
                                                                self._longest)
        origin = p[live].mean(axis=1, keepdims=True)  # float32 about each frame's centre, not the world origin
        x0 = np.ascontiguousarray((p[live] - origin).transpose(1, 0, 2), dtype=np.float32).reshape(n, -1)
        x = x0
        with self._blas.limit(limits=1, user_api="blas"):
            for _ in range(self.iterations):
                d = (self._d @ x).reshape(m, frames, 3)
                length = vector_lengths(d)
                if not (length > longest).any():
                    break
                d *= (np.minimum(length, longest) / np.maximum(length, 1e-12))[..., None]
                x = self._solve(self._dt @ d.reshape(m, -1) + self.anchor * x0)
        p[live] = x.reshape(n, frames, 3).transpose(1, 0, 2).astype(np.float64) + origin
        return p

    def stretch(self, points: np.ndarray, quantile: float = LIMIT_CHECK_QUANTILE) -> np.ndarray:
        """(T,) float64 the ``quantile`` of each frame's edge lengths over their rest lengths
        (NaN for a frame with a non-finite point)."""
        p = np.asarray(points, dtype=np.float64)
        if not len(self.edges):
            return np.ones(p.shape[0])
        d = p[:, self.edges[:, 1]] - p[:, self.edges[:, 0]]
        return np.quantile(vector_lengths(d) * self._per_rest, quantile, axis=1)


def limit_slides(points: np.ndarray, limited: np.ndarray) -> np.ndarray:
    """(T,) bool the frames where the strain limit moved the garment (T, N, 3) to ``limited`` by
    more than :data:`LIMIT_MOVE_BOUND` at the :data:`LIMIT_CHECK_QUANTILE` of its vertices' moves: a
    region slid along the body, not a spike pulled back (:func:`~cloth_usd.core.pipeline.post_process`
    pushes such a frame without the limit)."""
    move = vector_lengths(np.asarray(limited) - np.asarray(points))
    return np.quantile(move, LIMIT_CHECK_QUANTILE, axis=1) > LIMIT_MOVE_BOUND


def garment_margin(rest_points: np.ndarray, faces: np.ndarray, *, base: float = DEFAULT_MARGIN,
                   radius: float = LIMB_RADIUS) -> float:
    """The clearance [m] that keeps a garment's triangles, not only its vertices, off the body.

    Pushed out to ``margin`` at its vertices, a flat triangle spanning a curved limb still
    has the limb bulging through its middle by the sagitta ``r - sqrt(r^2 - c^2 / 4)`` of its
    edge ``c`` over the limb's radius ``r``: 4.7 mm for the 4 cm edges of a 1000-vertex garment
    on a shin, where the body showed through a tight trouser leg in a close-up render. So the
    margin is the larger of ``base`` and that sagitta at the median edge length.

    Args:
        rest_points: (N, 3) the rest garment [m]; faces: (M, 3) int its triangles.
        base: the smallest clearance [m]; radius: the limb radius [m].
    """
    p = np.asarray(rest_points, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if f.size == 0:
        return float(base)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    c = float(np.median(np.linalg.norm(p[edges[:, 0]] - p[edges[:, 1]], axis=1)))
    half = min(0.5 * c, radius)
    return max(float(base), radius - float(np.sqrt(radius * radius - half * half)))


#: [m] how near a garment triangle a body vertex must lie for :class:`TriangleLift` to measure it
#: against the triangle (as ``bench/bench_postprocess_stages.py`` counts the body through a garment).
LIFT_REACH = 0.01
#: [m] how far behind a garment triangle :class:`TriangleLift` leaves the body vertices under it.
LIFT_MARGIN = 0.0005
#: The longest :class:`TriangleLift` may make an edge, over its rest length (the issue's bound on a frame's
#: longest edge): on a tight top on CMU 13_10 (100 frames) a lift without it took the frames with an edge
#: past 1.5 from 50 to 89, with it to 59. Measured once, with every lift the check took back put back at
#: once, it left an edge stretched between a vertex taken back and its lifted neighbour: MakeHuman's sport
#: top on its own bundle (trained again in stop 62), 24 of the 100 frames with an edge past 1.5; measured
#: until none is, 7.
LIFT_STRETCH = 1.5
#: [m] how far from the rest garment a body vertex may lie and be covered by it (:func:`covered_at_rest`).
COVER_REACH = 0.03
#: [m] how far in front of a garment triangle a body vertex it covers must lie to show through it
#: (:meth:`TriangleLift.bared`; the benches count the skin through a garment the same way).
THROUGH_DEPTH = 1e-3
#: How many covered body vertices may show through a frame of the garment after the lift (specks, not a
#: patch) before the post-process solves the strain limit again with the edges about them left as the models
#: made them (:meth:`TriangleLift.bared`, :func:`~cloth_usd.core.pipeline.post_process`). At 2, the sample
#: shirt's own bundle was solved again in 63 of 76 frames of CMU 09_12, its stretch p99 1.114 -> 1.154 at the
#: median frame; at 8, in 1.
BARED_TOLERANCE = 8
#: How many rings of neighbours around the triangles the body shows through the second solve leaves free.
BARED_RINGS = 3


def inner_triangles(faces: np.ndarray, num_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(inner (M', 3), ring (N, D))``: a garment's triangles none of whose corners is on its open
    edges (:func:`~cloth_usd.core.mesh.boundary_vertices`), and the rows of them around each of its
    ``num_vertices`` vertices (-1 padded)."""
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    inner = f[~np.isin(f, boundary_vertices(f)).any(axis=1)]
    return inner, incident_faces(inner, num_vertices)


def body_ahead(garment: np.ndarray, inner: np.ndarray, ring: np.ndarray, body_points: np.ndarray,
               body_normals: np.ndarray, *, reach: float = LIFT_REACH, neighbours: int = 6,
               index: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """How far body vertices lie in front of a garment, each against the nearest of its ``inner``
    triangles (:func:`inner_triangles`, ``ring`` around each vertex) around its ``neighbours`` nearest
    garment vertices.

    Args:
        garment: (N, 3) one frame of the garment [m].
        body_points, body_normals: (V, 3) body vertices [m] and their unit normals.
        reach: [m] a body vertex further than this from every inner triangle is not measured.
        index: (V, k) each body vertex's nearest garment vertices when the caller has them (N: none).
    Returns:
        ``(ahead (V,), distance (V,), barycentric (V, 3), corners (V, 3))``: how far [m] each body
        vertex lies in front of its triangle along its own normal and how far from it, NaN (corners
        -1) where none is within ``reach``; the closest point's weights and the triangle's corners.
    """
    g = np.asarray(garment, dtype=np.float64)
    q = np.asarray(body_points, dtype=np.float64)
    if index is None:
        index = search_tree(g).query(q, k=neighbours, distance_upper_bound=3 * reach)[1].reshape(len(q), -1)
    found = index < len(g)
    found[found] = ring[index[found], 0] >= 0  # a vertex with inner triangles around it
    near = np.flatnonzero(found.any(axis=1))
    ahead, distance = np.full(len(q), np.nan), np.full(len(q), np.nan)
    bary, corners = np.zeros((len(q), 3)), np.full((len(q), 3), -1, dtype=np.int64)
    if near.size:
        closest, b, c = _closest_triangle(q[near], np.zeros(near.size, dtype=np.int64),
                                          np.where(found, index, 0)[near], found[near], g, inner, ring)
        gap = vector_lengths(q[near] - closest)
        ok = gap < reach
        rows = near[ok]
        ahead[rows] = np.einsum("ic,ic->i", q[rows] - closest[ok], np.asarray(body_normals)[rows])
        distance[rows], bary[rows], corners[rows] = gap[ok], b[ok], c[ok]
    return ahead, distance, bary, corners


def covered_at_rest(rest_points: np.ndarray, faces: np.ndarray, body_points: np.ndarray,
                    body_normals: np.ndarray, *, reach: float = COVER_REACH) -> np.ndarray:
    """(V,) bool the body vertices (V, 3, at rest, unit normals (V, 3)) the rest garment covers: within
    ``reach`` [m] of one of its inner triangles (:func:`inner_triangles`) and straight under (or over)
    it, along the body vertex's normal to within 37 degrees. Skin that shows through a garment is skin
    it covers: a hand lying on a shirt's chest in a frame is in front of it too, and so is a forearm past
    a sleeve's cuff."""
    rest = np.asarray(rest_points, dtype=np.float64)
    inner, ring = inner_triangles(faces, len(rest))
    ahead, distance = body_ahead(rest, inner, ring, body_points, body_normals, reach=reach)[:2]
    with np.errstate(invalid="ignore"):
        return np.abs(ahead) >= 0.8 * distance  # NaN (not near) compares False


def edge_midpoints(points: np.ndarray, normals: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(midpoints (..., E, 3), unit normals (..., E, 3))`` of the ``edges`` (E, 2) of a mesh whose vertices are
    ``points`` (..., V, 3) with unit ``normals``: each normal the average of its ends' (the skin between a body's
    vertices, which :class:`TriangleLift` lifts the garment off and the benches count)."""
    p, n = np.asarray(points, dtype=np.float64), np.asarray(normals, dtype=np.float64)
    m = n[..., edges[:, 0], :] + n[..., edges[:, 1], :]
    m /= np.maximum(vector_lengths(m), 1e-12)[..., None]
    return 0.5 * (p[..., edges[:, 0], :] + p[..., edges[:, 1], :]), m


class TriangleLift:
    """The detail tier's last step: lift the garment's triangles off the body vertices in front of them.

    The push (:func:`push_out_of_surface`) moves vertices; a body vertex can still lie in front of a
    triangle whose three corners are out of the body (a bump of the body between them: the specks of
    skin a close-up render shows through a taut top). Per frame, each body vertex the rest garment
    covers (:func:`covered_at_rest`) that lies within ``reach`` of one of the garment's inner triangles
    is measured against the closest one around its nearest garment vertex. Where it lies in front of
    the triangle, or less than ``margin`` behind it, and the triangle faces the way the body does there
    (a sleeve's inner side next to the torso does not), the triangle's corners move along the body
    vertex's normal until it is ``margin`` behind: by their barycentric weights over their sum of
    squares (the least moves that do it). A garment vertex asked to move by several body vertices takes
    the largest move. With ``body_faces``, the midpoints of the body's edges between covered vertices are
    measured and lifted off the same way (the body between its vertices lies in front of a triangle too).

    Then the checks: a lifted vertex that the push would move (inside the body, measured as the push
    measures it: under the arm, a lift off the torso can go into the arm) goes back where it was, as
    do both ends of an edge the lift stretched past ``stretch`` (:data:`LIFT_STRETCH`) times its rest
    length; the edges are then measured again with those back, until the lift stretches none (a vertex
    lifted beside one taken back can leave their edge stretched).

    Args:
        faces: (M, 3) int the garment's triangles; rest_points: (N, 3) the rest garment [m].
        body_points, body_normals: (K, 3) the candidate body vertices the lift is called with, at rest
            (the garment's frame) [m], and their unit normals: which of them the garment covers.
        body_faces: (M', 3) int the body's triangles over those candidates: the midpoint of each of their
            edges between two covered vertices is lifted off too, its normal the average of theirs (the skin
            between the body's vertices, where a tight top shows most of its specks); None: the vertices alone.
        reach, margin: [m], see above.
        stretch: the stretch check's bound, over an edge's rest length (:data:`LIFT_STRETCH`).
        rest_lengths: (E,) [m] the rest lengths of the garment's edges (:func:`mesh_edges` of ``faces``, in its
            order) that bound the stretch; None: their lengths in ``rest_points`` (a sewn garment's are its
            pattern's).
    """

    def __init__(self, faces: np.ndarray, rest_points: np.ndarray, body_points: np.ndarray,
                 body_normals: np.ndarray, *, body_faces: np.ndarray | None = None, reach: float = LIFT_REACH,
                 margin: float = LIFT_MARGIN, stretch: float = LIFT_STRETCH,
                 rest_lengths: np.ndarray | None = None) -> None:
        self.num_vertices = len(rest_points)
        self.faces, self.ring = inner_triangles(faces, self.num_vertices)
        self.edges = mesh_edges(self.faces)
        self.all_edges = mesh_edges(faces)
        rest = np.asarray(rest_points, dtype=np.float64)
        if rest_lengths is None:
            rest_lengths = vector_lengths(rest[self.all_edges[:, 1]] - rest[self.all_edges[:, 0]])
        elif np.shape(rest_lengths) != (len(self.all_edges),):
            raise ArgumentError(f"the lift expected {len(self.all_edges)} rest lengths (the garment's edges), "
                                f"got {np.shape(rest_lengths)}")
        if not stretch >= 1.0:
            raise ArgumentError(f"the lift's stretch bound must be >= 1, got {stretch}")
        self.rest_lengths, self.stretch = np.asarray(rest_lengths, dtype=np.float64), float(stretch)
        self.cover = np.flatnonzero(covered_at_rest(rest_points, faces, body_points, body_normals))
        # the body's edges between two covered vertices: their midpoints are lifted off too
        covered = np.zeros(len(body_points), dtype=bool)
        covered[self.cover] = True
        edges = mesh_edges(body_faces) if body_faces is not None else np.zeros((0, 2), dtype=np.int64)
        self.cover_edges = edges[covered[edges].all(axis=1)]
        # each such edge's first end among the covered vertices: the midpoint is measured around that end's nearest
        # garment vertex (half a body edge away). A search of its own counted the skin through within one point at
        # the median on two clips and cost 12 ms a frame on the sample shirt's salsa against 4.4
        self._edge_end = np.searchsorted(self.cover, self.cover_edges[:, 0])
        # (N, 1 + K) each vertex and its neighbours along the inner triangles' edges (the corners of the
        # triangles around it), padded with itself
        table = neighbour_table(directed_edges(self.faces, self.num_vertices), self.num_vertices,
                                k_max=max(self.num_vertices, 1))
        self.ring_corners = np.concatenate([np.arange(self.num_vertices)[:, None], table.nbr], axis=1)
        self.reach, self.margin = float(reach), float(margin)

    def __call__(self, points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray,
                 body_faces: np.ndarray, candidates: np.ndarray, *, rings: np.ndarray | None = None,
                 trees: list | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Lift a batch.

        Args:
            points: (T, N, 3) the pushed garment [m].
            body_points, body_normals, body_faces, candidates, rings, trees: as
                :func:`push_out_of_surface` takes them (the check runs it); ``candidates`` (K,) the
                vertices the lift was made with, in their order.
        Returns:
            ``(points (T, N, 3) float64 [m], lifted (T,) int64)``: the lifted garment (a new array; a
            frame with a non-finite vertex is left as it is, for the guard) and how many of its vertices
            moved in each frame.
        """
        p = np.array(points, dtype=np.float64)
        b = np.asarray(body_points, dtype=np.float64)
        n = np.asarray(body_normals, dtype=np.float64)
        cand = np.asarray(candidates, dtype=np.int64)
        if p.ndim != 3 or p.shape[1:] != (self.num_vertices, 3) or b.ndim != 3 or b.shape != n.shape \
                or b.shape[0] != p.shape[0] or (self.cover.size and cand.size <= self.cover[-1]):
            raise ArgumentError(f"points (T, {self.num_vertices}, 3), body_points and body_normals (T, V', 3) "
                                f"and the lift's {self.cover[-1] + 1 if self.cover.size else 0}+ candidates "
                                f"expected, got {p.shape}, {b.shape}, {n.shape}, {cand.shape}")
        lifted = np.zeros(p.shape[0], dtype=np.int64)
        if not self.cover.size or not self.faces.size:
            return p, lifted
        covered, ends = cand[self.cover], cand[self.cover_edges]
        frames, rows, moves = [], [], []
        for t in range(p.shape[0]):
            if np.isfinite(p[t]).all():
                vertex, move = self._moves(p[t], *self._skin(b[t], n[t], covered, ends), self._edge_end)
                frames.append(np.full(vertex.size, t))
                rows.append(vertex)
                moves.append(move)
        if not frames or not sum(r.size for r in rows):
            return p, lifted
        frame, row, move = np.concatenate(frames), np.concatenate(rows), np.concatenate(moves)
        # the check, on the lifted vertices alone: each frame's, padded with NaN (which the push leaves)
        count = np.bincount(frame, minlength=p.shape[0])
        slot = np.arange(frame.size) - np.repeat(np.cumsum(count) - count, count)
        q = np.full((p.shape[0], int(count.max()), 3), np.nan)
        q[frame, slot] = p[frame, row] + move
        pushed = push_out_of_surface(q, b, n, body_faces, cand, margin=0.0, rings=rings, trees=trees)[0]
        keep = (pushed[frame, slot] == q[frame, slot]).all(axis=1)
        # nor may it stretch an edge past ``stretch`` times its rest length, and further than it was (only
        # an edge at a lifted vertex can): such an edge's lifted ends go back, and the edges are measured again
        # with them back (a lift kept beside one taken back can leave their edge stretched), until none is
        at_lifted = np.isin(self.all_edges, row).any(axis=1)
        e, longest = self.all_edges[at_lifted], self.stretch * self.rest_lengths[at_lifted]
        before, original = vector_lengths(p[:, e[:, 1]] - p[:, e[:, 0]]), p[frame, row]
        p[frame[keep], row[keep]] = q[frame[keep], slot[keep]]
        while True:
            after = vector_lengths(p[:, e[:, 1]] - p[:, e[:, 0]])
            at, over = np.nonzero((after > longest) & (after > before))
            stretched = np.zeros(p.shape[:2], dtype=bool)
            stretched[at, e[over, 0]] = stretched[at, e[over, 1]] = True
            back = keep & stretched[frame, row]
            if not back.any():
                break
            keep &= ~back
            p[frame[back], row[back]] = original[back]  # taken back; the others stay lifted
        np.add.at(lifted, frame[keep], 1)
        return p, lifted

    def bared(self, points: np.ndarray, body_points: np.ndarray, body_normals: np.ndarray,
              candidates: np.ndarray, *, depth: float = THROUGH_DEPTH, tolerance: int = BARED_TOLERANCE,
              rings: int = BARED_RINGS) -> tuple[np.ndarray, np.ndarray]:
        """The skin a close-up shows through the garment: the body vertices the garment covers that lie
        more than ``depth`` [m] in front of one of its inner triangles facing the way the body does there.

        Args:
            points: (T, N, 3) the garment [m].
            body_points, body_normals, candidates: as :meth:`__call__` takes them.
        Returns:
            ``(count (T,) int64, region (T, N) bool)``: how many such body vertices each frame has (-1 for a
            frame with a non-finite vertex) and, in a frame with more than ``tolerance``, their triangles'
            corners and ``rings`` rings of their neighbours (no vertex in any other frame).
        """
        p = np.asarray(points, dtype=np.float64)
        b, n = np.asarray(body_points, dtype=np.float64), np.asarray(body_normals, dtype=np.float64)
        covered = np.asarray(candidates, dtype=np.int64)[self.cover]
        count = np.zeros(p.shape[0], dtype=np.int64)
        region = np.zeros(p.shape[:2], dtype=bool)
        for t in range(p.shape[0]):
            if not np.isfinite(p[t]).all():
                count[t] = -1
            elif covered.size and self.faces.size:
                rows, _, _, corners = self._front(p[t], b[t, covered], n[t, covered], depth)
                count[t] = rows.size
                if rows.size > tolerance:
                    near = np.unique(corners)
                    for _ in range(rings):
                        near = np.unique(self.ring_corners[near])
                    region[t, near] = True
        return count, region

    @staticmethod
    def _skin(b: np.ndarray, n: np.ndarray, covered: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame's points of the covered skin: the body vertices ``b[covered]`` (with unit normals ``n``) and
        the midpoints of the body edges ``ends`` (E', 2) between them (:func:`edge_midpoints`)."""
        if not ends.size:
            return b[covered], n[covered]
        mids, normals = edge_midpoints(b, n, ends)
        return np.concatenate([b[covered], mids]), np.concatenate([n[covered], normals])

    def _front(self, g: np.ndarray, bp: np.ndarray, bn: np.ndarray, depth: float,
               edge_end: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One frame: the covered body points ``bp`` (K', 3) with unit normals ``bn`` (K', 3) that lie
        more than ``depth`` [m] in front of the closest of the garment ``g``'s (N, 3) inner triangles within
        ``reach``, and the triangle faces the way they do: ``(rows (H,), ahead (H,) [m], barycentric (H, 3),
        corners (H, 3))``. With ``edge_end`` (E',), the last E' points are body edges' midpoints, measured
        around the nearest garment vertex of the point (of the first K' - E') at each one's end."""
        e = g[self.edges[:, 0]] - g[self.edges[:, 1]]
        # a point of a triangle lies within its longest edge / sqrt(3) of one of its corners
        longest = float(np.sqrt(np.max(np.einsum("ec,ec->e", e, e))))
        ends = 0 if edge_end is None else len(edge_end)
        index = search_tree(g).query(bp[:len(bp) - ends], distance_upper_bound=self.reach + longest / np.sqrt(3.0))[1]
        if ends:
            index = np.concatenate([index, index[edge_end]])
        near = np.flatnonzero(index < g.shape[0])
        # a point of the triangles around a vertex lies in their corners' convex hull, so a body vertex
        # ``depth`` or more behind all those corners along its normal is so behind each triangle: only the
        # others are measured (on the sample shirt's salsa 25 a quarter of them, on a tight top and tight
        # trousers 68-70%)
        ahead = np.einsum("rkc,rc->rk", bp[near, None] - g[self.ring_corners[index[near]]], bn[near])
        near = near[np.max(ahead, axis=1) > depth]
        ahead, _, bary, corners = body_ahead(g, self.faces, self.ring, bp[near], bn[near], reach=self.reach,
                                             index=index[near, None])
        hit = np.flatnonzero(ahead > depth)  # NaN (not near) compares False
        tri = g[corners[hit]]
        hit = hit[np.einsum("ic,ic->i", cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), bn[near[hit]]) > 0]
        return near[hit], ahead[hit], bary[hit], corners[hit]

    def _moves(self, g: np.ndarray, bp: np.ndarray, bn: np.ndarray,
               edge_end: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One frame: ``(vertices (L,) int64, moves (L, 3) [m])`` of the garment ``g`` (N, 3) off the
        covered body points ``bp`` (K', 3) with unit normals ``bn`` (K', 3) (``edge_end``: as :meth:`_front`)."""
        rows, ahead, bary, corners = self._front(g, bp, bn, -self.margin, edge_end)
        if not rows.size:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        w = bary / np.einsum("ic,ic->i", bary, bary)[:, None]
        size = ((ahead + self.margin)[:, None] * w).ravel()  # (H * 3,) each corner's move along the normal
        vertex, along = corners.ravel(), np.repeat(bn[rows], 3, axis=0)
        order = np.lexsort((size, vertex))  # by vertex, the largest move last
        last = order[np.r_[vertex[order][1:] != vertex[order][:-1], True]]
        return vertex[last], size[last, None] * along[last]
