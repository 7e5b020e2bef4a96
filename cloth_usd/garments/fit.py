"""Bring a garment modelled elsewhere onto the body: ``cloth-usd garment fit``.

1. **Units and up axis.** From the file when it says (USD ``metersPerUnit`` / ``upAxis``,
   glTF: metres, Y up); otherwise (OBJ) the unit among m, dm, cm, mm and inch that makes
   the garment's size nearest a worn garment's for this body, and both Y-up and Z-up are
   tried in the alignment.
2. **Placement in the garment's own pose.** A MakeHuman garment with its ``.mhclo`` binding
   is placed by the binding on our body posed into MakeHuman's rest pose
   (:mod:`~cloth_usd.garments.mhclo`); its skinning weights are the body's at its bound
   points. Any other garment is aligned rigidly (translation, after the units) to our
   body in each of a few arm poses from the T-pose to MakeHuman's A-pose and each turn
   about the up axis in steps of 30 degrees (a garment modelled facing another way than
   +Z), the pose and turn it lies closest to win, and the turn is refined to about a
   degree; its skinning weights are the body's at each vertex's closest surface point,
   smoothed over the garment.
3. **Unposed to the T-pose** through those weights (inverse linear blend skinning), moved
   out of the body (:func:`~cloth_usd.garments.sew.push_out`) and draped under gravity on
   the T-posed body with Newton, its rest shape being its own unposed shape; what the
   drape left inside the full-resolution body (its collider is a decimated body) is moved
   out again, 2 mm from the skin. A piece the body does not hold up (it falls in the
   drape) keeps its undraped place.
4. **Lifted off the skin between its vertices** (:func:`~.sew.lift_off_skin`): where the body
   bulges in front of a triangle whose corners are out of it (a garment coarser than the
   body, at the chest and the collars), the triangle is moved off it, 2 mm too.

Pieces (connected parts) of a mesh that belong to another category are dropped: a
T-shirt keeps the parts whose centre lies above the hips, trousers the parts with legs;
buttons and buckles go with the part they lie on.

Shape letters: N garment vertices, C polygon corners, M triangles, J joints.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..core.association import Association, associate
from ..core.body import BodyModel, joint_transforms, lbs, shape_body
from ..core.features import vertex_normals
from ..core.heading import yaw_matrices
from ..core.mesh import edge_components
from ..core.plausibility import has_legs
from ..core.rotations import axis_angle_to_matrix
from .mhclo import Mhclo, bind_mhclo, load_hm08_map, mhclo_applies
from .sew import lift_off_skin, push_out
from .source import GarmentFitError, SourceMesh

__all__ = ["FitConfig", "FittedGarment", "fit_garment", "drape", "mhclo_beside", "triangulate_polygons",
           "UNIT_CANDIDATES"]

log = logging.getLogger(__name__)

#: Metres per unit an OBJ may be in: m, dm, cm, mm, inch.
UNIT_CANDIDATES = (1.0, 0.1, 0.01, 0.001, 0.0254)
#: A worn garment's 98% box diagonal over its body's height (README: 0.44 to 0.95).
_TYPICAL_SIZE = 0.7
#: Z-up to Y-up: (x, y, z) -> (x, z, -y).
_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: SMPL joints used to place and split a garment.
_PELVIS, _NECK = 0, 12
#: [m] a piece whose median vertex drops further than this in the drape fell off the body.
FALL = 0.03
#: [m] a piece smaller than this (its box's diagonal) is a decoration: it goes with the piece it lies on.
DECORATION_SIZE = 0.1
#: [m] a decoration further than this (its median vertex) from every kept piece is dropped.
DECORATION_GAP = 0.02


@dataclass(frozen=True)
class FitConfig:
    """How a garment is fitted."""

    arm_poses: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
    """Fractions of MakeHuman's rest pose (0: T-pose, 1: MakeHuman's A-pose) tried for a
    garment without a binding."""
    in_between_margin: float = 0.05
    """Garments are modelled in the T-pose or the A-pose: an arm pose strictly between the
    first and the last of ``arm_poses`` is taken only if its alignment distance is this
    fraction smaller (a short sleeve hangs a little below the T-posed arm, which a slightly
    lowered arm matches as well)."""
    turns: tuple[float, ...] = tuple(float(a) for a in range(0, 360, 30))
    """Turns about the up axis [deg] tried for a garment without a binding (0: it faces +Z,
    as the body does); the best is then refined (:attr:`turn_refine`)."""
    turn_refine: float = 0.5
    """The best turn is refined by halving steps from half the grid's spacing down to the
    last one no smaller than this [deg] (15, 7.5, ... 0.94), each taken only where it brings
    the garment closer to the body; 0 keeps the grid's turn."""
    turn_margin: float = 0.15
    """A turn other than 0 is taken only if its alignment distance is this fraction smaller:
    a garment's front and back look alike, so the file's own facing is trusted unless
    another is clearly closer."""
    icp_iterations: int = 20
    """Translation updates of the rigid alignment."""
    align_sample: int = 2000
    """At most this many of the garment's vertices (evenly spread over its numbering) are
    aligned when turns and arm poses are compared; the garment then moves as they do."""
    weight_smoothing: int = 10
    """Passes of neighbour averaging of the skinning weights over the garment."""
    clearance: float = 0.006
    """Distance [m] a vertex is kept from the body's surface before the drape."""
    drape_frames: int = 16
    """Frames (24 fps) hanging under gravity on the T-posed body; 0 skips the drape."""
    final_clearance: float = 0.002
    """After the drape, a vertex inside the full-resolution body or nearer than this [m] to
    it is moved out to this distance along the surface normal."""
    lift_rounds: int = 2
    """Rounds of the lift of the garment's triangles off the skin between its vertices, to
    :attr:`final_clearance` behind them (:func:`~cloth_usd.garments.sew.lift_off_skin`); 0: none."""
    max_median_distance: float = 0.12
    """A garment whose median vertex lies further [m] from the body after alignment is refused."""


@dataclass(frozen=True)
class FittedGarment:
    """A garment fitted to the T-posed body."""

    points: np.ndarray
    """(N, 3) float64 worn at rest [m], canonical body frame."""
    face_counts: np.ndarray
    """(P,) int64 corners per polygon (the input's polygons, of the pieces kept)."""
    face_indices: np.ndarray
    """(C,) int64 vertex of each corner."""
    uv: np.ndarray | None
    """(U, 2) float64 the input's UVs, or None."""
    uv_indices: np.ndarray | None
    """(C,) int64 UV of each corner, or None."""
    report: dict = field(default_factory=dict)
    """JSON-able: how it was fitted (method, units, up axis, pose, distances, time)."""


def triangulate_polygons(counts: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangulation.

    Args:
        counts: (P,) int corners per polygon; indices: (C,) int vertex per corner.
    Returns:
        ``(triangles (M, 3) int64 vertices, polygon (M,) int64 the polygon each came from)``.
    """
    counts = np.asarray(counts, dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris, owner = [], []
    for k in range(3, int(counts.max(initial=0)) + 1):
        sel = np.flatnonzero(counts >= k)
        if len(sel):
            tris.append(np.stack([start[sel], start[sel] + k - 2, start[sel] + k - 1], axis=1))
            owner.append(sel)
    if not tris:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    corner = np.concatenate(tris)
    return np.asarray(indices, dtype=np.int64)[corner], np.concatenate(owner)


def _components(num: int, tri: np.ndarray) -> np.ndarray:
    return edge_components(num, np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]]]))


def _box(points: np.ndarray) -> np.ndarray:
    """(3,) the sides of the box holding 98% of the points."""
    return np.percentile(points, 99, axis=0) - np.percentile(points, 1, axis=0)


def _guess_unit(points: np.ndarray, height: float) -> float:
    diag = float(np.linalg.norm(_box(points)))
    ratios = [abs(np.log(max(diag * u, 1e-12) / (_TYPICAL_SIZE * height))) for u in UNIT_CANDIDATES]
    return UNIT_CANDIDATES[int(np.argmin(ratios))]


def _units(src: SourceMesh, height: float) -> tuple[float, str]:
    """Metres per unit and where that came from: the file, or (no units in the file, or
    units that make the garment implausibly sized: USD's unauthored default of centimetres
    on a file in metres) the size guess."""
    guess = _guess_unit(src.points, height)
    if src.meters_per_unit is None:
        return guess, "size"
    ratio = float(np.linalg.norm(_box(src.points))) * src.meters_per_unit / height
    if 0.15 <= ratio <= 3.0:
        return src.meters_per_unit, "file"
    log.warning("%s: in the units its file says (%g m) the garment would be %.2f times the body's height; "
                "using %g m per unit", src.source, src.meters_per_unit, ratio, guess)
    return guess, "size"


def _smooth_weights(weights: np.ndarray, tri: np.ndarray, passes: int) -> np.ndarray:
    if passes <= 0 or not len(tri):
        return weights
    n = len(weights)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    adj = sparse.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                            shape=(n, n)).tocsr()
    adj = adj + sparse.eye(n)
    adj = sparse.diags(1.0 / np.asarray(adj.sum(axis=1)).ravel()) @ adj
    for _ in range(passes):
        weights = adj @ weights
    return weights


def _pose(body: BodyModel, v_shaped: np.ndarray, joints: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return lbs(body, v_shaped, joints, pose[None])[0][0]


def _unpose(points: np.ndarray, weights: np.ndarray, joints: np.ndarray, pose: np.ndarray,
            parents: np.ndarray) -> np.ndarray:
    """(N, 3) points in ``pose`` carried back to the rest pose by inverse blend skinning."""
    rot = axis_angle_to_matrix(pose.reshape(1, -1, 3))
    _, skin = joint_transforms(rot, joints, parents)  # (1, J, 3, 4)
    blended = np.einsum("nj,jab->nab", weights, skin[0])  # (N, 3, 4)
    return np.linalg.solve(blended[:, :, :3], (points - blended[:, :, 3])[..., None])[..., 0]


def _align(points: np.ndarray, category: str, posed: np.ndarray, faces: np.ndarray, joints: np.ndarray,
           iterations: int) -> tuple[np.ndarray, float]:
    """Translate a garment onto a posed body; ``(shift (3,) [m], score [m])``: the score is
    the mean distance of the garment's vertices to the body's (clipped at 0.3 m), and the
    shift the best-scoring one the iterations visited."""
    tree = cKDTree(posed)
    top = np.percentile(points[:, 1], 99)
    anchor = joints[_NECK, 1] + 0.02 if category != "trousers" else joints[_PELVIS, 1] + 0.12
    centre_x = 0.5 * (np.percentile(points[:, 0], 1) + np.percentile(points[:, 0], 99))  # garments are symmetric
    shift = np.array([-centre_x, anchor - top, 0.0])
    band = np.abs(posed[:, 1] - (np.median(points[:, 1]) + shift[1])) < 0.1
    shift[2] = (np.median(posed[band, 2]) if np.any(band) else 0.0) - np.median(points[:, 2])
    normals = vertex_normals(posed, faces)

    def score(at: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        d, i = tree.query(points + at)
        return float(np.mean(np.minimum(d, 0.3))), d, i

    best, d, i = score(shift)
    best_shift = shift
    for _ in range(iterations):
        keep = d <= np.percentile(d, 80)
        # point-to-plane: the translation that best brings each vertex onto its nearest
        # body vertex's tangent plane (a garment may slide along the skin, not through it)
        n = normals[i[keep]]
        r = np.einsum("nc,nc->n", posed[i[keep]] - (points[keep] + shift), n)
        a = n.T @ n
        step = np.linalg.solve(a + 0.05 * np.trace(a) / 3 * np.eye(3), n.T @ r)  # weak directions stay put
        shift = shift + step
        value, d, i = score(shift)
        if value < best:
            best, best_shift = value, shift
        if np.linalg.norm(step) < 1e-4:
            break
    return best_shift, best


def _sample(count: int, most: int) -> np.ndarray:
    """(min(count, most),) int64 indices spread evenly over ``range(count)``."""
    return np.unique(np.linspace(0, count - 1, min(count, max(most, 1))).astype(np.int64))


def _refine_turn(upright: np.ndarray, sample: np.ndarray, turn: float, score: float, placed: np.ndarray,
                 category: str, posed: np.ndarray, faces: np.ndarray, joints: np.ndarray,
                 config: FitConfig) -> tuple[float, float, np.ndarray]:
    """``(turn [deg], score [m], placed (N, 3))``: the grid's best turn refined by halving steps
    about the up axis (a garment modelled at 137 degrees is found at 120 or 150 on a
    30-degree grid, then brought within about a degree); ``sample`` the vertices aligned."""
    turns = np.sort(np.asarray(config.turns, dtype=np.float64) % 360.0)
    if config.turn_refine <= 0 or len(turns) < 2:
        return turn, score, placed
    step = 0.5 * float(np.min(np.diff(np.r_[turns, turns[0] + 360.0])))
    while step >= config.turn_refine:
        for candidate in (turn - step, turn + step):
            pts = upright @ yaw_matrices(np.deg2rad(candidate)).T
            shift, value = _align(pts[sample], category, posed, faces, joints, config.icp_iterations)
            if value < score:
                turn, score, placed = candidate, value, pts + shift
                break
        step *= 0.5
    return turn, score, placed


def _check_shape(src: SourceMesh, tri: np.ndarray) -> None:
    name = src.source or "the mesh"
    if src.num_vertices < 3 or not len(tri):
        raise GarmentFitError(f"{name}: holds no polygons; a garment mesh is needed")
    if not np.all(np.isfinite(src.points)):
        raise GarmentFitError(f"{name}: has NaN or infinite vertex positions")
    box = np.sort(_box(src.points[np.unique(tri)]))
    if box[2] <= 0 or box[0] < 0.02 * box[2] or box[1] < 0.1 * box[2]:
        raise GarmentFitError(f"{name}: is flat or a strip (its box is {box[0]:.3g} x {box[1]:.3g} x {box[2]:.3g} "
                              "units); a garment wraps round the body, so it cannot be fitted")


def _keep_pieces(points: np.ndarray, tri: np.ndarray, category: str, joints: np.ndarray,
                 source: str) -> tuple[np.ndarray, int]:
    """``(keep (N,) bool, pieces dropped)``: the vertices of the pieces (connected parts) that
    belong to ``category`` (vertices in no polygon are dropped too, uncounted); ``source``
    names the file in the refusal when none does.

    A T-shirt keeps the pieces whose centre lies above the hips; trousers the pieces with
    legs (:func:`~cloth_usd.core.plausibility.has_legs`: a bib overall has them, a coat or a jacket does not). A piece
    smaller than :data:`DECORATION_SIZE` (a button, a buckle) goes with the kept piece it
    lies on, within :data:`DECORATION_GAP`."""
    label = _components(len(points), tri)
    used = np.zeros(len(points), dtype=bool)
    used[np.unique(tri)] = True
    keep = used.copy()
    if category == "dress":
        return keep, 0
    pieces = [(label == c) & used for c in np.unique(label[used])]
    for sel in pieces:
        if category == "tshirt":
            keep[sel] = float(np.median(points[sel, 1])) >= joints[_PELVIS, 1]
        else:  # trousers
            keep[sel] = has_legs(points, tri, sel, joints[_PELVIS])
    decorations = [sel for sel in pieces if float(np.linalg.norm(np.ptp(points[sel], axis=0))) < DECORATION_SIZE]
    carriers = keep & ~np.logical_or.reduce(decorations) if decorations else keep
    tree = cKDTree(points[carriers]) if np.any(carriers) else None
    for sel in decorations:
        keep[sel] = tree is not None and float(np.median(tree.query(points[sel])[0])) <= DECORATION_GAP
    if not keep.any():
        raise GarmentFitError(f"{source}: no piece of the mesh sits where a {category} is worn (every part was "
                              "dropped)")
    return keep, sum(not keep[sel].any() for sel in pieces)


def fit_garment(src: SourceMesh, category: str, betas: np.ndarray, *, body: BodyModel,
                mhclo: Mhclo | None = None, config: FitConfig = FitConfig()) -> FittedGarment:
    """Fit a garment mesh to the T-posed body of ``betas`` (see the module's docstring).

    Raises:
        GarmentFitError: the mesh is empty, flat, or lies nowhere near the body.
    """
    began = time.perf_counter()
    tri, _ = triangulate_polygons(src.face_counts, src.face_indices)
    _check_shape(src, tri)
    betas = np.asarray(betas, dtype=np.float64)
    v_rest, joints = shape_body(body, betas)
    height = float(v_rest[:, 1].max() - v_rest[:, 1].min())
    hmap = load_hm08_map()
    a_pose = hmap.pose if hmap is not None else _fallback_a_pose()
    report: dict = {"source": src.source, "input_vertices": src.num_vertices}

    why_not = mhclo_applies(mhclo, hmap, body, src.num_vertices) if mhclo is not None else "no .mhclo binding"
    if why_not is None:
        posed_points, weights = bind_mhclo(mhclo, hmap, body, betas)
        pose = a_pose
        report.update(method="mhclo", units_m=0.1, up_axis="Y", arm_pose=1.0)
    else:
        if mhclo is not None:
            log.warning("%s: the .mhclo binding does not apply (%s); fitting by shape", src.source, why_not)
        unit, units_from = _units(src, height)
        ups = [src.up_axis] if src.up_axis else ["Y", "Z"]
        best = None
        poses = {frac: _pose(body, v_rest, joints, a_pose * frac) for frac in config.arm_poses}
        sample = _sample(src.num_vertices, config.align_sample)
        ends = (config.arm_poses[0], config.arm_poses[-1])
        for up in ups:
            upright = src.points * unit @ (_Z_UP.T if up == "Z" else np.eye(3))
            for turn in config.turns:
                pts = upright @ yaw_matrices(np.deg2rad(turn)).T
                for frac, posed in poses.items():
                    shift, score = _align(pts[sample], category, posed, body.faces, joints, config.icp_iterations)
                    log.debug("up %s turn %g arm pose %.2f: mean distance %.1f mm", up, turn, frac, score * 1e3)
                    ranked = score * (1.0 + config.in_between_margin) if frac not in ends else score
                    ranked *= (1.0 + config.turn_margin) if turn % 360.0 else 1.0
                    if best is None or ranked < best[0]:
                        best = (ranked, score, up, turn, frac, pts + shift, a_pose * frac, posed, upright)
        _, score, up, turn, frac, posed_points, pose, posed, upright = best
        turn, score, posed_points = _refine_turn(upright, sample, turn, score, posed_points, category, posed,
                                                 body.faces, joints, config)
        a = associate(posed_points, posed, body.faces)
        weights = np.einsum("nk,nkj->nj", a.barycentric, body.weights[body.faces[a.triangle]])
        weights = _smooth_weights(weights, tri, config.weight_smoothing)
        median = float(np.median(a.distance))
        if median > config.max_median_distance:
            raise GarmentFitError(f"{src.source}: does not fit the body: after alignment its median vertex is "
                                  f"{median:.2f} m from the body's surface (at most {config.max_median_distance} m); "
                                  "is it a garment, and in the units its file says?")
        report.update(method="shape", units_m=unit, units_from=units_from, up_axis=up,
                      turned_deg=round(float(turn) % 360.0, 1), arm_pose=frac,
                      align_mean_mm=round(score * 1e3, 1), **({"mhclo_skipped": why_not} if mhclo is not None else {}))
    keep, dropped = _keep_pieces(posed_points, tri, category, joints, src.source)
    if category != "trousers" and has_legs(posed_points, tri, keep, joints[_PELVIS]):
        # a MakeHuman suit (shirt and trousers in one piece) fitted as a T-shirt: tshirt-v6's models hung a
        # sheet of cloth between its legs; its own (train-garment) hang two trouser legs
        log.warning("%s: it has legs (two tubes below the hips: a suit or an overall in one piece), which no %s "
                    "the %s bundles were trained on has, and their learned tiers read it as one; give it models "
                    "of its own (cloth-usd train-garment) or bake it with --tier skinning", src.source, category,
                    category)
        report.update(legs=True)
    rest = _unpose(posed_points, weights, joints, pose, body.parents)
    # the pieces kept, renumbered; polygons with a dropped vertex go
    new_index = np.cumsum(keep) - 1
    starts = np.concatenate([[0], np.cumsum(src.face_counts)[:-1]])
    poly_keep = np.logical_and.reduceat(keep[src.face_indices], starts) if len(starts) else np.zeros(0, bool)
    corner_keep = np.repeat(poly_keep, src.face_counts)
    counts = src.face_counts[poly_keep]
    indices = new_index[src.face_indices[corner_keep]]
    rest = rest[keep]
    uv_indices = src.uv_indices[corner_keep] if src.uv_indices is not None else None
    rest = push_out(rest, np.asarray(v_rest), body.faces, clearance=config.clearance)
    tri_kept, _ = triangulate_polygons(counts, indices)
    if config.drape_frames > 0:
        rest, undraped = _hang(body, betas, rest, tri_kept, config.drape_frames, src.source)
        report.update(pieces_undraped=undraped)
        # the drape's collider is the body decimated (6000 faces): on it, a vertex can sit a
        # few millimetres inside the full body (measured on a MakeHuman suit: 5.8% of its
        # vertices, 1.9 mm deep at the median, 32 mm at most, at the hips and the armpits)
        depth = _depth(rest, np.asarray(v_rest), body.faces)
        report.update(inside_after_drape=round(float(np.mean(depth < 0)), 4),
                      inside_after_drape_max_mm=round(float(max(-depth.min(), 0.0)) * 1e3, 1))
        rest = push_out(rest, np.asarray(v_rest), body.faces, clearance=config.final_clearance)
    if config.lift_rounds > 0:
        rest, through = lift_off_skin(rest, tri_kept, np.asarray(v_rest), body.faces,
                                      margin=config.final_clearance, rounds=config.lift_rounds)
        report.update(skin_through_before=through[0], skin_through=through[1])
    final = associate(rest, np.asarray(v_rest), body.faces)
    report.update(vertices=int(len(rest)), polygons=int(len(counts)), triangles=int(len(tri_kept)),
                  pieces_dropped=dropped,
                  median_distance_mm=round(float(np.median(final.distance)) * 1e3, 1),
                  inside_fraction=round(float(np.mean(_depth(rest, np.asarray(v_rest), body.faces, final) < 0)), 4),
                  seconds=round(time.perf_counter() - began, 1))
    return FittedGarment(points=rest, face_counts=counts, face_indices=indices, uv=src.uv, uv_indices=uv_indices,
                         report=report)


def _depth(points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray,
           a: Association | None = None) -> np.ndarray:
    """(N,) signed distance [m] of each point from its closest body surface point along the
    surface normal there: negative inside the body."""
    a = a if a is not None else associate(points, body_vertices, body_faces)
    corners = body_faces[a.triangle]
    closest = np.einsum("nk,nkc->nc", a.barycentric, body_vertices[corners])
    normal = np.einsum("nk,nkc->nc", a.barycentric, vertex_normals(body_vertices, body_faces)[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return np.einsum("nc,nc->n", points - closest, normal)


def _fallback_a_pose() -> np.ndarray:
    """(72,) arms 45 degrees down, for a body without the shipped hm08 map."""
    pose = np.zeros((24, 3))
    pose[16, 2], pose[17, 2] = -np.pi / 4, np.pi / 4
    return pose.ravel()


def drape(body: BodyModel, betas: np.ndarray, points: np.ndarray, tri: np.ndarray, *, frames: int) -> np.ndarray:
    """(N, 3) a garment hung ``frames`` frames under gravity on the T-posed body (Newton VBD,
    the sewing material), its rest shape its current shape."""
    from ..datagen.simulate import _import_engine, make_collider, resolve_device
    from .sew import SewConfig, _simulate, quiet_warp

    quiet_warp()
    newton, wp = _import_engine()
    cfg = SewConfig().sim
    v_rest, _ = shape_body(body, betas)
    collider = make_collider(body, betas, cfg.collider_faces)
    col_points = collider.pose(np.asarray(v_rest)[None], body.faces)[0]
    return _simulate(newton, wp, resolve_device(cfg.device), points, tri, collider_points=col_points,
                     collider_faces=collider.faces, frames=frames, gravity=cfg.gravity, cfg=cfg)


def _hang(body: BodyModel, betas: np.ndarray, points: np.ndarray, tri: np.ndarray, frames: int,
          source: str) -> tuple[np.ndarray, int]:
    """``(draped (N, 3), pieces kept in place)``: the drape, where no piece falls off the body.
    A piece the body does not hold up (trousers too wide for the hips, a bib overall without
    its straps, a button) falls in the drape: it keeps the place the fit gave it instead."""
    label = _components(len(points), tri)
    draped = drape(body, betas, points, tri, frames=frames)
    fallen = _fallen(points, draped, label)
    for c in fallen:
        draped[label == c] = points[label == c]
    if fallen:
        sizes = ", ".join(str(int(np.sum(label == c))) for c in fallen)
        log.warning("%s: %d piece(s) (%s vertices) fell off the body in the drape (nothing on the body holds "
                    "them up); they keep the place the fit gave them, undraped", source, len(fallen), sizes)
    return draped, len(fallen)


def _fallen(before: np.ndarray, after: np.ndarray, label: np.ndarray) -> list[int]:
    """The pieces (``label`` values) whose median vertex dropped more than :data:`FALL` [m]."""
    drop = before[:, 1] - after[:, 1]
    return [int(c) for c in np.unique(label) if float(np.median(drop[label == c])) > FALL]


def mhclo_beside(path: str | Path) -> Path | None:
    """The ``.mhclo`` file next to a MakeHuman ``.obj`` (same stem), if any."""
    candidate = Path(path).with_suffix(".mhclo")
    return candidate if candidate.is_file() else None
