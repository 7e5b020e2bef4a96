"""One garment from its category, cut and body: measure, draft, triangulate, sew, drape,
and lay the panels out as UVs. Shape letters: K garment vertices, M triangles, N pattern
vertices, P panels."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..core.body import BodyModel, shape_body
from ..errors import ArgumentError
from .designs import design_from_params, draft
from .measure import BodyMeasurements, measure_body
from .pattern import Pattern, PatternMesh, triangulate_pattern
from .sew import SewConfig, SewnGarment, sew

__all__ = ["MadeGarment", "pattern_spacing", "pack_uvs", "make_garment"]

#: Default vertex count of a made garment (before seams merge).
DEFAULT_VERTICES = 3500


@dataclass(frozen=True)
class MadeGarment:
    """A garment made for a body: its worn rest shape, UVs and how well it was sewn."""

    category: str
    design: Any
    """The design dataclass it was cut from (:mod:`cloth_usd.garments.designs`)."""
    measurements: BodyMeasurements
    pattern: Pattern
    mesh: PatternMesh
    sewn: SewnGarment
    st: np.ndarray
    """(N, 2) float64 UVs in [0, 1] of the pattern vertices (panels packed, one scale)."""
    seconds: float

    @property
    def points(self) -> np.ndarray:
        """(K, 3) float64 the draped garment [m], canonical body frame."""
        return self.sewn.points

    @property
    def faces(self) -> np.ndarray:
        """(M, 3) int64 triangles."""
        return self.sewn.faces

    @property
    def st_indices(self) -> np.ndarray:
        """(M, 3) int64 UV index of each triangle corner."""
        return self.sewn.corner_vertex

    def report(self) -> dict:
        """JSON-able figures: sizes, stretch against the pattern, time."""
        s = self.sewn.stretch
        return {"category": self.category, "design": dataclasses.asdict(self.design),
                "panels": len(self.pattern.panels), "seams": len(self.pattern.seams),
                "pattern_vertices": int(len(self.mesh.uv)), "vertices": int(len(self.points)),
                "triangles": int(len(self.faces)), "spacing_m": round(self.mesh.spacing, 5),
                "stretch_p50": round(float(np.percentile(s, 50)), 4),
                "stretch_p99": round(float(np.percentile(s, 99)), 4), "stretch_max": round(float(s.max()), 4),
                "compression_p1": round(float(np.percentile(s, 1)), 4),
                "seam_gap_mm": round(self.sewn.stitched_gap * 1e3, 2), "seconds": round(self.seconds, 1),
                **({} if self.sewn.skin_through is None else
                   {"skin_through_before": self.sewn.skin_through[0], "skin_through": self.sewn.skin_through[1]})}


def _area(ring: np.ndarray) -> float:
    return 0.5 * abs(float(np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])))


def pattern_spacing(pattern: Pattern, target_vertices: int) -> float:
    """Edge length [m] that triangulates ``pattern`` into about ``target_vertices`` vertices."""
    if target_vertices < 50:
        raise ArgumentError(f"--vertices {target_vertices}: at least 50")
    area = sum(_area(np.concatenate([e[:-1] for _, e in p.edges])) for p in pattern.panels)
    return float(np.sqrt(area / (0.866 * target_vertices)) * 1.04)  # the outline's points add about 8%


def pack_uvs(mesh: PatternMesh, outward: np.ndarray, margin: float = 0.02) -> np.ndarray:
    """Panels laid side by side in the unit square at one scale (shelf packing, tallest first).

    Args:
        outward: (P,) +1 or -1 per panel: -1 mirrors it in u so it reads from outside.
    Returns:
        (N, 2) float64 UVs.
    """
    uv = mesh.uv * np.where(outward[mesh.panel] < 0, -1.0, 1.0)[:, None] * [1.0, 1.0]
    boxes = []
    for p in range(len(mesh.panel_names)):
        pts = uv[mesh.panel == p]
        boxes.append((pts.min(0), pts.max(0)))
    sizes = np.array([hi - lo for lo, hi in boxes])
    gap = margin * float(np.sqrt((sizes[:, 0] * sizes[:, 1]).sum()))
    width = max(float(sizes[:, 0].max()), 1.3 * float(np.sqrt((sizes[:, 0] * sizes[:, 1]).sum())))
    order = np.argsort(-sizes[:, 1], kind="stable")
    x = y = row = 0.0
    offsets = np.zeros((len(boxes), 2))
    for p in order:
        if x > 0 and x + sizes[p, 0] > width:
            x, y, row = 0.0, y + row + gap, 0.0
        offsets[p] = (x, y)
        x += sizes[p, 0] + gap
        row = max(row, sizes[p, 1])
    out = uv - np.array([boxes[p][0] for p in mesh.panel]) + offsets[mesh.panel]
    extent = max(float(out[:, 0].max()), float(out[:, 1].max()))
    return gap / 2 / (extent + gap) + out / (extent + gap)


def make_garment(category: str, betas: np.ndarray, *, body: BodyModel, preset: str | None = None,
                 params: Mapping[str, str | float] | None = None, target_vertices: int = DEFAULT_VERTICES,
                 config: SewConfig = SewConfig()) -> MadeGarment:
    """Cut, sew and drape a garment for the body of ``betas``.

    Args:
        category: ``tshirt``, ``dress`` or ``trousers``.
        betas: (10,) shape coefficients.
        preset: a named cut (:data:`~cloth_usd.garments.designs.PRESETS`); params override it.
        target_vertices: about this many pattern vertices.
    """
    began = time.perf_counter()
    design = design_from_params(category, preset, params)
    measurements = measure_body(body, betas)
    pattern = draft(category, measurements, design)
    mesh = triangulate_pattern(pattern, pattern_spacing(pattern, target_vertices))
    sewn = sew(body, betas, mesh, config)
    outward = np.array([p.outward for p in pattern.panels])
    return MadeGarment(category=category, design=design, measurements=measurements, pattern=pattern, mesh=mesh,
                       sewn=sewn, st=pack_uvs(mesh, outward), seconds=time.perf_counter() - began)


def body_joints(body: BodyModel, betas: np.ndarray) -> np.ndarray:
    """(24, 3) rest joints [m] of the body of ``betas``."""
    return np.asarray(shape_body(body, np.asarray(betas, dtype=np.float64))[1])
