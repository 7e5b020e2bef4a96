"""The garment's physical energy as a differentiable torch loss (HOOD / SNUG style).

The terms are the ones Newton's VBD cloth solver (newton 1.8.0, the simulator behind
:mod:`cloth_usd.datagen.simulate`) minimises every step, with the same material numbers,
so a network trained on this loss and the simulator answer the same question:

- membrane: the stable Neo-Hookean shell energy of VBD's
  ``evaluate_neo_hookean_membrane_force_hessian`` (default), or the StVK energy HOOD and
  SNUG use (:attr:`MembraneModel.STVK`);
- bending: the dihedral-angle energy of VBD's
  ``evaluate_dihedral_angle_based_bending_force_hessian``, same edge ordering and sign;
- gravity: the potential ``sum_i m_i g y_i`` (Y up);
- body contact: a one-sided penalty on each garment vertex's signed distance to the
  body, either HOOD / SNUG's cubic (default) or the quadratic-plus-log-barrier profile of
  VBD's ``evaluate_self_contact_force_norm`` (:attr:`ContactModel.VBD`);
- inertia (dynamic variant only): implicit Euler's ``sum_i m_i / (2 h^2) |x_t - y_t|^2``
  with ``y_t = 2 x_{t-1} - x_{t-2}``;
- friction (dynamic, separate: :func:`friction_energy`): lagged smooth Coulomb friction,
  the potential of VBD's ``compute_friction``; not part of :func:`garment_energy`.

Without inertia the sum is the quasi-static energy: a garment at rest in a pose without
friction sits at its minimum (with friction, a draped garment can rest away from it,
holding stretch that friction keeps from relaxing). Every energy is in joules, per
frame: shape (B,).

Contact differs from the simulator's in kind: VBD meets the body (a kinematic cloth) by
vertex-triangle and edge-edge pairs in the unsigned distance; here each garment vertex
takes the signed distance to one body point the caller supplies.

Shape letters: B frames (batch), N garment vertices, M triangles, E interior (bending)
edges. Positions are metres, Y up (gravity along -Y), SMPL's internal frame.

Functions are stateless (numpy only for the rest-state precomputation);
:class:`GarmentEnergy` is a thin :class:`torch.nn.Module` that owns the rest state as
buffers.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn

from ..errors import ArgumentError

if TYPE_CHECKING:  # annotation only: from_sim_config reads attributes, never imports the simulator
    from ..datagen.simulate import SimConfig

__all__ = [
    "Material",
    "GarmentRest",
    "MembraneModel",
    "ContactModel",
    "EnergyTerms",
    "GarmentEnergy",
    "garment_rest",
    "deformation_gradient",
    "membrane_energy",
    "dihedral_angles",
    "bending_energy",
    "gravity_energy",
    "contact_energy",
    "inertia_energy",
    "contact_normal_force",
    "friction_energy",
    "garment_energy",
]

log = logging.getLogger(__name__)

#: Newton's bending kernel drops an edge whose (unnormalised) triangle normals or edge
#: are shorter than this [m^2 for normals, m for the edge]; we drop the same edges.
_BEND_EPS = 1.0e-6
#: Newton clamps the squared area ratio J^2 of a triangle from below by this.
_J_SQ_MIN = 1.0e-20


class MembraneModel(str, enum.Enum):
    """The in-plane (stretch and shear) material law."""

    NEO_HOOKEAN = "neo_hookean"
    """Stable Neo-Hookean for shells (Smith et al. 2018), what Newton's VBD evaluates."""
    STVK = "stvk"
    """Saint Venant-Kirchhoff on the Green strain, HOOD's and SNUG's form."""


class ContactModel(str, enum.Enum):
    """The one-sided body-contact penalty profile in the signed distance d."""

    CUBIC = "cubic"
    """``w max(r - d, 0)^3`` (HOOD / SNUG), weight w in J/m^3."""
    VBD = "vbd"
    """Newton VBD's self-contact profile: ``k/2 (r - d)^2`` for ``r/2 < d < r``, a log
    barrier below ``r/2``, its quadratic Taylor extension below ``min(1e-5, r/4)``; k in N/m."""


@dataclass(frozen=True)
class Material:
    """One cloth material in the simulator's units (SI, per unit rest area)."""

    density: float = 0.15
    """Mass per rest area [kg/m^2]."""
    stretch_mu: float = 5.0e3
    """Membrane Lame mu [N/m] (Newton's ``tri_ke``)."""
    stretch_lambda: float = 5.0e3
    """Membrane Lame lambda [N/m] (Newton's ``tri_ka``)."""
    bend_stiffness: float = 5.0e-5
    """Dihedral bending stiffness per metre of edge [J/(m rad^2)]
    (Newton's ``edge_ke``; an edge's stiffness is this times its rest length)."""
    contact_stiffness: float = 1.0e4
    """Contact stiffness of the VBD profile [N/m] (Newton's ``soft_contact_ke``)."""
    contact_margin: float = 4.0e-3
    """Distance [m] to the body below which a garment vertex is penalised."""
    contact_weight: float | None = None
    """Weight of the cubic profile [J/m^3]; None derives it as
    ``contact_stiffness / contact_margin``, which gives the cubic and the VBD profile the
    same energy ``k r^2 / 8`` at half the margin."""
    friction: float = 0.3
    """Coulomb friction coefficient (used by :func:`friction_energy` only)."""
    gravity: float = 9.81
    """Gravitational acceleration [m/s^2] along -Y."""

    def __post_init__(self) -> None:
        for name in ("density", "stretch_mu", "bend_stiffness", "contact_stiffness", "contact_margin",
                     "friction", "gravity"):
            if not getattr(self, name) >= 0.0:
                raise ArgumentError(f"Material.{name} must be >= 0, got {getattr(self, name)}")
        if not self.stretch_lambda + self.stretch_mu > 0.0:
            raise ArgumentError(f"Material.stretch_lambda + stretch_mu must be > 0, got "
                                f"{self.stretch_lambda} + {self.stretch_mu}")
        if self.contact_weight is not None and not self.contact_weight >= 0.0:
            raise ArgumentError(f"Material.contact_weight must be None or >= 0, got {self.contact_weight}")

    @property
    def cubic_contact_weight(self) -> float:
        """The cubic profile's weight [J/m^3] (:attr:`contact_weight` or its derived default)."""
        if self.contact_weight is not None:
            return float(self.contact_weight)
        return self.contact_stiffness / max(self.contact_margin, 1e-12)

    @classmethod
    def from_sim_config(cls, config: SimConfig, **overrides) -> Material:
        """The material the simulator uses, from a :class:`cloth_usd.datagen.simulate.SimConfig`.

        Field by field (how :func:`cloth_usd.datagen.simulate.simulate` passes them to Newton):

        - ``density`` [kg/m^2] -> :attr:`density`: ``add_cloth_mesh(density=...)``, each
          vertex's mass is density x a third of each adjacent rest triangle's area;
          enters the gravity and the inertia term.
        - ``stretch_stiffness`` [N/m] -> both :attr:`stretch_mu` and :attr:`stretch_lambda`:
          passed as ``tri_ke`` (mu) and ``tri_ka`` (lambda) of the Neo-Hookean membrane.
        - ``bend_stiffness`` -> :attr:`bend_stiffness`: ``edge_ke``; Newton scales it per
          edge by the edge's rest length, so an edge's stiffness is ``edge_ke x l_rest``.
        - ``contact_stiffness`` [N/m] -> :attr:`contact_stiffness`: ``soft_contact_ke``,
          the stiffness of VBD's garment-body contact (the body is a kinematic cloth).
        - ``contact_margin`` [m] -> :attr:`contact_margin`: VBD's
          ``particle_self_contact_margin``, the distance at which contact starts.
        - ``friction`` -> :attr:`friction`: ``soft_contact_mu``.
        - ``gravity`` [m/s^2] -> :attr:`gravity`: the builder's gravity along -Y.

        The damping fields (``stretch_damping``, ``bend_damping``, ``contact_damping``) are
        dissipative, not energies, and have no counterpart here.

        Args:
            config: the simulator's config (any object with those attributes).
            overrides: fields of this dataclass to set instead (e.g. ``contact_weight``).
        """
        fields = dict(density=float(config.density), stretch_mu=float(config.stretch_stiffness),
                      stretch_lambda=float(config.stretch_stiffness), bend_stiffness=float(config.bend_stiffness),
                      contact_stiffness=float(config.contact_stiffness), contact_margin=float(config.contact_margin),
                      friction=float(config.friction), gravity=float(config.gravity))
        fields.update(overrides)
        return cls(**fields)


# --------------------------------------------------------------------------- rest state


@dataclass(frozen=True)
class GarmentRest:
    """What the energy needs from the rest (as-cut) garment, precomputed once."""

    positions: torch.Tensor
    """(N, 3) float rest vertices [m]."""
    faces: torch.Tensor
    """(M, 3) int64 triangles."""
    dm_inv: torch.Tensor
    """(M, 2, 2) float inverse rest shape matrix of each triangle in its own 2D frame
    (Newton's ``tri_poses``) [1/m]; the identity for a degenerate rest triangle."""
    areas: torch.Tensor
    """(M,) float rest triangle areas [m^2]; 0 for a degenerate triangle (no energy)."""
    masses: torch.Tensor
    """(N,) float vertex masses [kg]: density x a third of each adjacent rest area."""
    edges: torch.Tensor
    """(E, 4) int64 interior edges as Newton orders them: ``(o0, o1, v0, v1)`` with the
    edge ``v0 -> v1`` and the triangles ``(o0, v0, v1)`` and ``(o1, v1, v0)``."""
    rest_angles: torch.Tensor
    """(E,) float rest dihedral angles [rad] (Newton's ``edge_rest_angle``)."""
    rest_lengths: torch.Tensor
    """(E,) float rest edge lengths [m] (Newton's ``edge_rest_length``)."""

    @property
    def total_mass(self) -> float:
        """Garment mass [kg]."""
        return float(self.masses.sum())

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None) -> GarmentRest:
        """A copy on another device and/or float dtype (index tensors stay int64)."""
        out = {}
        for f in dataclasses.fields(self):
            t = getattr(self, f.name)
            out[f.name] = t.to(device=device, dtype=dtype if t.is_floating_point() else None)
        return GarmentRest(**out)


def _interior_edges(faces: np.ndarray) -> np.ndarray:
    """(E, 4) int64 interior edges ``(o0, o1, v0, v1)`` in Newton's ``MeshAdjacency`` order.

    A triangle's local edges are ``(t0, t1 | t2)``, ``(t1, t2 | t0)``, ``(t2, t0 | t1)``;
    an edge takes its direction and ``o0`` from its first occurrence (in triangle order),
    ``o1`` from its second; edges are numbered by first occurrence. Boundary edges are
    dropped (Newton keeps them with ``o1 = -1`` and no energy); a third or later triangle
    on a non-manifold edge is ignored, as Newton does.
    """
    m = faces.shape[0]
    if m == 0:
        return np.zeros((0, 4), dtype=np.int64)
    v0 = faces[:, [0, 1, 2]].reshape(-1)
    v1 = faces[:, [1, 2, 0]].reshape(-1)
    opp = faces[:, [2, 0, 1]].reshape(-1)
    keys = np.stack([np.minimum(v0, v1), np.maximum(v0, v1)], 1)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")  # entries grouped by edge, ascending entry id
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    if np.any(counts > 2):
        log.warning("%d non-manifold edges: only their first two triangles bend", int(np.sum(counts > 2)))
    interior = counts >= 2
    first = order[starts[interior]]
    second = order[starts[interior] + 1]
    rows = np.stack([opp[first], opp[second], v0[first], v1[first]], 1)
    return rows[np.argsort(first, kind="stable")].astype(np.int64)


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of v normalised; zero rows stay zero (as Newton's rest-shape helpers do)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0.0, 1.0, n)


def _np_dihedral(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(E,) rest angles as Newton's builder computes them."""
    x0, x1, x2, x3 = (x[edges[:, k]] for k in range(4))
    n1 = _unit(np.cross(x2 - x0, x3 - x0))
    n2 = _unit(np.cross(x3 - x1, x2 - x1))
    e = _unit(x3 - x2)
    cos = np.clip(np.sum(n1 * n2, -1), -1.0, 1.0)
    sin = np.sum(np.cross(n1, n2) * e, -1)
    return np.arctan2(sin, cos)


def garment_rest(vertices, faces, material: Material = Material(), *, dtype: torch.dtype = torch.float32,
                 device: torch.device | str | None = None, rest_angles: str = "rest") -> GarmentRest:
    """Precompute the rest state of a garment of any topology.

    Computed in float64 numpy, then cast. Degenerate rest triangles (zero area) get zero
    area, the identity ``dm_inv`` and no mass, as Newton's ``add_triangles`` drops them
    (Newton then also drops their bending edges; here those edges stay, with rest angle 0).

    Args:
        vertices: (N, 3) float rest (as-cut) garment [m], array or tensor.
        faces: (M, 3) int triangles, consistently wound.
        material: supplies the density for the masses.
        dtype: float dtype of the returned tensors.
        device: their device.
        rest_angles: "rest" takes the rest garment's own dihedral angles (what Newton does
            with the garment it is given); "flat" sets them to 0 (a garment cut from flat
            panels).
    Returns:
        A :class:`GarmentRest`.
    Raises:
        ArgumentError: malformed arrays or an unknown ``rest_angles``.
    """
    x = np.asarray(vertices.detach().cpu() if torch.is_tensor(vertices) else vertices, dtype=np.float64)
    f = np.asarray(faces.detach().cpu() if torch.is_tensor(faces) else faces, dtype=np.int64)
    if x.ndim != 2 or x.shape[1] != 3 or not np.all(np.isfinite(x)):
        raise ArgumentError(f"vertices must be finite (N, 3), got shape {x.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= x.shape[0])):
        raise ArgumentError(f"faces must be (M, 3) indices below {x.shape[0]}, got shape {f.shape}")
    if rest_angles not in ("rest", "flat"):
        raise ArgumentError(f"rest_angles must be 'rest' or 'flat', got {rest_angles!r}")

    # Newton's _triangle_rest_geometry: the triangle's frame (e1 along x1 - x0, e2 in plane).
    qp, rp = x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]
    normal = _unit(np.cross(qp, rp))
    e1 = _unit(qp)
    e2 = _unit(np.cross(normal, e1))
    dm = np.stack([np.stack([np.sum(e1 * qp, -1), np.sum(e1 * rp, -1)], -1),
                   np.stack([np.sum(e2 * qp, -1), np.sum(e2 * rp, -1)], -1)], -2)  # (M, 2, 2)
    areas = np.linalg.det(dm) / 2.0 if f.size else np.zeros(0)
    bad = ~(areas > 0.0)
    areas = np.where(bad, 0.0, areas)
    dm[bad] = np.eye(2)
    dm_inv = np.linalg.inv(dm) if f.size else np.zeros((0, 2, 2))

    masses = np.zeros(x.shape[0])
    for k in range(3):
        np.add.at(masses, f[:, k], material.density * areas / 3.0)

    edges = _interior_edges(f)
    angles = _np_dihedral(x, edges) if rest_angles == "rest" else np.zeros(edges.shape[0])
    lengths = np.linalg.norm(x[edges[:, 3]] - x[edges[:, 2]], axis=1)

    def fl(a):
        return torch.as_tensor(a, dtype=dtype, device=device)

    def it(a):
        return torch.as_tensor(a, dtype=torch.int64, device=device)

    return GarmentRest(positions=fl(x), faces=it(f), dm_inv=fl(dm_inv), areas=fl(areas), masses=fl(masses),
                       edges=it(edges), rest_angles=fl(angles), rest_lengths=fl(lengths))


# --------------------------------------------------------------------------- energies


def _check_positions(x: torch.Tensor, rest: GarmentRest, name: str = "x") -> None:
    n = rest.positions.shape[0]
    if x.ndim != 3 or x.shape[1:] != (n, 3):
        raise ArgumentError(f"{name} must be (B, {n}, 3) garment positions, got shape {tuple(x.shape)}")


def deformation_gradient(x: torch.Tensor, rest: GarmentRest) -> torch.Tensor:
    """Per-triangle deformation gradient ``F = [x1 - x0, x2 - x0] Dm^-1``.

    Args:
        x: (B, N, 3) float garment positions [m].
        rest: the rest state.
    Returns:
        (B, M, 3, 2) float, dimensionless.
    """
    _check_positions(x, rest)
    tri = x[:, rest.faces]  # (B, M, 3, 3): corner, xyz
    ds = torch.stack([tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0]], dim=-1)  # (B, M, 3, 2)
    return ds @ rest.dm_inv.to(x.dtype)


def membrane_energy(x: torch.Tensor, rest: GarmentRest, material: Material, *,
                    model: MembraneModel | str = MembraneModel.NEO_HOOKEAN) -> torch.Tensor:
    """Stretch and shear energy of the garment, zero at the rest shape.

    Neo-Hookean (default), as Newton's ``evaluate_neo_hookean_membrane_force_hessian``:
    with ``I_c = tr(F^T F)`` and ``J = |f0 x f1|`` (area ratio; ``J^2`` clamped below at
    1e-20 as Newton does), ``psi = mu/2 (I_c - 2) + lam'/2 (J - alpha)^2`` where
    ``lam' = lam + mu`` and ``alpha = 1 + mu / lam'``. At rest psi is ``mu^2 / (2 lam')``;
    that constant is subtracted. Energy = sum over triangles of rest area x psi.

    StVK (HOOD's and SNUG's ``stretching_energy``): ``G = (F^T F - I) / 2``,
    ``S = mu G + lam/2 tr(G) I``, psi = ``tr(S^T G) = mu tr(G^2) + lam/2 tr(G)^2``;
    energy = rest area x psi (HOOD's extra thickness factor is already in mu and lam
    here, which are per unit area, N/m).

    Args:
        x: (B, N, 3) float garment positions [m].
        rest: the rest state.
        material: ``stretch_mu`` and ``stretch_lambda`` [N/m].
        model: a :class:`MembraneModel` or its value.
    Returns:
        (B,) energy [J].
    """
    model = _enum(MembraneModel, model, "model")
    f = deformation_gradient(x, rest)
    f0, f1 = f[..., 0], f[..., 1]  # (B, M, 3)
    mu, lam = material.stretch_mu, material.stretch_lambda
    area = rest.areas.to(x.dtype)
    if model is MembraneModel.NEO_HOOKEAN:
        ic = (f * f).sum(dim=(-1, -2))
        j = torch.linalg.cross(f0, f1, dim=-1).pow(2).sum(-1).clamp_min(_J_SQ_MIN).sqrt()
        lam_nh = lam + mu
        alpha = 1.0 + mu / lam_nh
        psi = 0.5 * mu * (ic - 2.0) + 0.5 * lam_nh * (j - alpha) ** 2 - 0.5 * mu * mu / lam_nh
    else:
        c = f.transpose(-1, -2) @ f  # (B, M, 2, 2)
        g = 0.5 * (c - torch.eye(2, dtype=x.dtype, device=x.device))
        tr = g[..., 0, 0] + g[..., 1, 1]
        psi = mu * (g * g).sum(dim=(-1, -2)) + 0.5 * lam * tr * tr
    return (area * psi).sum(-1)


def dihedral_angles(x: torch.Tensor, edges: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Signed dihedral angle of each interior edge, Newton's convention.

    With opposite vertices x0, x1 and the edge x2 -> x3: ``n1 = (x2 - x0) x (x3 - x0)``,
    ``n2 = (x3 - x1) x (x2 - x1)``, ``theta = atan2((n1^ x n2^) . e^, n1^ . n2^)``: 0 for a
    flat pair, positive when the pair folds so that ``n1`` turns toward ``n2`` about ``e``.
    An edge whose normals or length fall below 1e-6 (Newton's degenerate test) is
    reported invalid and given angle 0, with a zero (finite) gradient.

    Args:
        x: (B, N, 3) float positions [m].
        edges: (E, 4) int64 ``(o0, o1, v0, v1)`` rows (:attr:`GarmentRest.edges`).
    Returns:
        ``(theta (B, E) float [rad], valid (B, E) bool)``.
    """
    x0, x1, x2, x3 = (x[:, edges[:, k]] for k in range(4))
    n1 = torch.linalg.cross(x2 - x0, x3 - x0, dim=-1)
    n2 = torch.linalg.cross(x3 - x1, x2 - x1, dim=-1)
    e = x3 - x2
    with torch.no_grad():
        valid = ((n1.pow(2).sum(-1) >= _BEND_EPS ** 2) & (n2.pow(2).sum(-1) >= _BEND_EPS ** 2)
                 & (e.pow(2).sum(-1) >= _BEND_EPS ** 2))
    safe = torch.tensor([0.0, 0.0, 1.0], dtype=x.dtype, device=x.device)
    v = valid[..., None]
    n1 = torch.where(v, n1, safe)
    n2 = torch.where(v, n2, safe)
    e = torch.where(v, e, safe.roll(1))
    n1h = n1 / n1.norm(dim=-1, keepdim=True)
    n2h = n2 / n2.norm(dim=-1, keepdim=True)
    eh = e / e.norm(dim=-1, keepdim=True)
    sin = (torch.linalg.cross(n1h, n2h, dim=-1) * eh).sum(-1)
    cos = (n1h * n2h).sum(-1)
    theta = torch.atan2(sin, cos)
    return torch.where(valid, theta, torch.zeros_like(theta)), valid


def bending_energy(x: torch.Tensor, rest: GarmentRest, material: Material) -> torch.Tensor:
    """Dihedral bending energy, as Newton's ``evaluate_dihedral_angle_based_bending_force_hessian``.

    Per interior edge ``E = 1/2 k (theta - theta_rest)^2`` with ``k = edge_ke x l_rest``
    (:attr:`Material.bend_stiffness` times the rest edge length). Degenerate edges carry
    no energy, as in Newton. HOOD and SNUG weight ``theta^2`` by ``l^2 / (4 A)`` instead.

    Args:
        x: (B, N, 3) float garment positions [m].
        rest: the rest state.
        material: ``bend_stiffness``.
    Returns:
        (B,) energy [J].
    """
    _check_positions(x, rest)
    theta, valid = dihedral_angles(x, rest.edges)
    k = material.bend_stiffness * rest.rest_lengths.to(x.dtype)
    d = theta - rest.rest_angles.to(x.dtype)
    return torch.where(valid, 0.5 * k * d * d, torch.zeros_like(d)).sum(-1)


def gravity_energy(x: torch.Tensor, rest: GarmentRest, material: Material) -> torch.Tensor:
    """Gravitational potential ``sum_i m_i g y_i`` (zero at height y = 0).

    Args:
        x: (B, N, 3) float garment positions [m], Y up.
        rest: the rest state (its masses).
        material: ``gravity`` [m/s^2].
    Returns:
        (B,) energy [J].
    """
    _check_positions(x, rest)
    return material.gravity * (rest.masses.to(x.dtype) * x[..., 1]).sum(-1)


def contact_energy(x: torch.Tensor, body_points: torch.Tensor, body_normals: torch.Tensor, material: Material, *,
                   model: ContactModel | str = ContactModel.CUBIC, mask: torch.Tensor | None = None) -> torch.Tensor:
    """One-sided penalty keeping each garment vertex outside the body by the contact margin.

    With ``d = (x - p) . n`` (p the vertex's body point, n its outward unit normal) and
    r = :attr:`Material.contact_margin`:

    - :attr:`ContactModel.CUBIC` (HOOD's ``collision_penalty``, SNUG's):
      ``E = w sum max(r - d, 0)^3``, w = :attr:`Material.cubic_contact_weight` [J/m^3].
    - :attr:`ContactModel.VBD` (Newton's ``evaluate_self_contact_force_norm`` in the
      signed distance, k = :attr:`Material.contact_stiffness` [N/m], tau = r/2,
      d_min = min(1e-5, tau/2)): ``k/2 (r - d)^2`` for ``tau <= d < r``;
      ``k tau^2 (1/2 - ln(d / tau))`` for ``d_min <= d < tau``; its quadratic Taylor
      extension below d_min (finite for any penetration). C2 like Newton's. Newton
      measures the unsigned distance to the body's triangles and never lets it go
      negative; a signed distance also penalises a vertex that starts inside.

    Args:
        x: (B, N, 3) float garment positions [m].
        body_points: (B, N, 3) float nearest (or associated) body point per vertex [m].
        body_normals: (B, N, 3) float outward unit body normal there.
        material: ``contact_margin`` and the weight of the chosen profile.
        model: a :class:`ContactModel` or its value.
        mask: (N,) or (B, N) bool, vertices that take part (all when None).
    Returns:
        (B,) energy [J].
    """
    model = _enum(ContactModel, model, "model")
    if body_points.shape != x.shape or body_normals.shape != x.shape:
        raise ArgumentError(f"body_points and body_normals must have the shape of x {tuple(x.shape)}, got "
                            f"{tuple(body_points.shape)} and {tuple(body_normals.shape)}")
    d = ((x - body_points.to(x.dtype)) * body_normals.to(x.dtype)).sum(-1)  # (B, N)
    e = _contact_profile(d, material, model)
    if mask is not None:
        e = e * mask.to(e.dtype)
    return e.sum(-1)


def _contact_profile(d: torch.Tensor, material: Material, model: ContactModel) -> torch.Tensor:
    """Per-vertex contact energy [J] of signed distances d [m] (any shape)."""
    r = material.contact_margin
    if model is ContactModel.CUBIC:
        return material.cubic_contact_weight * torch.clamp(r - d, min=0.0) ** 3
    k, tau = material.contact_stiffness, 0.5 * r
    d_min = min(1.0e-5, 0.5 * tau)
    k2 = k * tau * tau
    e_tau = 0.5 * k * tau * tau
    dq = torch.clamp(d, min=tau, max=r)  # each branch on a clamped copy: finite gradients
    dl = torch.clamp(d, min=d_min, max=tau)
    quad = 0.5 * k * (r - dq) ** 2
    barrier = e_tau - k2 * torch.log(dl / tau)
    e_min = e_tau - k2 * math.log(d_min / tau)
    dd = torch.clamp(d, max=d_min) - d_min
    taylor = e_min - k2 / d_min * dd + 0.5 * k2 / (d_min * d_min) * dd * dd
    return torch.where(d >= tau, quad, torch.where(d >= d_min, barrier, taylor))


def inertia_energy(x: torch.Tensor, x_prev: torch.Tensor, x_prev2: torch.Tensor, rest: GarmentRest, *,
                   dt: float) -> torch.Tensor:
    """Implicit Euler's inertia ``sum_i m_i / (2 h^2) |x_t - y_t|^2``, ``y_t = 2 x_{t-1} - x_{t-2}``.

    y is the inertial prediction ``x_{t-1} + h v_{t-1}`` with ``v_{t-1} = (x_{t-1} - x_{t-2}) / h``
    (SNUG's ``inertial_term``, HOOD's ``inertia``); gravity is a separate term here, so
    y does not include ``h^2 g``. Zero for constant-velocity motion.

    Args:
        x: (B, N, 3) float positions at frame t [m].
        x_prev: (B, N, 3) float positions at t - 1 [m].
        x_prev2: (B, N, 3) float positions at t - 2 [m].
        rest: the rest state (its masses).
        dt: the time step h between frames [s] (1 / fps).
    Returns:
        (B,) energy [J].
    """
    _check_positions(x, rest)
    if x_prev.shape != x.shape or x_prev2.shape != x.shape:
        raise ArgumentError(f"x_prev and x_prev2 must have the shape of x {tuple(x.shape)}, got "
                            f"{tuple(x_prev.shape)} and {tuple(x_prev2.shape)}")
    if not dt > 0.0:
        raise ArgumentError(f"dt must be > 0 seconds, got {dt}")
    r = x - (2.0 * x_prev - x_prev2).to(x.dtype)
    return (rest.masses.to(x.dtype) * r.pow(2).sum(-1)).sum(-1) / (2.0 * dt * dt)


def contact_normal_force(x: torch.Tensor, body_points: torch.Tensor, body_normals: torch.Tensor, material: Material,
                         *, model: ContactModel | str = ContactModel.CUBIC) -> torch.Tensor:
    """Magnitude of each vertex's contact force, ``-dE/dd`` of :func:`contact_energy` (detached).

    Args:
        x: (B, N, 3) float garment positions [m].
        body_points: (B, N, 3) float body point per vertex [m].
        body_normals: (B, N, 3) float outward unit normals there.
        material: as for :func:`contact_energy`.
        model: the contact profile.
    Returns:
        (B, N) float normal force [N], 0 beyond the margin.
    """
    model = _enum(ContactModel, model, "model")
    with torch.enable_grad():
        d = ((x.detach() - body_points.to(x.dtype)) * body_normals.to(x.dtype)).sum(-1).detach().requires_grad_(True)
        (g,) = torch.autograd.grad(_contact_profile(d, material, model).sum(), d)
    return (-g).clamp_min(0.0).detach()


def friction_energy(x: torch.Tensor, x_prev: torch.Tensor, body_points: torch.Tensor, body_points_prev: torch.Tensor,
                    body_normals: torch.Tensor, normal_force: torch.Tensor, material: Material, *, dt: float,
                    epsilon: float = 1.0e-2) -> torch.Tensor:
    """Lagged, smoothed Coulomb friction against the body over one step (IPC form).

    With ``u`` the tangential part (w.r.t. ``body_normals``) of the vertex's displacement
    relative to its body point, ``(x - x_prev) - (p - p_prev)``, and ``eps_u = epsilon x dt``:
    ``E = mu lambda (f0(|u|) - eps_u / 3)``, ``f0(y) = y^2 / eps_u - y^3 / (3 eps_u^2) + eps_u / 3``
    below eps_u and ``y`` above. Its gradient is the force Newton's ``compute_friction``
    applies, ``mu lambda f1(|u|) u / |u|`` with ``f1(y) = 2 y / eps_u - y^2 / eps_u^2`` (1 above
    eps_u); ``lambda`` is the normal force, held constant (lagged) as VBD does within a step.

    Args:
        x: (B, N, 3) float positions at this frame [m].
        x_prev: (B, N, 3) float positions at the previous frame [m].
        body_points: (B, N, 3) float each vertex's body point now [m].
        body_points_prev: (B, N, 3) float the same body point (same barycentrics) one frame earlier [m].
        body_normals: (B, N, 3) float outward unit body normals.
        normal_force: (B, N) float normal force magnitudes [N] (:func:`contact_normal_force`).
        material: ``friction`` (mu).
        dt: time between the frames [s].
        epsilon: Newton's ``friction_epsilon`` [m/s], the slip speed below which friction is smoothed.
    Returns:
        (B,) energy [J].
    """
    if not (dt > 0.0 and epsilon > 0.0):
        raise ArgumentError(f"dt and epsilon must be > 0, got dt={dt}, epsilon={epsilon}")
    for name, t in (("x_prev", x_prev), ("body_points", body_points), ("body_points_prev", body_points_prev),
                    ("body_normals", body_normals)):
        if t.shape != x.shape:
            raise ArgumentError(f"{name} must have the shape of x {tuple(x.shape)}, got {tuple(t.shape)}")
    if normal_force.shape != x.shape[:-1]:
        raise ArgumentError(f"normal_force must be {tuple(x.shape[:-1])}, got {tuple(normal_force.shape)}")
    n = body_normals.to(x.dtype)
    rel = (x - x_prev.to(x.dtype)) - (body_points - body_points_prev).to(x.dtype)
    u = rel - (rel * n).sum(-1, keepdim=True) * n
    eps = epsilon * dt
    y_sq = u.pow(2).sum(-1)
    slow = y_sq < eps * eps
    y_fast = torch.where(slow, torch.full_like(y_sq, eps * eps), y_sq).sqrt()  # sqrt only where y >= eps
    y_slow = torch.where(slow, y_sq, torch.zeros_like(y_sq))
    f0 = torch.where(slow, y_slow / eps - y_slow.pow(1.5) / (3 * eps * eps),
                     y_fast - eps / 3.0)
    return (material.friction * normal_force.to(x.dtype) * f0).sum(-1)


# --------------------------------------------------------------------------- totals


@dataclass(frozen=True)
class EnergyTerms:
    """The named terms of the garment's energy, each (B,) float [J]."""

    membrane: torch.Tensor
    """Stretch and shear."""
    bending: torch.Tensor
    """Dihedral bending."""
    gravity: torch.Tensor
    """Gravitational potential (zero at y = 0)."""
    contact: torch.Tensor
    """Body contact penalty (zeros without body points)."""
    inertia: torch.Tensor
    """Inertia (zeros in the quasi-static variant)."""

    @property
    def total(self) -> torch.Tensor:
        """(B,) float sum of all terms [J]."""
        return self.membrane + self.bending + self.gravity + self.contact + self.inertia

    def as_dict(self) -> dict[str, torch.Tensor]:
        """The terms by name, plus ``"total"``."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["total"] = self.total
        return out


def garment_energy(x: torch.Tensor, rest: GarmentRest, material: Material, *,
                   body_points: torch.Tensor | None = None, body_normals: torch.Tensor | None = None,
                   previous: tuple[torch.Tensor, torch.Tensor] | None = None, dt: float | None = None,
                   membrane: MembraneModel | str = MembraneModel.NEO_HOOKEAN,
                   contact: ContactModel | str = ContactModel.CUBIC,
                   contact_mask: torch.Tensor | None = None) -> EnergyTerms:
    """All terms of the garment's energy; quasi-static unless ``previous`` is given.

    Args:
        x: (B, N, 3) float garment positions [m].
        rest: the rest state.
        material: the material.
        body_points: (B, N, 3) float body point per vertex [m]; with ``body_normals``
            enables the contact term.
        body_normals: (B, N, 3) float outward unit normals there.
        previous: ``(x_prev, x_prev2)``, each (B, N, 3) float [m], the two frames before
            x; enables the inertia term (needs ``dt``).
        dt: time between frames [s].
        membrane: the membrane law (:class:`MembraneModel`).
        contact: the contact profile (:class:`ContactModel`).
        contact_mask: (N,) or (B, N) bool vertices in contact consideration.
    Returns:
        :class:`EnergyTerms`.
    """
    _check_positions(x, rest)
    zeros = x.new_zeros(x.shape[0])
    if (body_points is None) != (body_normals is None):
        raise ArgumentError("body_points and body_normals go together: give both or neither")
    if previous is not None and dt is None:
        raise ArgumentError("the inertia term (previous=...) needs dt, the time between frames [s]")
    con = zeros if body_points is None else contact_energy(x, body_points, body_normals, material, model=contact,
                                                           mask=contact_mask)
    ine = zeros if previous is None else inertia_energy(x, previous[0], previous[1], rest, dt=dt)
    return EnergyTerms(membrane=membrane_energy(x, rest, material, model=membrane),
                       bending=bending_energy(x, rest, material), gravity=gravity_energy(x, rest, material),
                       contact=con, inertia=ine)


class GarmentEnergy(nn.Module):
    """:func:`garment_energy` for one garment, its rest state held as buffers.

    Shapes:
        x: (B, N, 3) float [m]; output :class:`EnergyTerms` of (B,) [J].
    """

    def __init__(self, rest: GarmentRest, material: Material, *,
                 membrane: MembraneModel | str = MembraneModel.NEO_HOOKEAN,
                 contact: ContactModel | str = ContactModel.CUBIC) -> None:
        super().__init__()
        self.material = material
        self.membrane = _enum(MembraneModel, membrane, "membrane")
        self.contact = _enum(ContactModel, contact, "contact")
        self._fields = [f.name for f in dataclasses.fields(GarmentRest)]
        for name in self._fields:
            self.register_buffer(name, getattr(rest, name))

    @property
    def rest(self) -> GarmentRest:
        """The rest state, on this module's device and dtype."""
        return GarmentRest(**{name: getattr(self, name) for name in self._fields})

    def forward(self, x: torch.Tensor, *, body_points: torch.Tensor | None = None,
                body_normals: torch.Tensor | None = None,
                previous: tuple[torch.Tensor, torch.Tensor] | None = None, dt: float | None = None,
                contact_mask: torch.Tensor | None = None) -> EnergyTerms:
        return garment_energy(x, self.rest, self.material, body_points=body_points, body_normals=body_normals,
                              previous=previous, dt=dt, membrane=self.membrane, contact=self.contact,
                              contact_mask=contact_mask)


def _enum(kind: type[enum.Enum], value, name: str):
    try:
        return kind(value)
    except ValueError:
        raise ArgumentError(f"{name} must be one of {[m.value for m in kind]}, got {value!r}") from None
