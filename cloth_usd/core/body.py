"""The SMPL body: model files in, posed vertices and joint transforms out (numpy only).

The maths mirrors smplx's ``lbs.py`` (``M_b = LBS(T + B_s(beta) + B_p(theta), J(beta),
theta, W)``) as stateless functions over arrays; ``cloth_usd.body_torch`` builds the
same model as ``smplx.SMPL`` and a test holds the two equal. Shape letters: T frames,
V body vertices, J joints (24), B shape coefficients.
"""

from __future__ import annotations

import logging
import zipfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy import sparse

from ..errors import BodyModelError
from .files import file_sha256, models_dir
from .rotations import axis_angle_to_matrix
from .smpl import NUM_JOINTS, PARENTS

__all__ = [
    "BodyModel",
    "load_body_model",
    "default_body_model_path",
    "shape_body",
    "blend_skin",
    "pose_feature",
    "joint_transforms",
    "posed_vertices",
    "lbs",
    "SMPL_KEYS",
    "body_model_from_arrays",
]

log = logging.getLogger(__name__)

#: Keys of the official SMPL layout that cloth_usd needs.
SMPL_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")

def default_body_model_path() -> Path:
    """The embedded body model shipped in ``models/body``."""
    return models_dir() / "body" / "cloth_usd_neutral.npz"


@dataclass(frozen=True)
class BodyModel:
    """An SMPL-format body model as plain arrays."""

    v_template: np.ndarray
    """(V, 3) float64 mean rest vertices [m], Y-up, facing +Z, T-pose."""
    shapedirs: np.ndarray
    """(V, 3, B) float64 shape blend shapes [m per unit beta]."""
    posedirs: np.ndarray | None
    """(V, 3, 207) float64 pose correctives [m], None when all zero."""
    J_regressor: np.ndarray
    """(J, V) float64 joint regressor, rows sum to 1."""
    weights: np.ndarray
    """(V, J) float64 skinning weights, rows sum to 1."""
    faces: np.ndarray
    """(F, 3) int64 triangles."""
    parents: np.ndarray = field(default_factory=lambda: PARENTS.copy())
    """(J,) int64 kinematic tree, -1 for the root."""
    vertex_ids: Mapping[str, int] | None = None
    """Landmark vertices for smplx's extra joints; None means SMPL's own (6890 vertices)."""
    source: str = ""
    """The file it was read from."""
    sha256: str = ""
    """sha256 of that file."""

    @cached_property
    def sparse_weights(self) -> sparse.csr_matrix:
        """:attr:`weights` as a sparse matrix (a vertex has few joints), made once: what
        :func:`blend_skin` multiplies by."""
        return sparse.csr_matrix(self.weights)

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def num_betas(self) -> int:
        return int(self.shapedirs.shape[2])


def _read_raw(path: Path) -> dict[str, Any]:
    if path.suffix == ".npz":
        if path.is_file() and not zipfile.is_zipfile(path):  # np.load would try to unpickle it
            raise BodyModelError(f"{path}: not a readable .npz file (not a zip archive of arrays)")
        try:
            with np.load(path, allow_pickle=False) as data:
                return {k: data[k] for k in data.files}
        except OSError as exc:
            raise BodyModelError(f"{path}: cannot read body model file ({exc})") from exc
        except ValueError as exc:
            raise BodyModelError(
                f"{path}: the .npz holds Python objects, which cloth_usd never unpickles; "
                f"re-save it with plain arrays ({exc})") from exc
        except Exception as exc:  # zipfile.BadZipFile and friends
            raise BodyModelError(f"{path}: not a readable .npz file ({exc})") from exc
    if path.suffix == ".pkl":
        from .safe_pickle import load_smpl_pickle

        return load_smpl_pickle(path)
    raise BodyModelError(f"{path}: unknown body model format '{path.suffix}' (valid: .npz, .pkl)")


def _resolve(path: str | Path | None, gender: str) -> Path:
    if path is None:
        return default_body_model_path()
    path = Path(path)
    if path.is_dir():
        for name in (f"SMPL_{gender.upper()}.npz", f"SMPL_{gender.upper()}.pkl",
                     f"basicmodel_{gender[0]}_lbs_10_207_0_v1.1.0.pkl"):
            if (path / name).exists():
                return path / name
        raise BodyModelError(
            f"{path}: no SMPL_{gender.upper()}.npz or .pkl in this folder (gender '{gender}')")
    return path


def _array(raw: Mapping[str, Any], key: str, path: Path, ndim: int) -> np.ndarray:
    if key not in raw:
        raise BodyModelError(f"{path}: missing key '{key}' (an SMPL file has {', '.join(SMPL_KEYS)})")
    try:
        arr = np.asarray(raw[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise BodyModelError(f"{path}: key '{key}' is not numeric ({exc})") from exc
    if arr.ndim != ndim:
        raise BodyModelError(f"{path}: key '{key}' has shape {arr.shape}, expected {ndim} dimensions")
    if not np.all(np.isfinite(arr)):
        raise BodyModelError(f"{path}: key '{key}' holds NaN or Inf values")
    return arr


def _vertex_ids(raw: Mapping[str, Any]) -> dict[str, int] | None:
    if "vertex_ids" not in raw or "vertex_ids_names" not in raw:
        return None
    return {str(n): int(i) for n, i in zip(raw["vertex_ids_names"], raw["vertex_ids"])}


def body_model_from_arrays(raw: Mapping[str, Any], *, source: str = "<arrays>",
                           sha256: str = "") -> BodyModel:
    """Validate SMPL-layout arrays and build a :class:`BodyModel`.

    Raises :class:`BodyModelError` naming ``source`` and the offending key.
    """
    path = Path(source)
    v_template = _array(raw, "v_template", path, 2)
    num_v = v_template.shape[0]
    if v_template.shape[1] != 3:
        raise BodyModelError(f"{path}: key 'v_template' has shape {v_template.shape}, expected (V, 3)")
    shapedirs = _array(raw, "shapedirs", path, 3)
    if shapedirs.shape[:2] != (num_v, 3) or shapedirs.shape[2] < 1:
        raise BodyModelError(f"{path}: key 'shapedirs' has shape {shapedirs.shape}, expected ({num_v}, 3, B)")
    posedirs = _array(raw, "posedirs", path, 3)
    if posedirs.shape != (num_v, 3, 9 * (NUM_JOINTS - 1)):
        raise BodyModelError(f"{path}: key 'posedirs' has shape {posedirs.shape}, expected ({num_v}, 3, 207)")
    regressor = _array(raw, "J_regressor", path, 2)
    if regressor.shape != (NUM_JOINTS, num_v):
        raise BodyModelError(f"{path}: key 'J_regressor' has shape {regressor.shape}, expected (24, {num_v})")
    weights = _array(raw, "weights", path, 2)
    if weights.shape != (num_v, NUM_JOINTS):
        raise BodyModelError(f"{path}: key 'weights' has shape {weights.shape}, expected ({num_v}, 24)")
    if np.any(np.abs(weights.sum(axis=1) - 1.0) > 1e-3) or np.any(weights < -1e-6):
        raise BodyModelError(f"{path}: key 'weights' rows must be non-negative and sum to 1")
    faces = _array(raw, "f", path, 2).astype(np.int64)
    if faces.shape[1] != 3 or faces.size == 0 or faces.min() < 0 or faces.max() >= num_v:
        raise BodyModelError(f"{path}: key 'f' must be (F, 3) triangles indexing {num_v} vertices")
    kintree = np.asarray(raw["kintree_table"]) if "kintree_table" in raw else None
    if kintree is None:
        raise BodyModelError(f"{path}: missing key 'kintree_table'")
    try:
        parents = np.array(kintree[0], dtype=np.int64, ndmin=1)
    except (TypeError, ValueError, IndexError, OverflowError) as exc:
        raise BodyModelError(f"{path}: key 'kintree_table' is not a (2, 24) integer table ({exc})") from exc
    if parents.shape != (NUM_JOINTS,):
        raise BodyModelError(f"{path}: key 'kintree_table' has shape {kintree.shape}, expected (2, 24)")
    parents[0] = -1  # official files store 4294967295 (uint32 -1)
    if parents.shape != (NUM_JOINTS,) or not np.array_equal(parents, PARENTS):
        raise BodyModelError(f"{path}: key 'kintree_table' is not SMPL's 24-joint tree "
                             f"(parents {parents.tolist()}, expected {PARENTS.tolist()})")
    return BodyModel(
        v_template=v_template, shapedirs=shapedirs,
        posedirs=posedirs if np.any(posedirs) else None,
        J_regressor=regressor, weights=weights, faces=faces, parents=parents,
        vertex_ids=_vertex_ids(raw), source=str(source), sha256=sha256,
    )


def load_body_model(path: str | Path | None = None, *, gender: str = "neutral") -> BodyModel:
    """Load an SMPL-format body model.

    Args:
        path: a ``.npz`` (plain arrays, SMPL keys) or official ``.pkl`` file, or a folder
            holding ``SMPL_<GENDER>.npz|pkl``; None for the embedded model.
        gender: picks the file inside a folder: neutral, female or male.
    """
    if gender not in ("neutral", "female", "male"):
        raise BodyModelError(f"unknown gender '{gender}' (valid: neutral, female, male)")
    resolved = _resolve(path, gender)
    if not resolved.exists():
        hint = " (the embedded model: reinstall cloth-usd)" if path is None else ""
        raise BodyModelError(f"{resolved}: body model file not found{hint}")
    raw = _read_raw(resolved)
    return body_model_from_arrays(raw, source=str(resolved), sha256=file_sha256(resolved))


def shape_body(body: BodyModel, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unposed shaped body and its joints.

    Args:
        betas: (B',) float shape coefficients; B' <= B, missing ones are zero.
    Returns:
        ``(v_shaped (V, 3) [m], joints (J, 3) [m])``.
    """
    betas = np.asarray(betas, dtype=np.float64)
    nb = min(betas.shape[0], body.num_betas)
    v_shaped = body.v_template + body.shapedirs[:, :, :nb] @ betas[:nb]
    return v_shaped, body.J_regressor @ v_shaped


def pose_feature(rotmats: np.ndarray) -> np.ndarray:
    """SMPL's pose-corrective input: ``(R_j - I)`` of joints 1..23, flattened.

    Args:
        rotmats: (T, J, 3, 3) local joint rotations.
    Returns:
        (T, 207) float64.
    """
    return (rotmats[:, 1:] - np.eye(3)).reshape(rotmats.shape[0], -1)


def joint_transforms(rotmats: np.ndarray, joints: np.ndarray,
                     parents: np.ndarray = PARENTS) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics, as smplx's ``batch_rigid_transform``.

    Args:
        rotmats: (T, J, 3, 3) local joint rotations.
        joints: (J, 3) rest joint positions [m].
    Returns:
        ``(posed_joints (T, J, 3) [m], skinning (T, J, 3, 4))``: the rigid transform that
        carries a rest point bound to joint j to its posed place (before ``transl``).
    """
    num_t, num_j = rotmats.shape[:2]
    rel = joints.copy()
    rel[1:] -= joints[parents[1:]]
    world_r = np.empty((num_t, num_j, 3, 3))
    world_t = np.empty((num_t, num_j, 3))
    world_r[:, 0] = rotmats[:, 0]
    world_t[:, 0] = rel[0]
    for j in range(1, num_j):
        p = parents[j]
        world_r[:, j] = world_r[:, p] @ rotmats[:, j]
        world_t[:, j] = world_t[:, p] + world_r[:, p] @ rel[j]
    skin = np.empty((num_t, num_j, 3, 4))
    skin[..., :3] = world_r
    skin[..., 3] = world_t - np.einsum("tjab,jb->tja", world_r, joints)
    return world_t, skin


def blend_skin(weights: np.ndarray, skin: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Linear blend skinning of points by per-joint (3, 4) transforms.

    The transforms are blended per point as one sparse matrix product (V, J) @ (J, T * 12)
    (a vertex has few joints), columns first, then applied column by column: about 15x
    faster than the einsum form on the body's 13k vertices. Sparse, not BLAS: OpenBLAS's
    threads keep spinning after a call and took half the CPU from onnxruntime's next run
    (in a coarse bake, onnxruntime took 20.8 ms/frame after a dense product, 10.4 after this one).

    Args:
        weights: (V, J) skinning weights, dense or (better, made once) scipy sparse;
        skin: (T, J, 3, 4) joint transforms;
        points: (T, V, 3) or (V, 3) rest points [m].
    Returns:
        (T, V, 3) skinned points [m].
    """
    num_t, num_j = skin.shape[:2]
    columns = np.swapaxes(skin, 2, 3).transpose(1, 0, 2, 3).reshape(num_j, num_t * 12)  # (J, T * 12)
    w = weights if sparse.issparse(weights) else sparse.csr_matrix(weights)
    blended = np.asarray(w @ columns).reshape(-1, num_t, 4, 3).transpose(1, 0, 2, 3)  # (T, V, 4, 3)
    return (blended[:, :, 3] + points[..., 0:1] * blended[:, :, 0] + points[..., 1:2] * blended[:, :, 1]
            + points[..., 2:3] * blended[:, :, 2])


def lbs(body: BodyModel, v_shaped: np.ndarray, joints: np.ndarray, poses: np.ndarray,
        transl: np.ndarray | None = None, *, vertices: np.ndarray | None = None
        ) -> tuple[np.ndarray, np.ndarray]:
    """Pose an already shaped body (the shape is computed once per character).

    Args:
        v_shaped: (V, 3) unposed shaped body [m]; joints: (J, 3) its joints [m].
        poses: (T, 72) axis-angle [rad].
        transl: (T, 3) root translation [m], or None for zero.
        vertices: (V',) int body vertex indices to pose (all when None): a garment needs
            only the patch of body it is associated with.
    Returns:
        ``(vertices (T, V or V', 3) [m], posed joints (T, J, 3) [m])``, both with ``transl``.
    """
    weights, posedirs = body.sparse_weights, body.posedirs
    if vertices is not None:
        idx = np.asarray(vertices, dtype=np.int64)
        v_shaped, weights = v_shaped[idx], weights[idx]
        posedirs = posedirs[idx] if posedirs is not None else None
    rotmats = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    verts = np.broadcast_to(v_shaped, (rotmats.shape[0],) + v_shaped.shape)
    if posedirs is not None:
        verts = verts + np.einsum("vck,tk->tvc", posedirs, pose_feature(rotmats))
    posed_joints, skin = joint_transforms(rotmats, joints, body.parents)
    out = blend_skin(weights, skin, verts)
    if transl is not None:
        shift = np.asarray(transl, dtype=np.float64)[:, None, :]
        out, posed_joints = out + shift, posed_joints + shift
    return out, posed_joints


def posed_vertices(body: BodyModel, betas: np.ndarray, poses: np.ndarray,
                   transl: np.ndarray | None = None) -> np.ndarray:
    """The full SMPL forward pass, batched over frames.

    Args:
        betas: (B',) shape coefficients.
        poses: (T, 72) axis-angle [rad].
        transl: (T, 3) root translation [m], or None for zero.
    Returns:
        (T, V, 3) float64 posed vertices [m].
    """
    v_shaped, joints = shape_body(body, betas)
    return lbs(body, v_shaped, joints, poses, transl)[0]
