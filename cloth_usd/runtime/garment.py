"""One garment animated by a model bundle (the coarse and detail tiers of METHOD.md).

Everything that depends only on the garment-body pair is computed once, when a
:class:`LearnedGarment` is made: the association (through the skinning binding), the
garment graph, and the fit attribute alpha. :meth:`LearnedGarment.evaluate` then runs
frames in batches: pose the body, coarse features -> coarse model -> ``M_coarse``, detail
features on ``M_coarse`` -> detail model -> ``M_detail``, and the post-process.
Shape letters: T frames, N garment vertices, V body vertices, M triangles, J joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.body import BodyModel, lbs, shape_body
from ..core.features import attributes, coarse_features, detail_features, vertex_normals
from ..core.fit import pair_distances
from ..core.graph import MeshGraph, build_graph
from ..core.postprocess import DEFAULT_MARGIN, push_out
from ..core.scene import Tier
from ..core.skinning import SkinBinding, bind_garment
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
    """(T,) int64 vertices the post-process pushed out of the body, per frame."""


class LearnedGarment:
    """A garment bound to one body shape and one model bundle, ready to evaluate.

    Args:
        bundle: the verified model bundle of the garment's category.
        body: the body model.
        betas: (B',) the character's shape coefficients.
        rest_points: (N, 3) garment rest points [m], canonical body frame (zero pose,
            no translation).
        faces: (M, 3) int garment triangles.
        binding: a skinning binding of the same pair to reuse (made here if None).
        margin: the post-process clearance [m].
    """

    def __init__(self, bundle: ModelBundle, body: BodyModel, betas: np.ndarray, rest_points: np.ndarray,
                 faces: np.ndarray, *, binding: SkinBinding | None = None,
                 margin: float = DEFAULT_MARGIN) -> None:
        self.bundle = bundle
        self.body = body
        self.betas = np.asarray(betas, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.margin = float(margin)
        rest_points = np.asarray(rest_points, dtype=np.float64)
        self.binding = binding if binding is not None else bind_garment(body, self.betas, rest_points)
        self.v_shaped, self.joints = shape_body(body, self.betas)
        self.graph: MeshGraph = build_graph(self.faces, rest_points)
        fit = bundle.fit
        if fit.anchors.size and int(fit.anchors.max()) >= body.num_vertices:
            raise BundleError(f"{bundle.path}: the fit model's anchors index body vertices up to "
                              f"{int(fit.anchors.max())}, but the body model has {body.num_vertices}")
        d = pair_distances(rest_points, self.binding.association, self.v_shaped, fit.anchors)
        self.alpha: np.ndarray = np.asarray(fit.transform(d), dtype=np.float64)
        """(F,) the pair's fit attribute alpha (F = 3)."""
        if self.alpha.shape != (3,):
            raise BundleError(f"{bundle.path}: the fit model has {self.alpha.shape[0]} factors, "
                              "the models take 3")

    @property
    def num_vertices(self) -> int:
        """N."""
        return self.graph.num_vertices

    def evaluate(self, tier: Tier | str, poses: np.ndarray, transl: np.ndarray, *,
                 batch_size: int = 16) -> LearnedFrames:
        """Animate the garment.

        Args:
            tier: coarse or detail.
            poses: (T, 72) axis-angle [rad], canonical body frame.
            transl: (T, 3) SMPL root translation [m].
            batch_size: frames per model call.
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
        coarse = self.bundle.session(Tier.COARSE)
        detail = self.bundle.session(Tier.DETAIL) if tier is Tier.DETAIL else None
        idx = self.binding.association.vertex
        num_t, n = poses.shape[0], self.graph.num_vertices
        points = np.empty((num_t, n, 3))
        moved = np.zeros(num_t, dtype=np.int64)
        for lo in range(0, num_t, batch_size):
            hi = min(lo + batch_size, num_t)
            verts, joints = lbs(self.body, self.v_shaped, self.joints, poses[lo:hi], transl[lo:hi])
            normals = vertex_normals(verts, self.body.faces)
            body_pts, body_nrm = verts[:, idx], normals[:, idx]
            feats = coarse_features(verts, normals, idx, transl[lo:hi], self.alpha[0])
            m = body_pts + coarse.run(coarse_inputs(feats, self.graph.table))[OUTPUT]
            if detail is not None:
                feats = detail_features(m, self.faces, joints, transl[lo:hi])
                attrs = attributes(self.alpha, self.betas, poses[lo:hi])
                m = m + detail.run(detail_inputs(feats, attrs, self.graph))[OUTPUT]
            points[lo:hi], moved[lo:hi] = push_out(m, body_pts, body_nrm, margin=self.margin)
        return LearnedFrames(points=points, moved=moved)
