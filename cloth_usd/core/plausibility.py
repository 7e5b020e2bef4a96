"""Is a garment plausibly worn by its body? Its size against the body's height and its
distance from the body's bones, from the rest skeleton alone (no body model needed); and,
with the body model, how much of it lies inside the shaped body and how far it lies from
the body's surface.

A garment authored in the wrong units (a MakeHuman top left in decimetres is 10 times too
big), placed away from its character, or made for another body shape reads without a
contract violation; these numbers let ``inspect`` and ``bake`` warn about it and ``bake``
refuse a garment many times too big. Shape letters: N garment vertices, J joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .association import surface_at
from .body import BodyModel, shape_body
from .features import vertex_normals
from .mesh import edge_components
from .skinning import SkinBinding
from .smpl import JOINT_NAMES, PARENTS

__all__ = ["HEIGHT_PER_HEAD_ANKLE", "SIZE_WARN", "SIZE_SMALL", "SIZE_REFUSE", "FAR_FROM_BONES", "FAR_FROM_BODY",
           "INSIDE_AT_REST", "INSIDE_DEPTH", "GarmentScale", "garment_scale", "scale_notes", "inside_at_rest",
           "body_notes", "has_legs", "THIGH_BELOW_HIPS", "LEG_OPENING", "LEG_TOP", "LEG_SIDE"]

#: Body height [m] per head-joint-to-mid-ankle distance [m]: 1.69 m / 1.46 m for the
#: embedded SMPL-format body at zero betas (the head joint sits below the crown, the ankles
#: above the soles).
HEIGHT_PER_HEAD_ANKLE = 1.16
#: ``inspect`` warns above this ratio of the garment's bounding-box diagonal to the body's
#: height. A T-posed long-sleeved shirt is about 1.1, a floor-length dress about 1.0.
SIZE_WARN = 1.6
#: ... and below this one (a garment in metres read as centimetres is 0.01).
SIZE_SMALL = 0.1
#: ``bake`` refuses a garment larger than this many times the body's height unless told otherwise.
SIZE_REFUSE = 3.0
#: ``inspect`` warns when the garment's median vertex lies further than this from the body's
#: bones [m]: a worn garment is within a torso's half depth plus its ease (about 0.15 m).
FAR_FROM_BONES = 0.35
#: A garment whose rest vertices lie further than this from the body surface on
#: average [m] is warned about: its ``cloth:body`` may target the wrong character.
FAR_FROM_BODY = 0.10
#: A garment with more than this share of its rest vertices deeper than :data:`INSIDE_DEPTH`
#: in its body, in the rest pose, is warned about: it was made for a smaller body (other
#: betas) or sits in it, and every tier starts from it there.
INSIDE_AT_REST = 0.05
#: How deep [m] a rest vertex must lie in the body to count for :data:`INSIDE_AT_REST` (a
#: tight garment touches the body; 2 mm in is a garment in the body).
INSIDE_DEPTH = 0.002

_HEAD = JOINT_NAMES.index("head")
_ANKLES = [JOINT_NAMES.index("left_ankle"), JOINT_NAMES.index("right_ankle")]
#: At most this many vertices are measured (evenly strided): the median needs no more.
_SAMPLE = 4096
#: [m] trousers' legs are looked for this far below the hip joints (the upper thigh, 7 cm
#: below the crotch of the mean body): there a piece with legs parts into a left and a right
#: tube, where a skirt or a coat stays one.
THIGH_BELOW_HIPS = 0.2
#: [m] shorts whose legs end above :data:`THIGH_BELOW_HIPS` (hot pants) are looked at this far
#: above their lowest point: their leg openings.
LEG_OPENING = 0.02
#: [m] legs are looked for no higher than this below the hip joints (the mean body's crotch
#: lies 13 cm below them): a piece that ends above it (a jacket, a crop top) has none.
LEG_TOP = 0.1
#: [m] a leg's middle lies at least this far to the side of the hip joints (a thigh's lies 8-10
#: cm off): the front and back panels of a shirt with side slits do not make legs.
LEG_SIDE = 0.03


@dataclass(frozen=True)
class GarmentScale:
    """How a garment's rest points sit on its body's rest skeleton."""

    diagonal: float
    """The diagonal of the garment's bounding box [m], taken over the 1st to 99th percentile
    of its vertices on each axis: a stray vertex or two (a garment of loose pieces) does not
    make it huge, a garment in the wrong units still is."""
    body_height: float
    """The body's height [m], estimated from its head and ankle joints."""
    distance: float
    """Median distance of the garment's vertices from the nearest bone segment [m]."""

    @property
    def ratio(self) -> float:
        """The garment's bounding-box diagonal over the body's height."""
        return self.diagonal / self.body_height


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to the nearest of the segments a[k]..b[k] (K, 3)."""
    ab = b - a  # (K, 3)
    ap = points[:, None, :] - a[None]  # (N, K, 3)
    t = np.clip(np.einsum("nkc,kc->nk", ap, ab) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=-1).min(axis=1)


def garment_scale(rest_points: np.ndarray, rest_joints: np.ndarray) -> GarmentScale:
    """Measure a garment against its body's rest skeleton.

    Args:
        rest_points: (N, 3) float garment rest points [m], the frame of ``rest_joints``.
        rest_joints: (24, 3) float SMPL joint positions of the body at rest [m].
    """
    points = np.asarray(rest_points, dtype=np.float64)
    joints = np.asarray(rest_joints, dtype=np.float64)
    if points.shape[0] == 0:
        return GarmentScale(0.0, 1.0, float("inf"))
    lo, hi = np.percentile(points, [1.0, 99.0], axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    height = HEIGHT_PER_HEAD_ANKLE * float(np.linalg.norm(joints[_HEAD] - joints[_ANKLES].mean(0)))
    sample = points[:: max(1, points.shape[0] // _SAMPLE)]
    child = np.arange(1, len(PARENTS))
    distance = float(np.median(_segment_distance(sample, joints[PARENTS[child]], joints[child])))
    return GarmentScale(diagonal=diagonal, body_height=max(height, 1e-9), distance=distance)


def scale_notes(scale: GarmentScale) -> list[str]:
    """One line for each implausibility of ``scale`` (empty when it looks worn)."""
    notes = []
    figure = (f"its bounding box ({scale.diagonal:.3g} m diagonal) is {scale.ratio:.2g} times the body's "
              f"height ({scale.body_height:.2f} m)")
    if scale.ratio > SIZE_WARN:
        notes.append(f"{figure}: check its units (metersPerUnit, or a scale on the prim)")
    elif scale.ratio < SIZE_SMALL:
        notes.append(f"{figure}: too small to be worn; check its units (metersPerUnit, or a scale on the prim)")
    if scale.distance > FAR_FROM_BONES:
        notes.append(f"its vertices lie {scale.distance:.2f} m from the body's bones (median; a worn garment is "
                     f"within {FAR_FROM_BONES:g} m): check its placement and cloth:body")
    return notes


def inside_at_rest(binding: SkinBinding, body: BodyModel, betas: np.ndarray) -> np.ndarray:
    """(N,) each rest garment vertex's depth inside its body in the rest pose [m] (0 outside):
    its signed distance, along the body normal interpolated at its nearest surface point (the
    binding's association), negated where negative.

    Args:
        binding: the garment bound to the body of shape ``betas`` (its association is against
            that shaped, unposed body).
    """
    v_shaped, _ = shape_body(body, betas)
    closest, normal = surface_at(binding.association, v_shaped, vertex_normals(v_shaped, body.faces), body.faces)
    return np.maximum(-np.einsum("nc,nc->n", binding.rest_points - closest, normal), 0.0)


def body_notes(binding: SkinBinding, body: BodyModel, betas: np.ndarray, body_prim: str) -> list[str]:
    """One line for each way the bound garment does not sit on its shaped body at rest: more
    than :data:`INSIDE_AT_REST` of it deeper than :data:`INSIDE_DEPTH` inside, or further
    than :data:`FAR_FROM_BODY` from it on average (empty when it sits on it).

    Args:
        binding: the garment bound to the body of shape ``betas``.
        body_prim: the body's prim path, named in the lines.
    """
    notes = []
    depth = inside_at_rest(binding, body, betas)
    inside = float(np.mean(depth > INSIDE_DEPTH))
    if inside > INSIDE_AT_REST:
        notes.append(f"{inside:.0%} of the garment's vertices lie more than {INSIDE_DEPTH * 1e3:g} mm inside the body "
                     f"<{body_prim}> at rest (up to {depth.max() * 1e3:.0f} mm): it was made for another body "
                     "shape, or sits in the body; every tier starts from it there")
    distance = float(binding.association.distance.mean())
    if distance > FAR_FROM_BODY:
        notes.append(f"the garment lies {distance:.2f} m from the body <{body_prim}> on average at rest (a worn "
                     f"garment is within {FAR_FROM_BODY:g} m); check its cloth:body and rest points")
    return notes


def has_legs(points: np.ndarray, tri: np.ndarray, piece: np.ndarray, pelvis: np.ndarray) -> bool:
    """Whether the ``piece`` (N,) bool of the garment (``points`` (N, 3) [m], ``tri`` (M, 3)) has
    legs: its vertices :data:`THIGH_BELOW_HIPS` below the ``pelvis`` joint (3,) [m] (or, for a
    piece that ends above that, within :data:`LEG_OPENING` of its lowest point, if that lies
    :data:`LEG_TOP` below the joint), joined by the mesh's edges between them, part into
    pieces on the left and the right of it, at least :data:`LEG_SIDE` off. Thighs that touch
    (a heavy body) do not join two legs, as a test of nearness to the midline would; edges
    rather than whole triangles join them, so that a hem of one row of vertices is a ring."""
    if not piece.any():
        return False
    level = max(pelvis[1] - THIGH_BELOW_HIPS, float(points[piece, 1].min()) + LEG_OPENING)
    if level > pelvis[1] - LEG_TOP:
        return False
    below = piece & (points[:, 1] < level)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    edges = edges[np.all(below[edges], axis=1)]
    if not len(edges):
        return False
    used = np.unique(edges)
    label = edge_components(len(points), edges)[used]
    parts, sizes = np.unique(label, return_counts=True)
    offsets = [float(np.median(points[used[label == c], 0]) - pelvis[0]) for c in parts[sizes >= 3]]
    return {-1.0, 1.0} <= {float(np.sign(o)) for o in offsets if abs(o) >= LEG_SIDE}
