"""The learned tiers' pipeline, shared by inference and training (numpy only).

The runtime (:class:`cloth_usd.runtime.LearnedGarment`, ONNX models) and the training
and evaluation code (``cloth_usd.nn``, torch models) build every model input through
these functions, so a model is trained on exactly the features it is later run on:

- :func:`prepare_pair`, once per garment-body pair: association (through the skinning
  binding), the garment graph, the fit attribute alpha;
- :func:`pose_body`, per batch of frames: the posed body, its normals, and the body
  point and normal at each garment vertex's associated body vertex;
- :func:`coarse_model_features` and :func:`detail_model_inputs`: the node features of
  the two generators (:mod:`cloth_usd.core.features`; the coarse model's set is a
  :class:`CoarseFeatures`, as it was trained);
- :func:`run_tiers`: coarse model -> ``M_coarse`` -> detail model -> ``M_detail`` ->
  post-process, with the models passed in as callables (an onnxruntime session or a
  torch module), run as they were trained (:class:`CoarseForm`). The coarse model's
  displacement is added to a :class:`CoarseBase`: the associated body vertices
  (docs/method.md) or the skinned garment. With
  :attr:`~cloth_usd.core.heading.Heading.CANONICAL` the models see the body turned to face
  +Z and their garment is turned back (:mod:`cloth_usd.core.heading`).

Shape letters: T frames, N garment vertices, V body vertices, M triangles, J joints,
F factors.
"""

from __future__ import annotations

import enum
import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import ArgumentError
from .association import incident_faces
from .body import BodyModel, lbs, shape_body
from .features import (CONTACT_FEATURES, COARSE_FEATURES, attributes, coarse_features, contact_features,
                       detail_features, vertex_normals)
from .fit import FIT_LIMIT, FitModel, pair_distances
from .garment_inputs import skin_displaced
from .graph import MeshGraph, build_graph
from .heading import Heading, heading_frame
from .mesh import TAUBIN_LAMBDA, TAUBIN_MU, laplacian_smooth, neighbour_mean
from .postprocess import (DEFAULT_MARGIN, LIMIT_CHECK_TOLERANCE, StrainLimiter, TriangleLift, limit_slides,
                          push_out_of_surface, search_tree)
from .scene import Category
from .skinning import SkinBinding, bind_worn, skin_garment
from .smpl import JOINT_NAMES

__all__ = ["GarmentPair", "BodyPatch", "body_patch", "body_under", "swinging_parts", "SWINGING_JOINTS", "CONTACT_REACH",
           "PosedBody", "prepare_pair", "pose_body", "coarse_model_features", "detail_model_inputs", "run_tiers", "CoarseFn", "DetailFn",
           "CoarseBase", "coarse_base_points", "CoarseFeatures", "coarse_feature_count", "CoarseForm",
           "contact_trees", "run_garment_model", "GarmentFn", "post_process", "OWN_SMOOTHING", "smooth_along_normals"]

#: A coarse model: ``(features (B, N, F), graph) -> delta (B, N, 3) [m]`` (F: :func:`coarse_feature_count`).
CoarseFn = Callable[[np.ndarray, MeshGraph], np.ndarray]
#: A detail model: ``(features (B, N, 30), attributes (B, 85), graph) -> delta (B, N, 3) [m]``.
DetailFn = Callable[[np.ndarray, np.ndarray, MeshGraph], np.ndarray]


class CoarseBase(str, enum.Enum):
    """What the coarse model's displacement is added to: ``M_coarse = base + Delta_coarse``."""

    BODY = "body"
    """``I M_b``, each garment vertex's associated posed body vertex (docs/method.md)."""
    SKINNED = "skinned"
    """The skinning tier's garment: the rest garment carried by the body's LBS, so the model
    learns only how the garment departs from skinning (a zero displacement is the skinning tier)."""


class CoarseFeatures(str, enum.Enum):
    """The coarse model's node features (what it was trained on; a bundle's ``models.coarse.features``)."""

    BODY = "body"
    """7 per vertex: the associated posed body vertex's normal and position, and a1 (docs/method.md)."""
    CONTACT = "contact"
    """11 per vertex: those, then where the body nearest to the vertex's coarse base point is
    (:func:`~cloth_usd.core.features.contact_features`: that body vertex's normal and the
    signed distance to its tangent plane, searched in the body under the garment), so the
    model sees an arm or a thigh that skinning puts into the garment."""


def coarse_feature_count(kind: CoarseFeatures | str) -> int:
    """F, the coarse model's node features of ``kind``."""
    return COARSE_FEATURES + (CONTACT_FEATURES if CoarseFeatures(kind) is CoarseFeatures.CONTACT else 0)


@dataclass(frozen=True)
class CoarseForm:
    """How a bundle's models were trained, so how they must be run: one record for the three
    choices of the coarse model that :func:`run_tiers` follows (a bundle's
    ``models.coarse.base``, ``heading`` and ``features``). Values may be given as the enums'
    strings; an unknown one raises ValueError."""

    base: CoarseBase = CoarseBase.BODY
    """What the coarse displacement is added to."""
    heading: Heading = Heading.WORLD
    """The frame the models see the body in."""
    features: CoarseFeatures = CoarseFeatures.BODY
    """The coarse model's node features."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "base", CoarseBase(self.base))
        object.__setattr__(self, "heading", Heading(self.heading))
        object.__setattr__(self, "features", CoarseFeatures(self.features))


@dataclass(frozen=True)
class GarmentPair:
    """What the learned tiers need of one garment-body pair, computed once."""

    betas: np.ndarray
    """(B',) float64 the body's shape coefficients."""
    faces: np.ndarray
    """(M, 3) int64 garment triangles."""
    binding: SkinBinding
    """The skinning binding (its association is docs/method.md's ``I``)."""
    v_shaped: np.ndarray
    """(V, 3) float64 unposed shaped body [m]."""
    joints: np.ndarray
    """(J, 3) float64 its rest joints [m]."""
    graph: MeshGraph
    """The garment graph (neighbour table and one pooling level)."""
    alpha: np.ndarray
    """(F,) float64 the pair's fit attribute, as the models read it (clamped to
    :data:`~cloth_usd.core.fit.FIT_LIMIT`)."""
    alpha_measured: np.ndarray
    """(F,) float64 the fit attribute as measured, before the clamp."""
    patch: BodyPatch
    """The body vertices the garment's features and post-process read."""

    @property
    def assoc_vertex(self) -> np.ndarray:
        """(N,) int64 associated body vertex of each garment vertex."""
        return self.binding.association.vertex

    @property
    def num_vertices(self) -> int:
        """N."""
        return self.graph.num_vertices

    @functools.cached_property
    def rest_normals(self) -> np.ndarray:
        """(N, 3) float64 the rest garment's unit vertex normals (:attr:`binding`'s rest points), made on first
        use (what :func:`run_garment_model` smooths along)."""
        return vertex_normals(self.binding.rest_points, self.faces)

    @functools.cached_property
    def neighbour_mean(self):
        """:func:`~cloth_usd.core.mesh.neighbour_mean` of the garment's triangles, made on first use: a bake
        evaluates a few frames a call, and making it costs more than smoothing them."""
        return neighbour_mean(self.faces, self.num_vertices)


@dataclass(frozen=True)
class BodyPatch:
    """The part of the body one garment needs: its associated vertices and their one-ring.

    Posing and normals only for these (a shirt reads ~2k of the body's 13k vertices); the
    associated vertices' normals are exact, since every triangle around them is kept.
    """

    vertices: np.ndarray
    """(V',) int64 body vertex indices, sorted."""
    faces: np.ndarray
    """(M', 3) int64 the body triangles touching an associated vertex, indexing ``vertices``."""
    assoc: np.ndarray
    """(N,) int64 each garment vertex's associated body vertex, indexing ``vertices``."""
    contact: np.ndarray
    """(V'',) int64 the body under the garment, indexing ``vertices``: the associated body
    vertices and every body vertex within :data:`CONTACT_REACH` of the rest garment, in the
    T-pose or with the arms lowered (:func:`body_under`), and the arms, hands and thighs
    (:func:`swinging_parts`), each once. The post-process (and
    the physics objective's nearest contact) looks here for the body point nearest to a
    garment vertex; their normals are exact."""
    rings: np.ndarray
    """(V', D) int64 the rows of ``faces`` around each of ``vertices``, padded with -1 (the
    triangles the post-process measures a garment vertex against)."""


def body_patch(body_faces: np.ndarray, assoc_vertex: np.ndarray, near: np.ndarray | None = None) -> BodyPatch:
    """The :class:`BodyPatch` of a garment associated with ``assoc_vertex`` (N,) body vertices.

    Args:
        near: (R,) int more body vertices to take into :attr:`BodyPatch.contact` (the body
            under the garment); None: the associated ones alone.
    """
    faces = np.asarray(body_faces, dtype=np.int64)
    assoc_vertex = np.asarray(assoc_vertex, dtype=np.int64)
    touched = assoc_vertex if near is None else np.union1d(assoc_vertex, np.asarray(near, dtype=np.int64))
    used = np.zeros(int(faces.max(initial=-1)) + 1 if faces.size else 0, bool)
    used[touched[touched < len(used)]] = True
    ring = faces[used[faces].any(axis=1)] if faces.size else faces
    vertices = np.union1d(np.unique(ring), touched)
    ring = np.searchsorted(vertices, ring)
    return BodyPatch(vertices=vertices, faces=ring, assoc=np.searchsorted(vertices, assoc_vertex),
                     contact=np.searchsorted(vertices, np.unique(touched)), rings=incident_faces(ring, vertices.size))


#: Body vertices within this distance of the rest garment [m] count as the body under it
#: (:attr:`BodyPatch.contact`): where a moved garment vertex can meet the body, such as the
#: front of a thigh swung into a skirt, though no garment vertex is bound to it.
CONTACT_REACH = 0.05


#: The arms lowered from the T-pose by this much [rad] (shoulders about +-Z): the pose in
#: which the inner arms come against the garment's sides (:func:`body_under`).
ARMS_DOWN = 1.35


def body_under(v_shaped: np.ndarray, rest_points: np.ndarray, reach: float = CONTACT_REACH, *,
               arms_down: np.ndarray | None = None) -> np.ndarray:
    """(R,) int64 the body vertices within ``reach`` [m] of a rest garment vertex, in the
    T-pose or, when given, with the arms lowered (the inner arms, which press into a
    bodice's or a shirt's sides when they hang, are then the body under it too).

    Args:
        v_shaped: (V, 3) the unposed body [m]; rest_points: (N, 3) the rest garment [m].
        arms_down: (V, 3) the same body with its arms lowered [m] (:data:`ARMS_DOWN`).
    """
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(rest_points, dtype=np.float64))
    near = np.isfinite(tree.query(np.asarray(v_shaped, dtype=np.float64), distance_upper_bound=reach)[0])
    if arms_down is not None:
        near |= np.isfinite(tree.query(np.asarray(arms_down, dtype=np.float64), distance_upper_bound=reach)[0])
    return np.flatnonzero(near).astype(np.int64)


#: The joints whose vertices always count as the body under a garment (:func:`swinging_parts`):
#: the arms and legs swing against a garment in poses neither of :func:`body_under`'s
#: reaches (the hands before the belly in a run, a thigh up into a shirt's hem in a kick, the
#: knee and shin after it when the kick is high).
SWINGING_JOINTS = ("left_hip", "right_hip", "left_knee", "right_knee", "left_shoulder", "right_shoulder",
                   "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand")


def swinging_parts(body: BodyModel) -> np.ndarray:
    """(R,) int64 the body vertices skinned mostly to :data:`SWINGING_JOINTS` (the arms, hands, thighs and shins)."""
    joints = [JOINT_NAMES.index(name) for name in SWINGING_JOINTS]
    return np.flatnonzero(np.isin(np.argmax(body.weights, axis=1), joints)).astype(np.int64)


def _arms_down(body: BodyModel, v_shaped: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(V, 3) the shaped body with its arms lowered by :data:`ARMS_DOWN`."""
    pose = np.zeros((1, 72))
    pose[0, 3 * 16 + 2], pose[0, 3 * 17 + 2] = -ARMS_DOWN, ARMS_DOWN  # left and right shoulder
    return lbs(body, v_shaped, joints, pose, np.zeros((1, 3)))[0][0]


@dataclass(frozen=True)
class PosedBody:
    """The body posed for a batch of frames, as the models' features need it."""

    joints: np.ndarray
    """(T, J, 3) float64 posed joints [m], world frame (``transl`` included)."""
    garment_points: np.ndarray
    """(T, N, 3) float64 each garment vertex's associated posed body vertex [m] (``I M_b``)."""
    garment_normals: np.ndarray
    """(T, N, 3) float64 the body normals there."""
    patch_points: np.ndarray | None = None
    """(T, V', 3) float64 every posed vertex of the pair's body patch [m] (the associated
    ones and their one-ring, :attr:`BodyPatch.vertices`)."""
    patch_normals: np.ndarray | None = None
    """(T, V', 3) float64 their normals (exact at the associated vertices only)."""


def prepare_pair(body: BodyModel, betas: np.ndarray, rest_points: np.ndarray, faces: np.ndarray,
                 fit: FitModel, *, binding: SkinBinding | None = None,
                 category: Category | str = Category.TSHIRT) -> GarmentPair:
    """Association, graph and fit attribute of one garment-body pair.

    Args:
        body: the body model.
        betas: (B',) shape coefficients.
        rest_points: (N, 3) garment rest points [m], canonical body frame.
        faces: (M, 3) int garment triangles.
        fit: the fit attribute's factor-analysis model (its anchors must index ``body``).
        binding: a skinning binding of the same pair to reuse (made here if None, as
            :func:`~cloth_usd.core.skinning.bind_worn` binds a garment of ``category``).
        category: the garment's category (how it is bound when ``binding`` is None).
    """
    betas = np.asarray(betas, dtype=np.float64)
    rest_points = np.asarray(rest_points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    binding = binding if binding is not None else bind_worn(body, betas, rest_points, faces, category)
    v_shaped, joints = shape_body(body, betas)
    graph = build_graph(faces, rest_points)
    d = pair_distances(rest_points, binding.association, v_shaped, fit.anchors)
    measured = np.asarray(fit.transform(d), dtype=np.float64)
    alpha = np.clip(measured, -FIT_LIMIT, FIT_LIMIT)
    patch = body_patch(body.faces, binding.association.vertex,
                       np.union1d(body_under(v_shaped, rest_points, arms_down=_arms_down(body, v_shaped, joints)),
                                  swinging_parts(body)))
    return GarmentPair(betas=betas, faces=faces, binding=binding, v_shaped=v_shaped, joints=joints,
                       graph=graph, alpha=alpha, alpha_measured=measured, patch=patch)


def pose_body(body: BodyModel, pair: GarmentPair, poses: np.ndarray, transl: np.ndarray) -> PosedBody:
    """Pose the pair's body for a batch of frames.

    Args:
        poses: (T, 72) axis-angle [rad], canonical body frame.
        transl: (T, 3) root translation [m].
    """
    patch = pair.patch
    verts, joints = lbs(body, pair.v_shaped, pair.joints, poses, transl, vertices=patch.vertices)
    normals = vertex_normals(verts, patch.faces)
    return PosedBody(joints=joints, garment_points=verts[:, patch.assoc], garment_normals=normals[:, patch.assoc],
                     patch_points=verts, patch_normals=normals)


def contact_trees(pair: GarmentPair, posed: PosedBody) -> list:
    """A :func:`~cloth_usd.core.postprocess.search_tree` per frame over the posed body under the
    garment (:attr:`BodyPatch.contact`): what the contact features and the post-process search."""
    return [search_tree(c) for c in posed.patch_points[:, pair.patch.contact]]


def coarse_model_features(pair: GarmentPair, posed: PosedBody, transl: np.ndarray,
                          kind: CoarseFeatures | str = CoarseFeatures.BODY, *, base: np.ndarray | None = None,
                          trees: list | None = None) -> np.ndarray:
    """(T, N, F) float64 coarse node features of ``kind``
    (:func:`~cloth_usd.core.features.coarse_features`, then for :attr:`CoarseFeatures.CONTACT`
    :func:`~cloth_usd.core.features.contact_features`).

    Args:
        base: (T, N, 3) the coarse base [m] (:func:`coarse_base_points`), where the contact
            features are measured; needed by :attr:`CoarseFeatures.CONTACT` only.
        trees: :func:`contact_trees` of ``posed``, when the caller built them already.
    """
    feats = coarse_features(posed.garment_points, posed.garment_normals, np.arange(pair.num_vertices), transl,
                            pair.alpha[0])
    if CoarseFeatures(kind) is CoarseFeatures.BODY:
        return feats
    if base is None:
        raise ArgumentError("coarse_model_features: the contact features need the coarse base points")
    cloud = pair.patch.contact
    contact = contact_features(base, posed.patch_points[:, cloud], posed.patch_normals[:, cloud], trees=trees)
    return np.concatenate([feats, contact], axis=-1)


def detail_model_inputs(pair: GarmentPair, coarse_points: np.ndarray, posed: PosedBody, poses: np.ndarray,
                        transl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Detail node features on the coarse garment and the parser's attributes.

    Args:
        coarse_points: (T, N, 3) ``M_coarse`` [m], world frame.
        poses: (T, 72) axis-angle [rad]; transl: (T, 3) [m].
    Returns:
        ``(features (T, N, 30) float64, attributes (T, 85) float64)``.
    """
    feats = detail_features(coarse_points, pair.faces, posed.joints, transl)
    return feats, attributes(pair.alpha, pair.betas, poses)


def coarse_base_points(body: BodyModel, pair: GarmentPair, posed: PosedBody, poses: np.ndarray, transl: np.ndarray,
                       base: CoarseBase | str = CoarseBase.BODY, *, skinned: np.ndarray | None = None) -> np.ndarray:
    """(T, N, 3) float64 the points the coarse displacement is added to [m], world frame.

    Args:
        posed: the posed body of these frames (:func:`pose_body`).
        poses: (T, 72) axis-angle [rad]; transl: (T, 3) [m].
        base: :class:`CoarseBase`.
        skinned: (T, N, 3) float64 the skinned garment of these frames [m], in the frame
            of ``poses`` (:func:`~cloth_usd.core.skinning.skin_garment` of them), when the
            caller has it already: the :attr:`CoarseBase.SKINNED` base is then not skinned again.
    """
    if CoarseBase(base) is CoarseBase.BODY:
        return posed.garment_points
    if skinned is not None:
        return skinned
    return skin_garment(pair.binding, poses, transl, body.parents)


def post_process(pair: GarmentPair, posed: PosedBody, points: np.ndarray, *, margin: float = DEFAULT_MARGIN,
                 limiter: StrainLimiter | None = None, lift: TriangleLift | None = None,
                 trees: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The post-process of a batch of the models' garment ``points`` (T, N, 3) [m]: the strain
    ``limiter`` first (None: none), then the push out of the posed body under the garment
    (:func:`~cloth_usd.core.postprocess.push_out_of_surface`, ``margin`` [m] in front of it;
    ``trees``: :func:`contact_trees` of ``posed`` when the caller built them already), then the
    ``lift`` of the garment's triangles off the body vertices in front of them
    (:class:`~cloth_usd.core.postprocess.TriangleLift`; None: none).

    A frame whose vertices the limit would move too far
    (:func:`~cloth_usd.core.postprocess.limit_slides`: a region, not a spike pulled back) is pushed
    without it: the limit's solve does not see the body, and a move that
    far slides a region of cloth along it (a trouser leg off a thigh raised to the chest) rather
    than shortening its edges. A frame that the limit and
    the push leave more stretched than the models made it (the
    :data:`~cloth_usd.core.postprocess.LIMIT_CHECK_QUANTILE` of its edges over their rest
    lengths, by more than :data:`~cloth_usd.core.postprocess.LIMIT_CHECK_TOLERANCE`) is pushed
    again without the limit, and whichever of the two is less stretched is kept: where the body
    leaves a garment too little cloth (legs spread in a kick), limiting it pulls it into the body
    and the push tears it. With the ``lift``, a frame the limit was kept for that still shows more than
    :data:`~cloth_usd.core.postprocess.BARED_TOLERANCE` covered body vertices through the lifted garment
    (:meth:`~cloth_usd.core.postprocess.TriangleLift.bared`) is limited again with the edges about them
    left as the models made them, then pushed and lifted, and kept if it shows at most half as many: where
    the models' garment needs its stretch to cover the body (``tshirt-v6`` keeps skinning's stretched
    shoulders), the limit pulls a region into the body and the push lays it back on the skin, shrunk (CMU
    martial arts 08 at time code 1179: a patch of the shoulder). Kept where it shows fewer, it took a few
    frames of the sample shirt's own bundle from 9-12 body vertices showing to 7-10, at a stretch
    (99th percentile) 0.06-0.13 higher.

    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the garment and, per frame, how many
        vertices the push moved plus how many the lift moved.
    """
    if lift is not None and trees is None:
        trees = contact_trees(pair, posed)  # the push and the lift's check search them

    def push(m: np.ndarray, frames: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        at = slice(None) if frames is None else frames
        picked = trees if trees is None or frames is None else [trees[t] for t in frames]
        return push_out_of_surface(m, posed.patch_points[at], posed.patch_normals[at], pair.patch.faces,
                                   pair.patch.contact, margin=margin, rings=pair.patch.rings, trees=picked)

    kept = np.zeros(len(points), dtype=bool)  # the frames the limit is kept for
    if limiter is None:
        out, moved = push(points)
    else:
        points = np.asarray(points)
        limited = limiter(points)
        slides = limit_slides(points, limited)
        out, moved = push(np.where(slides[:, None, None], points, limited))
        after = limiter.stretch(out)
        worse = np.flatnonzero(~slides & (after > limiter.stretch(points) + LIMIT_CHECK_TOLERANCE))
        kept = ~slides
        if worse.size:
            alone, alone_moved = push(points[worse], worse)
            better = limiter.stretch(alone) < after[worse]
            out[worse[better]], moved[worse[better]] = alone[better], alone_moved[better]
            kept[worse[better]] = False
    if lift is None:
        return out, moved
    out, up = lift(out, posed.patch_points, posed.patch_normals, pair.patch.faces, pair.patch.contact,
                   rings=pair.patch.rings, trees=trees)
    moved = moved + up
    frames = np.flatnonzero(kept)
    shows, bared = lift.bared(out[frames], posed.patch_points[frames], posed.patch_normals[frames],
                              pair.patch.contact)
    again = bared.any(axis=1)
    if again.any():  # the second solve, where the limit bared the skin; kept where it covers half of it or more
        frames, shows, bared = frames[again], shows[again], bared[again]
        second, pushed = push(limiter(points[frames], free=bared[:, limiter.edges].any(axis=2)), frames)
        second, up = lift(second, posed.patch_points[frames], posed.patch_normals[frames], pair.patch.faces,
                          pair.patch.contact, rings=pair.patch.rings, trees=[trees[t] for t in frames])
        better = 2 * lift.bared(second, posed.patch_points[frames], posed.patch_normals[frames],
                                pair.patch.contact)[0] <= shows
        out[frames[better]], moved[frames[better]] = second[better], pushed[better] + up[better]
    return out, moved


#: A garment's own model: (T, 72) poses in the canonical heading -> (T, N, 3) displacement of
#: the unposed garment [m] (:mod:`cloth_usd.core.garment_inputs`).
GarmentFn = Callable[[np.ndarray], np.ndarray]


#: Taubin passes (:func:`smooth_along_normals`) over the part along the rest garment's normals of a garment's
#: own model's displacement, before it is skinned (:func:`run_garment_model`). The model gives each vertex an
#: output of its own, and on motion far from its training their errors show as dimples a few centimetres apart
#: (the sample shirt's back in CMU salsa 10). On the three samples' Newton test sets 0, 2 and 4 passes measured
#: 13.94 / 13.93 / 13.92 mm (the shirt's detail tier), 20.01 / 19.91 / 19.94 (trousers), 58.69 / 58.30 / 58.26
#: (dress); two passes left dimples a close-up shows, four hardly any. The shirt's membrane energy before the
#: post-process rises 75 -> 144 -> 185 J a frame (the dimples took up what skinning compresses).
OWN_SMOOTHING = 4


def smooth_along_normals(displacement: np.ndarray, normals: np.ndarray, faces: np.ndarray, passes: int, *,
                         mean=None) -> np.ndarray:
    """(T, N, 3) float64 a displacement of a garment's vertices (T, N, 3) [m] with its part along their
    ``normals`` (N, 3) (unit) smoothed by ``passes`` Taubin passes over the triangles ``faces`` and its part
    across them (the membrane's) kept as it is. ``mean``: :func:`~cloth_usd.core.mesh.neighbour_mean` of
    ``faces``, when the caller made it already."""
    d = np.asarray(displacement, dtype=np.float64)
    along = np.einsum("tnc,nc->tn", d, normals)[..., None] * normals
    smooth = laplacian_smooth(along, faces, iterations=passes, lam=TAUBIN_LAMBDA, mu=TAUBIN_MU, mean=mean)
    return d - along + np.einsum("tnc,nc->tn", smooth, normals)[..., None] * normals


def run_garment_model(body: BodyModel, pair: GarmentPair, poses: np.ndarray, transl: np.ndarray,
                      model: GarmentFn, *, batch_size: int = 16, margin: float = DEFAULT_MARGIN,
                      postprocess: bool = True, limiter: StrainLimiter | None = None,
                      lift: TriangleLift | None = None,
                      smoothing: int = OWN_SMOOTHING) -> tuple[np.ndarray, np.ndarray]:
    """Animate a garment with its own model: the model reads the pose with the heading taken
    out (so a turned character gets the same garment turned), its displacement of the unposed
    garment has its part along the rest garment's normals smoothed (``smoothing`` passes of
    :func:`smooth_along_normals`; 0: none) and is skinned with the world pose, then the post-process (as
    :func:`run_tiers`).

    Args:
        poses: (T, 72) axis-angle [rad]; transl: (T, 3) root translation [m].
        model: see :data:`GarmentFn`.
        batch_size: frames per model call.
        margin: the post-process clearance [m].
        postprocess: False leaves the model's garment as it made it.
        limiter: the post-process's first step, which shortens the edges stretched past its
            limit (:class:`~cloth_usd.core.postprocess.StrainLimiter`); None: none.
        lift: the post-process's last step (:class:`~cloth_usd.core.postprocess.TriangleLift`); None: none.
        smoothing: passes over the displacement along the normals (:data:`OWN_SMOOTHING`); 0: none.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``.
    """
    num_t, n = poses.shape[0], pair.num_vertices
    canonical = heading_frame(poses, transl, pair.joints[0]).canonical_poses(poses)
    points = np.empty((num_t, n, 3))
    moved = np.zeros(num_t, dtype=np.int64)
    for lo in range(0, num_t, batch_size):
        hi = min(lo + batch_size, num_t)
        d = np.asarray(model(canonical[lo:hi]), dtype=np.float64)
        if d.shape != (hi - lo, n, 3):
            raise ArgumentError(f"the garment model gave a displacement of shape {d.shape}, expected "
                                f"({hi - lo}, {n}, 3)")
        if smoothing:
            d = smooth_along_normals(d, pair.rest_normals, pair.faces, smoothing, mean=pair.neighbour_mean)
        m = skin_displaced(pair.binding, poses[lo:hi], transl[lo:hi], body.parents, d)
        if postprocess:
            posed = pose_body(body, pair, poses[lo:hi], transl[lo:hi])
            points[lo:hi], moved[lo:hi] = post_process(pair, posed, m, margin=margin, limiter=limiter, lift=lift)
        else:
            points[lo:hi] = m
    return points, moved


def run_tiers(body: BodyModel, pair: GarmentPair, poses: np.ndarray, transl: np.ndarray,
              coarse: CoarseFn, detail: DetailFn | None = None, *, batch_size: int = 16,
              margin: float = DEFAULT_MARGIN, form: CoarseForm = CoarseForm(),
              skinned: np.ndarray | None = None, postprocess: bool = True,
              limiter: StrainLimiter | None = None, lift: TriangleLift | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Animate a garment with a coarse model and, if given, a detail model.

    ``M_coarse = base + coarse(...)`` (``base`` ``I M_b`` or the skinned garment:
    ``form.base``, as the coarse model was trained), ``M_detail = M_coarse + detail(...)``,
    then the post-process (:func:`~cloth_usd.core.postprocess.push_out_of_surface`, against
    the body under the garment (:attr:`BodyPatch.contact`) nearest to each garment vertex in
    that frame, and the surface there).

    Args:
        poses: (T, 72) axis-angle [rad]; transl: (T, 3) root translation [m].
        coarse, detail: the models (see :data:`CoarseFn`, :data:`DetailFn`).
        batch_size: frames per model call.
        margin: the post-process clearance [m].
        form: the models' :class:`CoarseForm` (base, heading, coarse features), as they were trained.
        skinned: (T, N, 3) float64 the skinned garment of these frames [m], world frame
            (:func:`~cloth_usd.core.skinning.skin_garment` of ``poses``, ``transl``), when the
            caller has it already (the baker's guard needs it too): the skinned coarse base
            is then taken from it, turned into the canonical heading where the models see
            one, instead of skinning every frame again. Unused with a body base.
        postprocess: False leaves the models' garment as they made it (what the post-process
            starts from: how far into the body they put it); ``moved`` is then all zero.
        limiter: the post-process's first step, which shortens the edges stretched past its
            limit (:class:`~cloth_usd.core.postprocess.StrainLimiter`); None: none.
        lift: the post-process's last step (:class:`~cloth_usd.core.postprocess.TriangleLift`); None: none.
    Returns:
        ``(points (T, N, 3) float64 [m], moved (T,) int64)``: the garment per frame and
        how many vertices the post-process moved in each.
    """
    num_t, n = poses.shape[0], pair.num_vertices
    if form.base is not CoarseBase.SKINNED:
        skinned = None
    elif skinned is not None:
        skinned = np.asarray(skinned, dtype=np.float64)
        if skinned.shape != (num_t, n, 3):
            raise ArgumentError(f"skinned: expected ({num_t}, {n}, 3) for {num_t} frames of {n} vertices, "
                                f"got {skinned.shape}")
    frame = heading_frame(poses, transl, pair.joints[0]) if form.heading is Heading.CANONICAL else None
    if frame is not None:
        poses = frame.canonical_poses(poses)
        if skinned is not None:
            skinned = frame.to_canonical(skinned)
    kind = form.features
    points = np.empty((num_t, n, 3))
    moved = np.zeros(num_t, dtype=np.int64)
    for lo in range(0, num_t, batch_size):
        hi = min(lo + batch_size, num_t)
        posed = pose_body(body, pair, poses[lo:hi], transl[lo:hi])
        base = coarse_base_points(body, pair, posed, poses[lo:hi], transl[lo:hi], form.base,
                                  skinned=None if skinned is None else skinned[lo:hi])
        trees = contact_trees(pair, posed) if kind is CoarseFeatures.CONTACT else None  # searched twice, built once
        m = base + coarse(coarse_model_features(pair, posed, transl[lo:hi], kind, base=base, trees=trees), pair.graph)
        if detail is not None:
            feats, attrs = detail_model_inputs(pair, m, posed, poses[lo:hi], transl[lo:hi])
            m = m + detail(feats, attrs, pair.graph)
        if postprocess:
            points[lo:hi], moved[lo:hi] = post_process(pair, posed, m, margin=margin, limiter=limiter, lift=lift,
                                                       trees=trees)
        else:
            points[lo:hi] = m
    return (points if frame is None else frame.to_world(points)), moved
