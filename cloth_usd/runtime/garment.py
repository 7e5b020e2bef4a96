"""One garment animated by a model bundle (the coarse and detail tiers of docs/method.md).

Everything that depends only on the garment-body pair is computed once, when a
:class:`LearnedGarment` is made: the association (through the skinning binding), the
garment graph, and the fit attribute alpha. :meth:`LearnedGarment.evaluate` then runs
frames in batches: pose the body, coarse features -> coarse model -> ``M_coarse``, detail
features on ``M_coarse`` -> detail model -> ``M_detail``, and the post-process. A garment's
own bundle (:attr:`ModelBundle.garment`) serves only the triangles it was trained on: its
model maps the pose and the shape to a displacement of the unposed garment, which the
garment's skinning then poses (:mod:`cloth_usd.nn.garment_model`), then the post-process.
Shape letters: T frames, N garment vertices, V body vertices, M triangles, J joints.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..core.body import BodyModel
from ..core.features import vertex_normals
from ..core.graph import MeshGraph
from ..core.pipeline import OWN_SMOOTHING, GarmentPair, prepare_pair, run_tiers
from ..core.postprocess import STRAIN_LIMIT, StrainLimiter, TriangleLift, check_strain_limit, garment_margin
from ..core.scene import Tier
from ..core.skinning import SkinBinding
from ..core.smpl import NUM_JOINTS
from ..errors import ArgumentError, BundleError
from .bundle import ModelBundle
from .io import OUTPUT, coarse_inputs, detail_inputs

__all__ = ["LearnedGarment", "LearnedFrames"]


@dataclass(frozen=True)
class LearnedFrames:
    """What :meth:`LearnedGarment.evaluate` returns."""

    points: np.ndarray
    """(T, N, 3) float64 garment points [m], internal world frame."""
    moved: np.ndarray
    """(T,) int64 vertices the post-process pushed out of the body, plus those the detail tier's lift
    moved, per frame."""


class LearnedGarment:
    """A garment bound to one body shape and one model bundle, ready to evaluate.

    Args:
        bundle: the verified model bundle of the garment's category.
        body: the body model.
        betas: (B',) the character's shape coefficients.
        rest_points: (N, 3) garment rest points [m], canonical body frame (zero pose,
            no translation).
        faces: (M, 3) int garment triangles.
        binding: a skinning binding of the same pair to reuse (made here if None, as the
            bundle's category binds).
        margin: the post-process clearance [m]; None: the garment's own
            (:func:`~cloth_usd.core.postprocess.garment_margin`: 2 mm, more for a coarse mesh).
        strain_limit: the detail tier's post-process first shortens the edges stretched past this
            times their rest length (:class:`~cloth_usd.core.postprocess.StrainLimiter`); None: it
            does not. The coarse tier, the fast one, is not limited: the limit and the pushes out
            of the body it leads to take 10-20 ms a frame on a 3500-vertex shirt.
        lift: the detail tier's post-process ends with a lift of the garment's triangles off the body
            vertices in front of them (:class:`~cloth_usd.core.postprocess.TriangleLift`); False: it
            does not.
        smoothing: with a garment's own bundle, the Taubin passes over the part of its model's
            displacement along the rest garment's normals (:data:`~cloth_usd.core.pipeline.OWN_SMOOTHING`;
            0: none). A category bundle's graph models are not smoothed.
    """

    def __init__(self, bundle: ModelBundle, body: BodyModel, betas: np.ndarray, rest_points: np.ndarray,
                 faces: np.ndarray, *, binding: SkinBinding | None = None,
                 margin: float | None = None, strain_limit: float | None = STRAIN_LIMIT, lift: bool = True,
                 smoothing: int = OWN_SMOOTHING) -> None:
        self.bundle = bundle
        self.body = body
        self.margin = float(margin) if margin is not None else garment_margin(rest_points, faces)
        if strain_limit is not None:  # checked now, though the limiter is built when the detail tier first runs
            check_strain_limit(strain_limit)
        self._limit = (np.asarray(rest_points, dtype=np.float64), np.asarray(faces), strain_limit)
        self._lift = lift
        if not (isinstance(smoothing, int) and smoothing >= 0):
            raise ArgumentError(f"smoothing must be a whole number of passes >= 0, got {smoothing!r}")
        self.smoothing = smoothing
        if bundle.garment is not None and not bundle.garment.serves(len(rest_points), faces):
            raise BundleError(f"{bundle.path}: bundle '{bundle.name}' was trained for one garment of "
                              f"{bundle.garment.vertices} vertices, and this garment ({len(rest_points)} vertices) is "
                              "not it (other triangles); bake it with its category's bundle or train one for it "
                              "with cloth-usd train-garment")
        fit = bundle.fit
        if fit.anchors.size and int(fit.anchors.max()) >= body.num_vertices:
            raise BundleError(f"{bundle.path}: the fit model's anchors index body vertices up to "
                              f"{int(fit.anchors.max())}, but the body model has {body.num_vertices}")
        self.pair: GarmentPair = prepare_pair(body, betas, rest_points, faces, fit, binding=binding,
                                               category=bundle.category)
        """The pair's association, graph and fit attribute (:mod:`cloth_usd.core.pipeline`)."""
        self.betas = self.pair.betas
        self.faces = self.pair.faces
        self.binding: SkinBinding = self.pair.binding
        self.v_shaped, self.joints = self.pair.v_shaped, self.pair.joints
        self.graph: MeshGraph = self.pair.graph
        self.alpha: np.ndarray = self.pair.alpha
        """(F,) the pair's fit attribute alpha (F = 3)."""
        self.own = bundle.garment is not None
        """True for a garment's own bundle (its model serves this garment's triangles alone)."""
        if self.alpha.shape != (3,):
            raise BundleError(f"{bundle.path}: the fit model has {self.alpha.shape[0]} factors, "
                              "the models take 3")

    @functools.cached_property
    def limiter(self) -> StrainLimiter | None:
        """The detail tier's strain limiter (None: none), factored when the detail tier first
        runs: a coarse bake never builds it."""
        limit = self._limit[2]
        return self.strain_limiter(limit=limit) if limit is not None else None

    @functools.cached_property
    def lift(self) -> TriangleLift | None:
        """The detail tier's lift of the triangles off the body (None: none), made when the detail
        tier first runs."""
        if not self._lift:
            return None
        patch = self.pair.patch
        under = patch.vertices[patch.contact]  # the candidates the lift is called with, in their order
        normals = vertex_normals(self.pair.v_shaped, self.body.faces)
        slot = np.full(len(patch.vertices), -1)
        slot[patch.contact] = np.arange(len(patch.contact))
        faces = slot[patch.faces]  # the patch's triangles over the candidates (those with every corner one)
        return TriangleLift(self._limit[1], self._limit[0], self.pair.v_shaped[under], normals[under],
                            body_faces=faces[(faces >= 0).all(axis=1)])

    def strain_limiter(self, **settings) -> StrainLimiter:
        """A :class:`~cloth_usd.core.postprocess.StrainLimiter` of this garment's rest (``settings``:
        its ``limit``, ``iterations`` and ``anchor``; the defaults where not given)."""
        rest, faces, _ = self._limit
        return StrainLimiter(rest, faces, **settings)

    @property
    def num_vertices(self) -> int:
        """N."""
        return self.graph.num_vertices

    def evaluate(self, tier: Tier | str, poses: np.ndarray, transl: np.ndarray, *,
                 batch_size: int = 16, skinned: np.ndarray | None = None, postprocess: bool = True) -> LearnedFrames:
        """Animate the garment.

        Args:
            tier: coarse or detail.
            poses: (T, 72) axis-angle [rad], canonical body frame.
            transl: (T, 3) SMPL root translation [m].
            batch_size: frames per model call.
            skinned: (T, N, 3) float64 the skinned garment of these frames [m], internal
                world frame (:func:`~cloth_usd.core.skinning.skin_garment` with
                :attr:`binding`), when the caller has it already: a bundle whose coarse
                base is the skinned garment then does not skin the frames again.
            postprocess: False returns the models' garment before the post-process (to
                measure how far into the body they put it); a bake always runs it.
        Returns:
            The garment points per frame and the post-process counts.
        """
        tier = Tier(tier)
        if tier is Tier.SKINNING:
            raise ArgumentError("LearnedGarment.evaluate: tier must be coarse or detail (skinning "
                                "needs no model)")
        if batch_size < 1:
            raise ArgumentError(f"batch_size must be >= 1, got {batch_size}")
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS)
        transl = np.asarray(transl, dtype=np.float64).reshape(-1, 3)
        if transl.shape[0] != poses.shape[0]:
            raise ArgumentError(f"poses has {poses.shape[0]} frames, transl {transl.shape[0]}")
        limiter, lift = (self.limiter, self.lift) if tier is Tier.DETAIL else (None, None)
        if self.own:
            from ..core.pipeline import run_garment_model
            from ..core.garment_inputs import garment_displacement_inputs

            sessions = [self.bundle.session(tier)]
            if tier is Tier.DETAIL and self.bundle.detail_adds_coarse:
                sessions.append(self.bundle.session(Tier.COARSE))

            def run_model(canonical_poses: np.ndarray) -> np.ndarray:
                inputs = garment_displacement_inputs(canonical_poses, self.betas)
                return sum(s.run(inputs)[OUTPUT] for s in sessions)

            points, moved = run_garment_model(self.body, self.pair, poses, transl, run_model, batch_size=batch_size,
                                              margin=self.margin, postprocess=postprocess, limiter=limiter,
                                              lift=lift, smoothing=self.smoothing)
            return LearnedFrames(points=points, moved=moved)
        coarse = self.bundle.session(Tier.COARSE)
        detail = self.bundle.session(Tier.DETAIL) if tier is Tier.DETAIL else None

        def run_coarse(feats: np.ndarray, graph: MeshGraph) -> np.ndarray:
            return coarse.run(coarse_inputs(feats, graph.table))[OUTPUT]

        def run_detail(feats: np.ndarray, attrs: np.ndarray, graph: MeshGraph) -> np.ndarray:
            return detail.run(detail_inputs(feats, attrs, graph))[OUTPUT]

        points, moved = run_tiers(self.body, self.pair, poses, transl, run_coarse,
                                  run_detail if detail is not None else None, batch_size=batch_size,
                                  margin=self.margin, form=self.bundle.form, skinned=skinned,
                                  postprocess=postprocess, limiter=limiter, lift=lift)
        return LearnedFrames(points=points, moved=moved)
