"""The garment energy: analytic values on hand-built sheets, invariances, gradients, and
agreement with Newton's own formulas (and kernels) where newton is installed."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="cloth_usd.nn needs torch (pip install 'cloth-usd[train]')")

from meshes import grid, icosphere  # noqa: E402

from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.nn.physics import (  # noqa: E402
    ContactModel,
    GarmentEnergy,
    Material,
    MembraneModel,
    bending_energy,
    contact_energy,
    contact_normal_force,
    dihedral_angles,
    friction_energy,
    garment_energy,
    garment_rest,
    gravity_energy,
    inertia_energy,
    membrane_energy,
)

F64 = torch.float64
MAT = Material(density=0.2, stretch_mu=3.0e3, stretch_lambda=2.0e3, bend_stiffness=1.0e-3,
               contact_stiffness=1.0e4, contact_margin=4.0e-3, gravity=9.81)


def sheet(nx: int = 5, ny: int = 4, cell: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """A flat sheet in the z = 0 plane, counter-clockwise seen from +z: (verts (N, 3), faces (M, 3))."""
    xs, ys = np.meshgrid(np.arange(nx) * cell, np.arange(ny) * cell)
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], 1)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def hinge(length: float = 0.04, half_width: float = 0.02, fold: float = 0.0) -> np.ndarray:
    """Two triangles (2, 0, 1) and (3, 1, 0) sharing the edge 0 -> 1 along x; vertex 3's wing
    is rotated by ``fold`` [rad] about the edge, toward +z (the side the normals face)."""
    return np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0], [length / 2, half_width, 0.0],
                     [length / 2, -half_width * math.cos(fold), half_width * math.sin(fold)]])


HINGE_FACES = np.array([[2, 0, 1], [3, 1, 0]])


def rotation(axis, angle) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def t64(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a), dtype=F64)


# --------------------------------------------------------------------------- rest state


def test_rest_state_masses_areas_and_edges():
    v, f = sheet(5, 4, 0.02)
    rest = garment_rest(v, f, MAT, dtype=F64)
    area = 4 * 3 * 0.02 ** 2
    torch.testing.assert_close(rest.areas.sum(), t64(area), atol=1e-15, rtol=1e-12)
    torch.testing.assert_close(rest.masses.sum(), t64(MAT.density * area), atol=1e-15, rtol=1e-12)
    # A 5 x 4 grid has 4*3 cells: 12 diagonals + 3*3 vertical + 4*2 horizontal interior edges.
    assert rest.edges.shape == (12 + 9 + 8, 4)
    faces = {tuple(t) for t in f.tolist()}
    rot = lambda t: {t, t[1:] + t[:1], t[2:] + t[:2]}  # noqa: E731
    for o0, o1, v0, v1 in rest.edges.tolist():  # both triangles exist, wound (o0, v0, v1), (o1, v1, v0)
        assert rot((o0, v0, v1)) & faces and rot((o1, v1, v0)) & faces
    torch.testing.assert_close(rest.rest_angles, torch.zeros_like(rest.rest_angles), atol=1e-12, rtol=0)
    torch.testing.assert_close(rest.rest_lengths.min(), t64(0.02))


def test_rest_state_of_a_closed_surface():
    f, v = icosphere(1)
    rest = garment_rest(v, f, MAT, dtype=F64)
    assert rest.edges.shape[0] == 3 * f.shape[0] // 2  # every edge is interior
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert volume > 0  # wound outward
    assert torch.all(rest.rest_angles > 0)  # convex: each wing folds away from the normals
    v_cut, f_cut = sheet(3, 3)
    assert torch.all(garment_rest(v_cut, f_cut, rest_angles="flat").rest_angles == 0)


def test_rest_state_rejects_malformed_input():
    v, f = sheet(3, 3)
    with pytest.raises(ArgumentError, match="faces"):
        garment_rest(v, f + 100)
    with pytest.raises(ArgumentError, match="vertices"):
        garment_rest(v[:, :2], f)
    with pytest.raises(ArgumentError, match="rest_angles"):
        garment_rest(v, f, rest_angles="bent")


# --------------------------------------------------------------------------- membrane, bending


@pytest.mark.parametrize("model", list(MembraneModel))
def test_flat_sheet_at_rest_has_no_energy_or_gradient(model):
    v, f = sheet()
    rest = garment_rest(v, f, MAT, dtype=F64)
    x = t64(v)[None].clone().requires_grad_(True)
    e = membrane_energy(x, rest, MAT, model=model) + bending_energy(x, rest, MAT)
    (g,) = torch.autograd.grad(e.sum(), x)
    assert abs(float(e.detach())) < 1e-12
    assert float(g.abs().max()) < 1e-9


@pytest.mark.parametrize("s", [0.8, 1.0, 1.1, 1.5])
def test_uniaxial_stretch_has_the_analytic_energy(s):
    # Stretch x by s, keep y: F^T F = diag(s^2, 1), J = s; the energy is area * psi(s).
    v, f = sheet(4, 3, 0.03)
    rest = garment_rest(v, f, MAT, dtype=F64)
    x = t64(v * [s, 1.0, 1.0])[None]
    area = 3 * 2 * 0.03 ** 2
    mu, lam = MAT.stretch_mu, MAT.stretch_lambda
    lam_nh = lam + mu
    alpha = 1 + mu / lam_nh
    psi_nh = mu / 2 * (s * s - 1) + lam_nh / 2 * ((s - alpha) ** 2 - (1 - alpha) ** 2)
    g = (s * s - 1) / 2
    psi_stvk = mu * g * g + lam / 2 * g * g
    torch.testing.assert_close(membrane_energy(x, rest, MAT), t64([area * psi_nh]), atol=1e-12, rtol=1e-10)
    torch.testing.assert_close(membrane_energy(x, rest, MAT, model="stvk"), t64([area * psi_stvk]),
                               atol=1e-12, rtol=1e-10)
    # Stretching a flat sheet in its plane does not bend it.
    assert abs(float(bending_energy(x, rest, MAT))) < 1e-15


@pytest.mark.parametrize("model", list(MembraneModel))
def test_rigid_motion_leaves_membrane_and_bending_at_zero(model):
    f, v = icosphere(1)
    v = 0.1 * v  # a curved rest garment: its rest angles are not zero
    rest = garment_rest(v, f, MAT, dtype=F64)
    moved = v @ rotation([0.3, -1.0, 0.5], 2.1).T + [0.4, -1.2, 0.7]
    x = t64(np.stack([v, moved]))
    e_m = membrane_energy(x, rest, MAT, model=model)
    e_b = bending_energy(x, rest, MAT)
    torch.testing.assert_close(e_m, torch.zeros(2, dtype=F64), atol=1e-11, rtol=0)
    torch.testing.assert_close(e_b, torch.zeros(2, dtype=F64), atol=1e-14, rtol=0)
    # ... while a real deformation of it has energy.
    assert float(bending_energy(t64(v * [1.3, 1.0, 1.0])[None], rest, MAT)) > 1e-8


@pytest.mark.parametrize("fold", [0.3, -0.7, 2.5])
def test_folded_hinge_has_the_analytic_bending_energy(fold):
    rest = garment_rest(hinge(), HINGE_FACES, MAT, dtype=F64)
    assert rest.edges.tolist() == [[2, 3, 0, 1]]
    x = t64(hinge(fold=fold))[None]
    theta, valid = dihedral_angles(x, rest.edges)
    # Lifting vertex 3's wing toward the normals (+z) is a negative angle in Newton's convention.
    torch.testing.assert_close(theta, t64([[-fold]]), atol=1e-12, rtol=0)
    assert bool(valid.all())
    k = MAT.bend_stiffness * 0.04  # edge_ke x rest length
    torch.testing.assert_close(bending_energy(x, rest, MAT), t64([0.5 * k * fold ** 2]), atol=1e-15, rtol=1e-10)


def test_bending_is_measured_from_the_rest_angle():
    rest = garment_rest(hinge(fold=0.4), HINGE_FACES, MAT, dtype=F64)
    torch.testing.assert_close(rest.rest_angles, t64([-0.4]))
    x = t64(np.stack([hinge(fold=0.4), hinge(fold=0.0)]))
    k = MAT.bend_stiffness * 0.04
    torch.testing.assert_close(bending_energy(x, rest, MAT), t64([0.0, 0.5 * k * 0.4 ** 2]), atol=1e-15, rtol=1e-10)


def test_degenerate_triangles_give_finite_energy_and_gradient():
    v, f = sheet(4, 4)
    rest = garment_rest(v, f, MAT, dtype=F64)
    x = t64(v).clone()
    x[5] = x[6]  # two vertices on top of each other: zero-length edge, two zero-area triangles
    x[9:12] = x[9]  # a row collapsed to a point
    x = x[None].requires_grad_(True)
    for model in MembraneModel:
        for c in ContactModel:
            terms = garment_energy(x, rest, MAT, body_points=torch.zeros_like(x), body_normals=torch.zeros_like(x),
                                   membrane=model, contact=c)
            (g,) = torch.autograd.grad(terms.total.sum(), x)
            assert torch.isfinite(terms.total).all() and torch.isfinite(g).all(), (model, c)
    # A degenerate rest triangle carries no area, mass or energy, and breaks nothing.
    v_bad = v.copy()
    v_bad[5] = v_bad[6]
    rest_bad = garment_rest(v_bad, f, MAT, dtype=F64)
    assert int((rest_bad.areas == 0).sum()) == 2
    xb = t64(v)[None].requires_grad_(True)
    (g,) = torch.autograd.grad(garment_energy(xb, rest_bad, MAT).total.sum(), xb)
    assert torch.isfinite(g).all()


def test_gradcheck_membrane_and_bending():
    rng = np.random.default_rng(0)
    v, f = sheet(3, 3, 0.05)
    rest = garment_rest(v + rng.normal(0, 0.005, v.shape), f, MAT, dtype=F64)
    x = t64(v + rng.normal(0, 0.01, v.shape))[None].requires_grad_(True)
    small = Material(stretch_mu=3.0, stretch_lambda=2.0, bend_stiffness=1.0)  # O(1) energies
    for model in MembraneModel:
        assert torch.autograd.gradcheck(lambda y, m=model: membrane_energy(y, rest, small, model=m), (x,),
                                        eps=1e-6, atol=1e-6, rtol=1e-4)
    assert torch.autograd.gradcheck(lambda y: bending_energy(y, rest, small), (x,), eps=1e-6, atol=1e-6, rtol=1e-4)


# --------------------------------------------------------------------------- gravity, contact, inertia


def test_gravity_energy_of_a_raised_sheet():
    v, f = sheet()
    rest = garment_rest(v, f, MAT, dtype=F64)
    x = t64(np.stack([v, v + [0.3, 0.25, -0.1]]))
    e = gravity_energy(x, rest, MAT)
    torch.testing.assert_close(e[1] - e[0], t64(rest.total_mass * MAT.gravity * 0.25), atol=1e-14, rtol=1e-12)


@pytest.mark.parametrize("model", list(ContactModel))
def test_contact_is_one_sided(model):
    v, f = sheet(3, 3)
    x = t64(v)[None].clone().requires_grad_(True)
    normals = t64([0.0, 0.0, 1.0]).expand_as(x)
    far = x.detach() - t64([0.0, 0.0, 1.01 * MAT.contact_margin])  # every vertex beyond the margin
    assert float(contact_energy(x.detach(), far, normals, MAT, model=model)) == 0.0
    inside = far.clone()
    inside[0, 4, 2] = float(x[0, 4, 2].detach()) + 0.001  # vertex 4 is 1 mm behind the body surface
    e = contact_energy(x, inside, normals, MAT, model=model)
    (g,) = torch.autograd.grad(e.sum(), x)
    assert float(e.detach()) > 0.0
    assert float(g[0, 4, 2]) < 0.0  # descending the energy pushes the vertex out along the normal
    g_other = g.clone()
    g_other[0, 4] = 0.0
    assert float(g_other.abs().max()) == 0.0
    mask = torch.ones(x.shape[1], dtype=torch.bool)
    mask[4] = False
    assert float(contact_energy(x.detach(), inside, normals, MAT, model=model, mask=mask)) == 0.0


def test_contact_profiles_values():
    x = torch.zeros(1, 7, 3, dtype=F64)
    n = t64([0.0, 1.0, 0.0]).expand_as(x)
    r, k = MAT.contact_margin, MAT.contact_stiffness
    tau, d_min = r / 2, 1e-5
    d = t64([r, 0.75 * r, tau, 0.5 * tau, d_min, 0.0, -0.002])
    p = torch.zeros_like(x)
    p[0, :, 1] = -d
    per = [float(contact_energy(x[:, i:i + 1], p[:, i:i + 1], n[:, i:i + 1], MAT, model="vbd")) for i in range(7)]
    e_tau = 0.5 * k * tau ** 2
    expect = [0.0, 0.5 * k * (0.25 * r) ** 2, e_tau, e_tau + k * tau ** 2 * math.log(2.0),
              e_tau - k * tau ** 2 * math.log(d_min / tau)]
    np.testing.assert_allclose(per[:5], expect, rtol=1e-10, atol=1e-12)
    assert per[6] > per[5] > per[4]  # finite and growing under penetration
    w = MAT.cubic_contact_weight
    assert w == pytest.approx(k / r)
    assert float(contact_energy(x[:, 2:3], p[:, 2:3], n[:, 2:3], MAT)) == pytest.approx(w * tau ** 3)
    assert w * tau ** 3 == pytest.approx(e_tau)  # the default cubic weight matches VBD at half the margin


def test_vbd_contact_is_c1():
    r = MAT.contact_margin
    for d0 in (r / 2, 1e-5):  # the two joints of the profile
        d = t64([d0 - 1e-9, d0 + 1e-9]).requires_grad_(True)
        x = torch.zeros(1, 2, 3, dtype=F64)
        p = torch.zeros(1, 2, 3, dtype=F64)
        n = t64([0.0, 1.0, 0.0]).expand(1, 2, 3)
        x = x + torch.stack([torch.zeros(2, dtype=F64), d, torch.zeros(2, dtype=F64)], -1)[None]
        e = contact_energy(x, p, n, MAT, model=ContactModel.VBD)
        (g,) = torch.autograd.grad(e, d)
        assert float(g[0]) == pytest.approx(float(g[1]), rel=1e-3)


def test_inertia_is_zero_for_constant_velocity():
    v, f = sheet()
    rest = garment_rest(v, f, MAT, dtype=F64)
    x0 = t64(v)[None]
    vel = t64([0.1, -0.2, 0.05])
    h = 1 / 24
    x1, x2 = x0 + vel * h, x0 + 2 * vel * h
    torch.testing.assert_close(inertia_energy(x2, x1, x0, rest, dt=h), t64([0.0]), atol=1e-15, rtol=0)
    # Falling one frame from rest by g h^2 costs m/(2 h^2) |g h^2|^2 = m g^2 h^2 / 2.
    drop = x1.clone()
    drop[..., 1] -= MAT.gravity * h * h
    torch.testing.assert_close(inertia_energy(drop, x1, x1, rest, dt=h),
                               t64([rest.total_mass * MAT.gravity ** 2 * h * h / 2]), atol=1e-15, rtol=1e-10)


def test_contact_normal_force_is_minus_the_profile_slope():
    r, k = MAT.contact_margin, MAT.contact_stiffness
    d = t64([2 * r, 0.75 * r, 0.25 * r])
    x = torch.stack([torch.zeros(3, dtype=F64), d, torch.zeros(3, dtype=F64)], -1)[None]
    p, n = torch.zeros_like(x), t64([0.0, 1.0, 0.0]).expand_as(x)
    vbd = contact_normal_force(x, p, n, MAT, model="vbd")[0]
    torch.testing.assert_close(vbd[:2], t64([0.0, k * 0.25 * r]))
    assert float(vbd[2]) == pytest.approx(k * (r / 2) ** 2 / (0.25 * r))  # the barrier: k tau^2 / d
    cubic = contact_normal_force(x, p, n, MAT)[0]
    torch.testing.assert_close(cubic, t64([0.0, 3 * MAT.cubic_contact_weight * (0.25 * r) ** 2,
                                           3 * MAT.cubic_contact_weight * (0.75 * r) ** 2]))


def test_friction_opposes_slip_like_newtons_compute_friction():
    h, eps_v = 1 / 24, 1e-2
    eps_u = eps_v * h
    n = t64([0.0, 1.0, 0.0]).expand(1, 3, 3)
    p_prev = torch.zeros(1, 3, 3, dtype=F64)
    p = p_prev + t64([0.01, 0.0, 0.0])  # the body moves 1 cm along x
    x_prev = torch.zeros(1, 3, 3, dtype=F64)
    # vertex 0 rides with the body (plus a normal move); 1 slips slowly, 2 fast, along z
    x = torch.stack([t64([0.01, 0.003, 0.0]), t64([0.01, 0.0, 0.3 * eps_u]), t64([0.01, 0.0, 5 * eps_u])])[None]
    x = x.clone().requires_grad_(True)
    lam = t64([[2.0, 2.0, 2.0]])
    mat = Material(friction=0.4)
    e = friction_energy(x, x_prev, p, p_prev, n, lam, mat, dt=h, epsilon=eps_v)
    (g,) = torch.autograd.grad(e.sum(), x)
    y_slow, y_fast = 0.3 * eps_u, 5 * eps_u
    f0 = y_slow ** 2 / eps_u - y_slow ** 3 / (3 * eps_u ** 2) + (y_fast - eps_u / 3)
    assert float(e.detach()) == pytest.approx(0.4 * 2.0 * f0, rel=1e-10)
    # Newton: force = -mu lambda f1(y)/y u, f1/y = (2 - y/eps)/eps below eps, 1/y above.
    f1_slow = (2 - y_slow / eps_u) / eps_u * y_slow
    torch.testing.assert_close(-g[0], t64([[0.0, 0.0, 0.0], [0.0, 0.0, -0.8 * f1_slow], [0.0, 0.0, -0.8]]))
    x0 = x_prev.clone().requires_grad_(True)  # no slip at all: zero energy, finite (zero) gradient
    (g0,) = torch.autograd.grad(friction_energy(x0, x_prev, p_prev, p_prev, n, lam, mat, dt=h).sum(), x0)
    assert float(g0.abs().max()) == 0.0


def test_gradcheck_contact_and_friction():
    rng = np.random.default_rng(3)
    small = Material(contact_stiffness=1.0, contact_margin=0.1, friction=0.5)
    x = t64(rng.uniform(-0.02, 0.12, (1, 12, 3)))  # distances spread across every branch of both profiles
    x[..., :2] = 0.0
    n = t64([0.0, 0.0, 1.0]).expand_as(x)
    p = torch.zeros_like(x)
    xg = x.clone().requires_grad_(True)
    for model in ContactModel:
        assert torch.autograd.gradcheck(lambda y, m=model: contact_energy(y, p, n, small, model=m), (xg,),
                                        eps=1e-7, atol=1e-5, rtol=1e-4)
    x_prev = x + t64(rng.normal(0, 0.02, x.shape))  # slips on both sides of eps_u = 0.05 * 0.5
    lam = t64(rng.uniform(0.5, 2.0, (1, 12)))
    assert torch.autograd.gradcheck(lambda y: friction_energy(y, x_prev, p, p, n, lam, small, dt=0.5, epsilon=0.05),
                                    (xg,), eps=1e-7, atol=1e-5, rtol=1e-4)


# --------------------------------------------------------------------------- totals, config


def test_total_is_the_sum_of_named_terms_and_the_module_agrees():
    f, v = grid(5, 4)
    rest = garment_rest(v, f, MAT)
    x = torch.as_tensor(v, dtype=torch.float32)[None].repeat(3, 1, 1) * 1.05
    bp, bn = x - 0.001, torch.nn.functional.normalize(torch.ones_like(x), dim=-1)
    terms = garment_energy(x, rest, MAT, body_points=bp, body_normals=bn, previous=(x, x * 0.99), dt=0.04)
    d = terms.as_dict()
    assert set(d) == {"membrane", "bending", "gravity", "contact", "inertia", "total"}
    assert all(t.shape == (3,) for t in d.values())
    torch.testing.assert_close(d["total"], sum(d[k] for k in d if k != "total"))
    module = GarmentEnergy(rest, MAT).double()
    xd = x.double()
    again = module(xd, body_points=bp.double(), body_normals=bn.double(), previous=(xd, xd * 0.99), dt=0.04)
    torch.testing.assert_close(again.total.float(), terms.total, rtol=1e-4, atol=1e-6)
    quasi = garment_energy(x, rest, MAT)
    assert float(quasi.contact.abs().max()) == 0.0 and float(quasi.inertia.abs().max()) == 0.0
    with pytest.raises(ArgumentError, match="dt"):
        garment_energy(x, rest, MAT, previous=(x, x))
    with pytest.raises(ArgumentError, match="membrane"):
        GarmentEnergy(rest, MAT, membrane="linear")
    with pytest.raises(ArgumentError, match=r"\(B, 20, 3\)"):
        garment_energy(x[:, :5], rest, MAT)


def test_material_from_the_simulator_config():
    from cloth_usd.datagen.simulate import SimConfig

    cfg = SimConfig(density=0.2, stretch_stiffness=7e3, bend_stiffness=2e-5, contact_stiffness=3e4,
                    contact_margin=5e-3, friction=0.4, gravity=9.8)
    m = Material.from_sim_config(cfg)
    assert (m.density, m.stretch_mu, m.stretch_lambda, m.bend_stiffness) == (0.2, 7e3, 7e3, 2e-5)
    assert (m.contact_stiffness, m.contact_margin, m.friction, m.gravity) == (3e4, 5e-3, 0.4, 9.8)
    assert Material.from_sim_config(cfg, contact_weight=1e5).cubic_contact_weight == 1e5
    with pytest.raises(ArgumentError, match="density"):
        Material(density=-1.0)


def test_importing_physics_pulls_in_no_simulator():
    import subprocess
    import sys

    code = "import sys, cloth_usd.nn.physics; print('warp' in sys.modules or 'newton' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------- against Newton


def test_rest_state_matches_newtons_model():
    """Our rest state equals what Newton's ModelBuilder.add_cloth_mesh builds (float32)."""
    newton = pytest.importorskip("newton", reason="comparing with Newton needs newton (pip install newton==1.8.0)")
    import warp as wp

    f, v = icosphere(1)
    v = (0.1 * v + np.random.default_rng(1).normal(0, 0.004, v.shape)).astype(np.float32)
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -MAT.gravity, 0.0))
    builder.add_cloth_mesh(pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
                           vertices=[wp.vec3(*p) for p in v], indices=f.ravel().tolist(), density=MAT.density,
                           tri_ke=MAT.stretch_mu, tri_ka=MAT.stretch_lambda, edge_ke=MAT.bend_stiffness)
    model = builder.finalize(device="cpu")
    rest = garment_rest(v, f, MAT, dtype=F64)
    newton_edges = model.edge_indices.numpy()
    interior = newton_edges[:, 1] >= 0
    np.testing.assert_array_equal(rest.edges.numpy(), newton_edges[interior])
    np.testing.assert_allclose(rest.dm_inv.numpy(), model.tri_poses.numpy(), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(rest.areas.numpy(), model.tri_areas.numpy(), rtol=1e-5)
    np.testing.assert_allclose(rest.masses.numpy(), model.particle_mass.numpy(), rtol=1e-5)
    np.testing.assert_allclose(rest.rest_angles.numpy(), model.edge_rest_angle.numpy()[interior], atol=1e-6)
    np.testing.assert_allclose(rest.rest_lengths.numpy(), model.edge_rest_length.numpy()[interior], rtol=1e-5)
    np.testing.assert_allclose(model.tri_materials.numpy()[:, :2], [[MAT.stretch_mu, MAT.stretch_lambda]] * len(f))


def test_angle_matches_newtons_formula():
    pytest.importorskip("newton", reason="comparing with Newton needs newton (pip install newton==1.8.0)")
    from newton._src.geometry.rest_shape import _dihedral_angles

    # A bent sheet and a hinge folded both ways: our angle against the formula Newton builds rest angles with.
    sv, sf = sheet(3, 3)
    srest = garment_rest(sv, sf, MAT, dtype=F64)
    bent = sv.copy()
    bent[:, 2] = 0.3 * (bent[:, 0] - 0.02) ** 2 / 0.02 - 0.2 * (bent[:, 1] - 0.02) * (bent[:, 0] > 0.02)
    for x in (bent, hinge(fold=0.6), hinge(fold=-1.1)):
        edges = srest.edges if x.shape[0] == 9 else garment_rest(hinge(), HINGE_FACES).edges
        e = edges.numpy()
        theirs = _dihedral_angles(x[e[:, 0]], x[e[:, 1]], x[e[:, 2]], x[e[:, 3]], x[e[:, 2]], x[e[:, 3]])
        ours, _ = dihedral_angles(t64(x)[None], edges)
        np.testing.assert_allclose(ours[0].numpy(), theirs, atol=1e-12)
        assert np.any(np.abs(theirs) > 0.05)


@pytest.mark.slow
def test_forces_match_newtons_vbd_kernels():
    """-grad of our membrane and bending energies equals the force Newton's VBD kernels compute."""
    pytest.importorskip("newton", reason="comparing with Newton needs newton (pip install newton==1.8.0)")
    import warp as wp
    from newton._src.solvers.vbd.particle_vbd_kernels import (
        evaluate_dihedral_angle_based_bending_force_hessian,
        evaluate_neo_hookean_membrane_force_hessian,
    )

    @wp.kernel
    def membrane_forces(pos: wp.array(dtype=wp.vec3), tris: wp.array2d(dtype=wp.int32),
                        poses: wp.array(dtype=wp.mat22), areas: wp.array(dtype=float), mu: float, lam: float,
                        out: wp.array(dtype=wp.vec3)):
        t, c = wp.tid()
        force, _h = evaluate_neo_hookean_membrane_force_hessian(t, c, pos, pos, tris, poses[t], areas[t], mu, lam,
                                                                0.0, 1.0)
        wp.atomic_add(out, tris[t, c], force)

    @wp.kernel
    def bending_forces(pos: wp.array(dtype=wp.vec3), edges: wp.array2d(dtype=wp.int32),
                       angles: wp.array(dtype=float), lengths: wp.array(dtype=float), ke: float,
                       out: wp.array(dtype=wp.vec3)):
        e, c = wp.tid()
        force, _h = evaluate_dihedral_angle_based_bending_force_hessian(e, c, pos, pos, edges, angles, lengths, ke,
                                                                        0.0, 1.0)
        wp.atomic_add(out, edges[e, c], force)

    f, v = icosphere(1)
    rng = np.random.default_rng(2)
    v = 0.1 * v
    rest = garment_rest(v, f, MAT, dtype=F64)
    x = v * [1.1, 0.95, 1.0] + rng.normal(0, 0.003, v.shape)
    xt = t64(x)[None].requires_grad_(True)
    (g_m,) = torch.autograd.grad(membrane_energy(xt, rest, MAT).sum(), xt)
    (g_b,) = torch.autograd.grad(bending_energy(xt, rest, MAT).sum(), xt)

    with wp.ScopedDevice("cpu"):
        pos = wp.array(x.astype(np.float32), dtype=wp.vec3)
        out_m = wp.zeros(len(x), dtype=wp.vec3)
        wp.launch(membrane_forces, dim=(len(f), 3),
                  inputs=[pos, wp.array(f.astype(np.int32), dtype=wp.int32),
                          wp.array(rest.dm_inv.numpy().astype(np.float32), dtype=wp.mat22),
                          wp.array(rest.areas.numpy().astype(np.float32), dtype=float),
                          MAT.stretch_mu, MAT.stretch_lambda, out_m])
        out_b = wp.zeros(len(x), dtype=wp.vec3)
        wp.launch(bending_forces, dim=(rest.edges.shape[0], 4),
                  inputs=[pos, wp.array(rest.edges.numpy().astype(np.int32), dtype=wp.int32),
                          wp.array(rest.rest_angles.numpy().astype(np.float32), dtype=float),
                          wp.array(rest.rest_lengths.numpy().astype(np.float32), dtype=float),
                          MAT.bend_stiffness, out_b])
    for ours, theirs in ((-g_m[0].numpy(), out_m.numpy()), (-g_b[0].numpy(), out_b.numpy())):
        scale = np.abs(ours).max()
        assert scale > 0
        np.testing.assert_allclose(theirs, ours, atol=2e-3 * scale, rtol=0)
