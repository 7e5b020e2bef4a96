"""A first parametric T-shirt, cut from the rest body and offset from it.

The shirt is the body's torso and upper-arm surface in the T-pose, cut at the hem,
the sleeve ends and the neckline, lifted off the body by an ease that grows towards
the hem, smoothed of anatomical detail, and refined to the requested resolution. It
is a worn garment at rest, not yet a draped one: the data factory relaxes it by
simulation. Shape letters: V body vertices, N garment vertices, M triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.association import associate
from ..core.body import BodyModel, shape_body
from ..core.mesh import boundary_vertices, open_edges
from ..errors import ClothUsdError

__all__ = ["TShirtParams", "make_tshirt", "tshirt_variants"]


def _trimesh():
    """trimesh, imported when a T-shirt is made (the ``datagen`` extra): importing this module,
    as the CLI does for every command, must not need it, since a bake never does."""
    try:
        import trimesh
    except ImportError as exc:
        raise ClothUsdError(f"making a T-shirt needs trimesh ({exc}); install it with pip install "
                            "'cloth-usd[datagen]'") from exc
    return trimesh


_PELVIS, _NECK, _HEAD, _L_SHOULDER, _R_SHOULDER = 0, 12, 15, 16, 17


@dataclass(frozen=True)
class TShirtParams:
    """Cut and fit of a T-shirt; lengths in metres."""

    hem: float = -0.06
    """Hem height relative to the pelvis joint (negative is lower). A hem cut from the
    body surface cannot pass the crotch (it would open leg holes), so a lower hem is
    raised, a centimetre at a time, until the cut has a single hem loop."""
    sleeve: float = 0.16
    """Sleeve length along the arm, from the shoulder joint."""
    ease: float = 0.012
    """Clearance between body and shirt at the chest."""
    hem_flare: float = 0.02
    """Extra clearance at the hem, blended in from the waist."""
    neck_drop: float = 0.07
    """Depth of the front neckline below the neck joint."""
    neck_width: float = 0.075
    """Half width of the neckline opening."""
    target_vertices: int = 3500
    """Approximate vertex count after refinement."""
    smooth_iterations: int = 12
    contact_clearance: float = 0.005
    """Gap [m] kept where the shirt rests on the body (shoulders, the top of the chest):
    a little above the simulator's contact margin, so the shirt starts resting rather than
    falling onto the body."""


def _count_rims(faces: np.ndarray) -> int:
    """Number of boundary loops of a triangle mesh."""
    trimesh = _trimesh()
    rim = open_edges(faces)
    return len(trimesh.graph.connected_components(rim)) if len(rim) else 0


def hem_height(body: BodyModel, v: np.ndarray, joints: np.ndarray, p: TShirtParams) -> float:
    """The hem's height [m]: the asked one, raised until the cut has one hem loop (4 rims:
    hem, neckline, two sleeves) rather than two leg openings."""
    hem_y = joints[_PELVIS, 1] + p.hem
    for _ in range(30):
        _, faces = _submesh(v, body.faces, _region(v, joints, body.weights, p, hem_y))
        if _count_rims(faces) <= 4:
            return hem_y
        hem_y += 0.01
    return hem_y


def _region(v: np.ndarray, joints: np.ndarray, weights: np.ndarray, p: TShirtParams,
            hem_y: float) -> np.ndarray:
    """(V,) bool: body vertices the shirt covers."""
    sleeve_x = np.abs(joints[[_L_SHOULDER, _R_SHOULDER], 0]).mean() + p.sleeve
    neck = joints[_NECK]
    keep = (v[:, 1] > hem_y) & (np.abs(v[:, 0]) < sleeve_x)
    keep &= weights[:, [_NECK, _HEAD]].sum(axis=1) < 0.35
    # Scoop the front neckline: an ellipse in front of the neck joint.
    dx = (v[:, 0] - neck[0]) / p.neck_width
    dy = (v[:, 1] - (neck[1] + 0.03)) / (p.neck_drop + 0.03)
    keep &= ~((dx ** 2 + dy ** 2 < 1.0) & (v[:, 2] > neck[2] - 0.02))
    keep &= ~((np.abs(dx) < 0.85) & (v[:, 1] > neck[1] - 0.015))  # the back of the collar
    return keep


def _submesh(v: np.ndarray, f: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    trimesh = _trimesh()
    faces = f[keep[f].all(axis=1)]
    mesh = trimesh.Trimesh(v, faces, process=False)
    parts = mesh.split(only_watertight=False)
    part = max(parts, key=lambda m: len(m.faces))
    return np.asarray(part.vertices), np.asarray(part.faces)


def _snap_cuts(v: np.ndarray, faces: np.ndarray, joints: np.ndarray, p: TShirtParams,
               hem_y: float) -> np.ndarray:
    """Move boundary vertices onto their cut: the hem plane, the sleeve-end planes."""
    v = v.copy()
    rim = boundary_vertices(faces)
    sleeve_x = np.abs(joints[[_L_SHOULDER, _R_SHOULDER], 0]).mean() + p.sleeve
    at_sleeve = rim[np.abs(v[rim, 0]) > sleeve_x - 0.05]
    at_hem = rim[(v[rim, 1] < hem_y + 0.05) & (np.abs(v[rim, 0]) < sleeve_x - 0.05)]
    v[at_sleeve, 0] = np.sign(v[at_sleeve, 0]) * sleeve_x
    v[at_hem, 1] = hem_y
    return v


def _push_out(v: np.ndarray, body_v: np.ndarray, body_f: np.ndarray, rest_on: float,
              ease: np.ndarray) -> np.ndarray:
    """Move garment vertices that are closer to the body than their clearance (see
    :func:`_clearance`), or inside it, out along the body normal."""
    trimesh = _trimesh()
    body = trimesh.Trimesh(body_v, body_f, process=False)
    normals = np.asarray(body.vertex_normals)
    assoc = associate(v, body_v, body_f)
    corners = body_f[assoc.triangle]
    surface = np.einsum("nk,nkc->nc", assoc.barycentric, body_v[corners])
    normal = np.einsum("nk,nkc->nc", assoc.barycentric, normals[corners])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    height = np.einsum("nc,nc->n", v - surface, normal)
    lift = np.maximum(_clearance(normal, ease, rest_on) - height, 0.0)
    return v + normal * lift[:, None]


def _clearance(normals: np.ndarray, ease: np.ndarray, rest_on: float) -> np.ndarray:
    """(N,) distance [m] to keep from the body: the ease on the sides and below, none on top.

    A worn shirt hangs from the shoulders: where the body surface faces up it rests on
    it (``rest_on``), and the ease opens towards surfaces that face sideways or down.
    """
    up = np.clip(normals[:, 1], 0.0, 1.0)
    return rest_on + ease * (1.0 - up)


def make_tshirt(body: BodyModel, betas: np.ndarray, params: TShirtParams = TShirtParams()
                ) -> tuple[np.ndarray, np.ndarray]:
    """Make a T-shirt worn by the body of shape ``betas`` in the rest (T-)pose.

    Returns:
        ``(vertices (N, 3) float64 [m] canonical body frame, faces (M, 3) int64)``.
    """
    trimesh = _trimesh()
    v_body, joints = shape_body(body, betas)
    hem_y = hem_height(body, v_body, joints, params)
    keep = _region(v_body, joints, body.weights, params, hem_y)
    v, f = _submesh(v_body, body.faces, keep)
    mesh = trimesh.Trimesh(v, f, process=False)
    waist_y = joints[_PELVIS, 1] + 0.15
    flare = params.hem_flare * np.clip((waist_y - v[:, 1]) / (waist_y - hem_y), 0.0, 1.0)
    normals = np.asarray(mesh.vertex_normals)
    v = v + normals * _clearance(normals, params.ease + flare, params.contact_clearance)[:, None]
    mesh = trimesh.Trimesh(_snap_cuts(v, f, joints, params, hem_y), f, process=False)
    trimesh.smoothing.filter_taubin(mesh, iterations=params.smooth_iterations)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    while v.shape[0] * 4 <= params.target_vertices * 1.3:
        v, f = trimesh.remesh.subdivide(v, f)
    if v.shape[0] < params.target_vertices * 0.85:  # one partial step: split the longest edges
        edges = trimesh.Trimesh(v, f, process=False).edges_unique_length
        v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge=float(np.quantile(
            edges, max(0.0, 1.0 - (params.target_vertices - v.shape[0]) / max(len(edges), 1)))))
    mesh = trimesh.Trimesh(v, f, process=True)  # merge split-edge duplicates
    trimesh.smoothing.filter_taubin(mesh, iterations=4)
    v, f = _snap_cuts(np.asarray(mesh.vertices), np.asarray(mesh.faces), joints, params, hem_y), np.asarray(mesh.faces)
    flare = params.hem_flare * np.clip((waist_y - v[:, 1]) / (waist_y - hem_y), 0.0, 1.0)
    v = _push_out(v, v_body, body.faces, params.contact_clearance, params.ease + flare)
    return v, f.astype(np.int64)


def tshirt_variants(count: int = 9, *, seed: int = 0) -> list[TShirtParams]:
    """``count`` T-shirts spanning hem (short to long), sleeve, ease, neckline and resolution.

    The first variants sweep the extremes deterministically so any ``count >= 3`` holds a
    short, a long and a loose shirt; the rest are drawn from ``seed``. Target vertex counts
    differ (3000-4000), so every variant has its own topology.
    """
    rng = np.random.default_rng(seed)
    fixed = [
        TShirtParams(hem=0.02, sleeve=0.10, ease=0.010, target_vertices=3000),  # short, tight
        TShirtParams(hem=-0.14, sleeve=0.22, ease=0.018, target_vertices=3900),  # long
        TShirtParams(hem=-0.06, sleeve=0.16, ease=0.030, hem_flare=0.04, target_vertices=3400),  # loose
    ]
    out = fixed[:count]
    while len(out) < count:
        out.append(TShirtParams(
            hem=float(rng.uniform(-0.14, 0.02)), sleeve=float(rng.uniform(0.10, 0.24)),
            ease=float(rng.uniform(0.008, 0.03)), hem_flare=float(rng.uniform(0.0, 0.04)),
            neck_drop=float(rng.uniform(0.04, 0.11)), neck_width=float(rng.uniform(0.06, 0.09)),
            target_vertices=int(rng.integers(3000, 4001))))
    return out
