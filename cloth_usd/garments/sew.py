"""Sew a triangulated pattern on the T-posed body and drape it, with Newton's VBD.

Simulations on the standing (rest-pose) body, whose surface is the same mesh-shape
collider the data factory uses (:func:`cloth_usd.datagen.simulate.make_collider`):

1. **Stitch.** The panels, placed flat around the body, are one cloth with the seams as
   zero-rest-length springs and no gravity: the springs pull each seam's two edges
   together round the body while the body keeps the cloth out.
2. **Merge, relax, drape, settle.** Each seam's vertex pairs become one vertex (at their
   mean), and from here the garment's rest metric is the flat pattern (each triangle's rest
   shape and area, each bending edge's rest length, from its panel; every rest dihedral
   angle 0: flat panels). It relaxes to that metric for a few frames with no gravity and
   nothing held (where three or four panels meet, the seams are still centimetres apart
   when the stitch ends), hangs under gravity (a waistband held where it was sewn), and
   settles for a few frames at more VBD iterations per step, since a few iterations leave
   a hanging garment a little stretched however long it hangs.

Newton and warp are imported lazily. Shape letters: N pattern vertices, K merged (garment)
vertices, M triangles, S seam pairs, E edges.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..core.body import BodyModel, shape_body
from ..core.features import vertex_normals
from ..core.postprocess import LIFT_MARGIN, LIFT_STRETCH, TriangleLift
from ..datagen.simulate import SimConfig, SimulationError, _import_engine, make_collider, resolve_device
from ..errors import ArgumentError
from .pattern import PatternMesh

__all__ = ["SewConfig", "SewnGarment", "merge_seams", "pattern_edge_lengths", "conform_placement", "sew",
           "lift_off_skin", "push_out"]

log = logging.getLogger(__name__)

#: The cloth material and solver for sewing: the data factory's defaults without
#: self-contact (the stitch pulls panels through each other's margins) and a full-body
#: collider is not needed at rest.
_SEW_SIM = SimConfig(self_contact=False, substeps=12, iterations=5)


@dataclass(frozen=True)
class SewConfig:
    """How a pattern is stitched and draped."""

    stitch_frames: int = 32
    """Frames (at ``sim.fps``) of seam springs pulling the placed panels together, no gravity."""
    drape_frames: int = 16
    """Frames of the merged garment hanging under gravity."""
    relax_frames: int = 2
    """Frames of the merged garment relaxing to its pattern with no gravity and nothing held,
    at ``settle_iterations``: where three or four panels meet, the seams are still apart
    when the stitch ends and merging them at their mean stretches the edges there; a held
    waistband would keep that stretch through the drape."""
    settle_frames: int = 4
    """Frames after the drape at ``settle_iterations``. VBD stops after a few iterations per
    step, so a hanging garment rests a little stretched (slim trousers at 1000 vertices: p99
    1.054 after 4 settling frames, against 1.066 after the drape and still 1.065 after 48
    drape frames)."""
    settle_iterations: int = 30
    """VBD iterations per step while relaxing and settling."""
    seam_stiffness: float = 60.0
    """Seam spring stiffness [N/m] (rest length 0)."""
    seam_damping: float = 0.05
    """Seam spring damping [N s/m]."""
    lift_rounds: int = 2
    """Rounds of the lift of the draped garment's triangles off the skin between its vertices
    (:func:`lift_off_skin`, to :attr:`lift_margin` behind them); 0: none."""
    lift_margin: float = LIFT_MARGIN
    """How far [m] the lift puts the skin behind the garment's triangles (the detail tier's own)."""
    lift_stretch: float = 1.05
    """The lift stretches no edge past this times its length in the pattern (further than the drape did):
    bounded at 1.5 x its draped length instead, it took the 400-vertex shorts' p99 to 1.065."""
    sim: SimConfig = field(default_factory=lambda: _SEW_SIM)
    """Material, contact and solver (its ``drape_frames`` is unused)."""


@dataclass(frozen=True)
class SewnGarment:
    """A pattern sewn and draped on a body: the worn garment at rest."""

    points: np.ndarray
    """(K, 3) float64 draped garment [m], canonical body frame."""
    faces: np.ndarray
    """(M, 3) int64 triangles over ``points``."""
    corner_vertex: np.ndarray
    """(M, 3) int64 the pattern vertex (an index into the PatternMesh) at each triangle corner:
    the face-varying index of the UVs."""
    vertex_of: np.ndarray
    """(N,) int64 the garment vertex each pattern vertex became."""
    stretch: np.ndarray
    """(E,) float64 each garment edge's draped length over its length in the pattern."""
    stitched_gap: float
    """Largest distance [m] between a seam's two sides when the stitch ended."""
    seconds: float
    skin_through: tuple[int, int] | None = None
    """The body vertices it covers more than 1 mm in front of its triangles, before and after the lift
    (:func:`lift_off_skin`; None: not lifted)."""


def merge_seams(num_vertices: int, seams: np.ndarray) -> np.ndarray:
    """(N,) int64: each pattern vertex's merged vertex, numbered in order of first appearance.

    Args:
        seams: (S, 2) int vertex pairs to merge (chains merge transitively).
    """
    parent = np.arange(num_vertices)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in seams:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(i) for i in range(num_vertices)])
    _, index = np.unique(roots, return_inverse=True)
    return index.astype(np.int64)


def pattern_edge_lengths(uv: np.ndarray, faces: np.ndarray, corner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each undirected garment edge and its length in the pattern (averaged over the panels
    that hold it: a seam edge is in two).

    Args:
        uv: (N, 2) pattern coordinates [m].
        faces: (M, 3) garment triangles; corner: (M, 3) their pattern vertices.
    Returns:
        ``(edges (E, 2) int64 sorted pairs, lengths (E,) float64 [m])``.
    """
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    c = np.concatenate([corner[:, [0, 1]], corner[:, [1, 2]], corner[:, [2, 0]]])
    length = np.linalg.norm(uv[c[:, 0]] - uv[c[:, 1]], axis=1)
    edges, inverse = np.unique(np.sort(e, axis=1), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    total = np.bincount(inverse, weights=length, minlength=len(edges))
    return edges.astype(np.int64), total / np.bincount(inverse, minlength=len(edges))


def _rest_frames(uv: np.ndarray, corner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2, 2) inverse rest bases and (M,) areas of the pattern triangles, as Newton builds
    them from a triangle's own 2D frame (``newton/_src/geometry/rest_shape.py``)."""
    p = np.concatenate([uv, np.zeros((len(uv), 1))], axis=1)[corner]  # (M, 3, 3)
    qp, rp = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    n = np.cross(qp, rp)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e1 = qp / np.linalg.norm(qp, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    frame = np.stack([e1, e2], axis=-1)  # (M, 3, 2)
    basis = np.swapaxes(frame, 1, 2) @ np.stack([qp, rp], axis=-1)  # (M, 2, 2)
    return np.linalg.inv(basis), np.linalg.det(basis) / 2.0


def _simulate(newton, wp, device: str, points: np.ndarray, faces: np.ndarray, *, collider_points: np.ndarray,
              collider_faces: np.ndarray, frames: int, gravity: float, cfg: SimConfig,
              springs: np.ndarray | None = None, seam_stiffness: float = 0.0, seam_damping: float = 0.0,
              rest: tuple[np.ndarray, np.ndarray, dict] | None = None, held: np.ndarray | None = None) -> np.ndarray:
    """Simulate a cloth on a static body for ``frames`` frames; (K, 3) its last positions.

    Args:
        rest: ``(inverse rest bases (M, 2, 2), areas (M,), {sorted vertex pair: length})`` to
            replace the rest metric Newton derives from ``points``; None keeps it.
        held: (K,) bool vertices that keep their place (zero mass: VBD leaves them still);
            only with ``rest``, which sets the masses.
    """
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -gravity, 0.0))
    builder.add_cloth_mesh(vertices=[wp.vec3(*p) for p in points.astype(np.float32)],
                           indices=faces.ravel().tolist(), density=cfg.density,
                           pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0,
                           vel=wp.vec3(0.0, 0.0, 0.0), tri_ke=cfg.stretch_stiffness, tri_ka=cfg.stretch_stiffness,
                           tri_kd=cfg.stretch_damping, edge_ke=cfg.bend_stiffness, edge_kd=cfg.bend_damping,
                           particle_radius=cfg.particle_radius, label="garment")
    if rest is not None:
        inv_d, areas, lengths = rest
        if len(builder.tri_poses) != len(inv_d):
            raise SimulationError(f"newton dropped {len(inv_d) - len(builder.tri_poses)} degenerate triangles "
                                  "of the draped garment")
        builder.tri_poses = inv_d.tolist()
        builder.tri_areas = areas.tolist()
        mass = np.zeros(len(points))
        for k in range(3):
            np.add.at(mass, faces[:, k], cfg.density * areas / 3.0)
        if held is not None:
            mass[held] = 0.0
        builder.particle_mass = mass.tolist()
        ends = np.sort(np.asarray(builder.edge_indices)[:, 2:4], axis=1)
        builder.edge_rest_length = [lengths.get((int(a), int(b)), float(np.linalg.norm(points[a] - points[b])))
                                    for a, b in ends]
        builder.edge_rest_angle = [0.0] * len(ends)
    if springs is not None and len(springs):
        for a, b in springs:
            builder.add_spring(int(a), int(b), seam_stiffness, seam_damping, 0.0)
        builder.spring_rest_length = [0.0] * len(springs)
    body_mesh = newton.Mesh(collider_points.astype(np.float32), collider_faces.ravel(), compute_inertia=False)
    shape_cfg = newton.ModelBuilder.ShapeConfig(
        ke=cfg.contact_stiffness, kd=cfg.contact_damping, mu=cfg.friction,
        margin=max(cfg.contact_margin - cfg.particle_radius, 0.0), gap=cfg.contact_gap,
        has_shape_collision=False, has_particle_collision=True)
    builder.add_shape_mesh(body=-1, mesh=body_mesh, cfg=shape_cfg, label="body")
    builder.color(include_bending=True)
    model = builder.finalize(device=device)
    model.soft_contact_ke = cfg.contact_stiffness
    model.soft_contact_kd = cfg.contact_damping
    model.soft_contact_mu = cfg.friction
    pipeline = newton.CollisionPipeline(model, soft_contact_gap=cfg.contact_gap)
    contacts = pipeline.contacts()
    solver = newton.solvers.SolverVBD(model, iterations=cfg.iterations, particle_enable_self_contact=False,
                                      particle_self_contact_margin=cfg.contact_margin,
                                      particle_self_contact_gap=cfg.contact_gap)
    states = [model.state(), model.state()]
    control = model.control()
    dt = 1.0 / (cfg.fps * cfg.substeps)
    for _ in range(frames):
        for _ in range(cfg.substeps):
            state_in, state_out = states
            pipeline.collide(state_in, contacts)
            state_in.clear_forces()
            solver.step(state_in, state_out, control, contacts, dt)
            states.reverse()
    q = states[0].particle_q.numpy()[: len(points)].astype(np.float64)
    if not np.all(np.isfinite(q)):
        raise SimulationError("the garment's simulation produced NaN positions")
    return q


def conform_placement(mesh: PatternMesh, body_vertices: np.ndarray, *, clearance: float = 0.02,
                      radius: float = 0.03, smoothing: int = 20) -> np.ndarray:
    """(N, 3) the placed pattern with its conforming panels' vertices moved along Z onto the
    body's front (or back) surface plus ``clearance``; where no body lies behind a vertex
    (beside a leg, between the legs) it goes to the body's mid-depth, so a front and a back
    panel's seams there start together.

    Args:
        body_vertices: (V, 3) the T-posed body [m].
    """
    from scipy.spatial import cKDTree

    placed = mesh.placed.copy()
    if mesh.conform is None or not np.any(mesh.conform):
        return placed
    side = mesh.conform.astype(np.float64)
    ids = np.flatnonzero(side != 0)
    tree = cKDTree(body_vertices[:, :2])
    mid = 0.5 * (float(body_vertices[:, 2].max()) + float(body_vertices[:, 2].min()))
    target = np.full(len(ids), mid)
    floor = np.full(len(ids), -np.inf)  # signed depth the vertex must stay outside of
    for k, near in enumerate(tree.query_ball_point(placed[ids, :2], r=radius)):
        if near:
            z = body_vertices[near, 2] * side[ids[k]]
            floor[k] = float(z.max()) + clearance
            target[k] = floor[k] * side[ids[k]]
    # Smooth the depth over the mesh (neighbours by edges), never into the body.
    e = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    z = placed[:, 2].copy()
    z[ids] = target
    count = np.bincount(e[:, 0], minlength=len(z)).astype(np.float64)
    for _ in range(smoothing):
        avg = np.bincount(e[:, 0], weights=z[e[:, 1]], minlength=len(z)) / np.maximum(count, 1)
        z[ids] = np.maximum(avg[ids] * side[ids], floor) * side[ids]
    placed[ids, 2] = z[ids]
    return placed


def push_out(points: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray, *,
             clearance: float = 0.006) -> np.ndarray:
    """(K, 3) points moved out of the body: a point behind (or nearer than ``clearance`` to)
    its closest body surface point goes to that point plus ``clearance`` along the surface
    normal. Merging a seam at the mean of its two sides can put a vertex inside the body
    (at the crotch, where four panels meet); the collider would then hold it inside.

    Args:
        body_vertices: (V, 3) the T-posed body [m]; body_faces: (F, 3) int.
    """
    from ..core.association import associate, surface_at

    closest, normal = surface_at(associate(points, body_vertices, body_faces), body_vertices,
                                 vertex_normals(body_vertices, body_faces), body_faces)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    depth = np.einsum("nc,nc->n", points - closest, normal)
    out = points.copy()
    inside = depth < clearance
    out[inside] = closest[inside] + clearance * normal[inside]
    return out


def lift_off_skin(points: np.ndarray, tri: np.ndarray, body_vertices: np.ndarray, body_faces: np.ndarray, *,
                  margin: float, rounds: int = 2, stretch: float = LIFT_STRETCH,
                  rest_lengths: np.ndarray | None = None) -> tuple[np.ndarray, tuple[int, int]]:
    """The garment (N, 3) at rest on the body at rest (``body_vertices`` (V, 3) [m], ``body_faces``) with its
    triangles (``tri``) lifted off the skin that lies in front of them, or less than ``margin`` [m] behind,
    between their corners: the body's vertices and the midpoints of its edges that the garment covers
    (:class:`~cloth_usd.core.postprocess.TriangleLift`, ``rounds`` times; no edge stretched past ``stretch``
    times its ``rest_lengths``, by default its length before, further than it was). The push out of the body
    and the drape on a decimated body hold the vertices off it, and a garment coarser than the body lets the
    body's bumps through between them: MakeHuman's sports top, 911 vertices, fitted, had 21 body vertices more
    than 1 mm in front of its triangles (the count returned here) at the chest and the collars, every tier then
    showing skin there.

    Returns:
        ``(points (N, 3), (before, after))``: the lifted garment and how many covered body vertices lie more
        than :data:`~cloth_usd.core.postprocess.THROUGH_DEPTH` in front of its triangles before and after.
    """
    normals = vertex_normals(body_vertices, body_faces)
    lift = TriangleLift(tri, points, body_vertices, normals, body_faces=body_faces, margin=margin, stretch=stretch,
                        rest_lengths=rest_lengths)
    frame, every = (body_vertices[None], normals[None]), np.arange(len(body_vertices))
    lifted = np.asarray(points, dtype=np.float64)[None]
    before = int(lift.bared(lifted, *frame, every)[0][0])
    for _ in range(rounds):
        lifted, moved = lift(lifted, *frame, body_faces, every)
        if not moved[0]:
            break
    return lifted[0], (before, int(lift.bared(lifted, *frame, every)[0][0]))


def quiet_warp() -> None:
    """No banner or module-load lines from warp on a command's stdout (read when newton
    initialises warp): ``config.quiet`` in older warp, ``config.log_level`` in newer (1.19
    ignores ``quiet``)."""
    try:
        import warp
    except ImportError:
        return  # _import_engine says what to install
    warp.config.quiet = True
    if hasattr(warp.config, "log_level") and hasattr(warp, "LOG_WARNING"):
        warp.config.log_level = warp.LOG_WARNING


def sew(body: BodyModel, betas: np.ndarray, mesh: PatternMesh, config: SewConfig = SewConfig()) -> SewnGarment:
    """Stitch a placed pattern round the T-posed body, merge its seams and drape it.

    Args:
        betas: (B',) the body's shape coefficients.
        mesh: the triangulated, placed pattern (:func:`~cloth_usd.garments.pattern.triangulate_pattern`).
    Raises:
        SimulationError: Newton is missing or the simulation failed.
    """
    quiet_warp()
    newton, wp = _import_engine()
    began = time.perf_counter()
    cfg = config.sim
    device = resolve_device(cfg.device)
    v_rest, _ = shape_body(body, np.asarray(betas, dtype=np.float64))
    collider = make_collider(body, betas, cfg.collider_faces)
    col_points = collider.pose(np.asarray(v_rest)[None], body.faces)[0]
    common = dict(collider_points=col_points, collider_faces=collider.faces, cfg=cfg)
    placed, flat_rest = mesh.placed, None
    if mesh.conform is not None and np.any(mesh.conform):
        placed = conform_placement(mesh, np.asarray(v_rest))
        inv_d0, areas0 = _rest_frames(mesh.uv, mesh.faces)
        e0, l0 = pattern_edge_lengths(mesh.uv, mesh.faces, mesh.faces)
        flat_rest = (inv_d0, areas0, {(int(a), int(b)): float(n) for (a, b), n in zip(e0, l0)})
    stitched = _simulate(newton, wp, device, placed, mesh.faces, frames=config.stitch_frames, gravity=0.0,
                         springs=mesh.seams, seam_stiffness=config.seam_stiffness,
                         seam_damping=config.seam_damping, rest=flat_rest, **common)
    gap = float(np.max(np.linalg.norm(stitched[mesh.seams[:, 0]] - stitched[mesh.seams[:, 1]], axis=1))) \
        if len(mesh.seams) else 0.0
    log.info("stitched in %.1f s; largest seam gap %.1f mm", time.perf_counter() - began, gap * 1e3)
    vertex_of = merge_seams(len(mesh.placed), mesh.seams)
    count = int(vertex_of.max()) + 1
    merged = np.zeros((count, 3))
    np.add.at(merged, vertex_of, stitched)
    merged /= np.bincount(vertex_of, minlength=count)[:, None]
    merged = push_out(merged, np.asarray(v_rest, dtype=np.float64), body.faces)
    faces = vertex_of[mesh.faces]
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces, corner = faces[ok], mesh.faces[ok]
    inv_d, areas = _rest_frames(mesh.uv, corner)
    edges, lengths = pattern_edge_lengths(mesh.uv, faces, corner)
    rest = (inv_d, areas, {(int(a), int(b)): float(n) for (a, b), n in zip(edges, lengths)})
    held = None
    if mesh.held:  # a waistband, held where it was sewn while the rest hangs from it
        unknown = sorted(set(mesh.held) - set(mesh.panel_names))
        if unknown:
            raise ArgumentError(f"pattern: held panels {unknown} are not among its panels "
                                f"({', '.join(mesh.panel_names)})")
        held = np.zeros(count, bool)
        held[vertex_of[np.isin(np.asarray(mesh.panel_names)[mesh.panel], mesh.held)]] = True
    converged = dict(common, cfg=dataclasses.replace(cfg, iterations=config.settle_iterations))
    if config.relax_frames:
        merged = _simulate(newton, wp, device, merged, faces, frames=config.relax_frames, gravity=0.0, rest=rest,
                           **converged)
    draped = _simulate(newton, wp, device, merged, faces, frames=config.drape_frames, gravity=cfg.gravity,
                       rest=rest, held=held, **common)
    if config.settle_frames:
        draped = _simulate(newton, wp, device, draped, faces, frames=config.settle_frames, gravity=cfg.gravity,
                           rest=rest, held=held, **converged)
    through = None
    if config.lift_rounds > 0:  # the full body's bumps between the vertices (the collider is the body decimated)
        draped, through = lift_off_skin(draped, faces, np.asarray(v_rest, dtype=np.float64), body.faces,
                                        margin=config.lift_margin, rounds=config.lift_rounds,
                                        stretch=config.lift_stretch, rest_lengths=lengths)  # edges: mesh_edges(faces)
    stretch = np.linalg.norm(draped[edges[:, 0]] - draped[edges[:, 1]], axis=1) / np.maximum(lengths, 1e-12)
    seconds = time.perf_counter() - began
    log.info("sewn and draped in %.1f s: %d vertices, edge stretch p99 %.3f", seconds, count,
             float(np.percentile(stretch, 99)))
    return SewnGarment(points=draped, faces=faces, corner_vertex=corner, vertex_of=vertex_of, stretch=stretch,
                       stitched_gap=gap, seconds=seconds, skin_through=through)


def with_sim(config: SewConfig, **changes) -> SewConfig:
    """``config`` with some of its SimConfig fields changed."""
    return dataclasses.replace(config, sim=dataclasses.replace(config.sim, **changes))
