"""Parametric sewing patterns for a T-shirt, a dress and trousers, drafted from a body's
measurements (:mod:`cloth_usd.garments.measure`).

Every panel is drawn in the body's own front view (u = X, v = Y of the canonical T-posed
body, metres) and placed flat in a plane in front of or behind the body, which is how
GarmentCode places its panels too. A panel is cut to the girth it must wrap plus ease,
not to the body's silhouette: a front panel is wider than the body seen from the front,
and the seams pull it round the sides.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..errors import ArgumentError
from .measure import BodyMeasurements
from .pattern import Panel, Pattern, Seam, arc, bezier, line

__all__ = ["TShirtDesign", "DressDesign", "TrousersDesign", "DESIGNS", "PRESETS", "design_from_params",
           "draft"]

_FRONT_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
#: Gap [m] between the body and a placed panel.
_CLEARANCE = 0.035
#: The least ease [m] of a trouser leg's girth over the calf.
_CALF_EASE = 0.04
#: Extra half width [m] of a back trouser panel at the hips and thigh, for the seat.
_SEAT = 0.02
#: How far the shoulder line of a front or back panel is raised above the body's shoulder [m].
_SHOULDER_LIFT = 0.045


@dataclass(frozen=True)
class TShirtDesign:
    """Cut of a T-shirt (lengths in metres)."""

    length: float = 0.08
    """Hem below the waist joint (spine1); negative is above it (a crop top)."""
    sleeve_length: float = 0.20
    """Sleeve length from the shoulder point along the arm; 0 is sleeveless."""
    ease: float = 0.10
    """Chest girth ease: how much larger than the chest the shirt is round."""
    sleeve_ease: float = 0.07
    """Arm girth ease of the sleeve."""
    flare: float = 0.03
    """Extra half width of the front and back panels at the hem."""
    neck_width: float = 0.09
    """Half width of the neckline."""
    neck_drop: float = 0.07
    """Depth of the front neckline below the shoulder line."""
    neck_shape: str = "round"
    """``round`` or ``v``."""
    back_neck_drop: float = 0.02


@dataclass(frozen=True)
class DressDesign:
    """Cut of a dress: a bodice and a flared skirt sewn at the waist (lengths in metres)."""

    skirt_length: float = 0.55
    """Skirt length from the waist, at the centre front."""
    flare: float = 0.25
    """Extra half width of a skirt panel at the hem (0: a straight skirt)."""
    sleeve_length: float = 0.0
    """0: sleeveless."""
    ease: float = 0.08
    waist_ease: float = 0.10
    sleeve_ease: float = 0.07
    neck_width: float = 0.09
    neck_drop: float = 0.10
    neck_shape: str = "round"
    back_neck_drop: float = 0.03


@dataclass(frozen=True)
class TrousersDesign:
    """Cut of trousers: four leg panels and a waistband (lengths in metres)."""

    length: float = 1.0
    """Leg length as a fraction of the way from the crotch to the ankle (1: full length, 0.35: shorts)."""
    hip_ease: float = 0.08
    waist_ease: float = 0.05
    thigh_ease: float = 0.08
    hem_ease: float = 0.10
    """Girth ease at the hem (larger: wider, bootcut; smaller: slim)."""
    rise: float = 0.0
    """Waistline above (+) or below (-) the natural waist (the torso's narrowest girth)."""
    crotch_drop: float = 0.14
    """How far below the body's crotch the seam is cut."""
    waistband: float = 0.04
    """Waistband height; 0: none."""


DESIGNS = {"tshirt": TShirtDesign, "dress": DressDesign, "trousers": TrousersDesign}

#: Named cuts per category; ``cloth-usd garment make CATEGORY --preset NAME``.
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "tshirt": {
        "classic": {},
        "fitted": {"ease": 0.05, "flare": 0.0, "sleeve_ease": 0.05},
        "loose": {"ease": 0.22, "flare": 0.06, "sleeve_ease": 0.12},
        "long-sleeve": {"sleeve_length": 0.44},
        "three-quarter": {"sleeve_length": 0.32, "neck_shape": "v", "neck_drop": 0.12},
        "tank": {"sleeve_length": 0.0, "neck_drop": 0.12, "neck_width": 0.10},
        "crop": {"length": -0.08, "ease": 0.12},
        "tunic": {"length": 0.24, "flare": 0.08, "sleeve_length": 0.14},
        "v-neck": {"neck_shape": "v", "neck_drop": 0.14, "sleeve_length": 0.16},
    },
    "dress": {
        "a-line": {},
        "sheath": {"flare": 0.06, "skirt_length": 0.50, "waist_ease": 0.06},
        "flared": {"flare": 0.45, "skirt_length": 0.50},
        "maxi": {"skirt_length": 0.85, "flare": 0.30},
        "mini": {"skirt_length": 0.32, "flare": 0.18},
        "t-shirt-dress": {"sleeve_length": 0.18, "flare": 0.12, "neck_drop": 0.07, "skirt_length": 0.48},
    },
    "trousers": {
        "straight": {},
        "slim": {"hem_ease": 0.03, "thigh_ease": 0.05, "hip_ease": 0.06},
        "wide": {"hem_ease": 0.30, "thigh_ease": 0.14},
        "shorts": {"length": 0.35, "hem_ease": 0.12},
        "capri": {"length": 0.75, "hem_ease": 0.06},
        "low-rise": {"rise": -0.08, "waistband": 0.03, "hem_ease": 0.08},
    },
}


def design_from_params(category: str, preset: str | None = None,
                       params: Mapping[str, str | float] | None = None):
    """A design dataclass from a preset and ``NAME=VALUE`` overrides (values parsed as numbers
    where the field is a number). ArgumentError names an unknown category, preset or field."""
    if category not in DESIGNS:
        raise ArgumentError(f"unknown garment category '{category}' (valid: {', '.join(DESIGNS)})")
    cls = DESIGNS[category]
    values: dict[str, Any] = {}
    if preset is not None:
        if preset not in PRESETS[category]:
            raise ArgumentError(f"--preset {preset}: no such {category} (valid: {', '.join(PRESETS[category])})")
        values.update(PRESETS[category][preset])
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name, value in (params or {}).items():
        key = name.replace("-", "_")
        if key not in fields:
            raise ArgumentError(f"--param {name}: not a {category} parameter (valid: {', '.join(fields)})")
        if isinstance(fields[key].default, str):
            values[key] = str(value)
        else:
            try:
                values[key] = float(value)
            except ValueError:
                raise ArgumentError(f"--param {name}={value}: not a number") from None
    design = cls(**values)
    if getattr(design, "neck_shape", "round") not in ("round", "v"):
        raise ArgumentError(f"--param neck_shape={design.neck_shape}: valid: round, v")
    return design


def _panel(name: str, edges, z: float, front: bool, conform: bool = False) -> Panel:
    return Panel(name=name, edges=tuple((n, np.asarray(e, dtype=np.float64)) for n, e in edges),
                 origin=np.array([0.0, 0.0, z]), axes=_FRONT_AXES, outward=1.0 if front else -1.0, conform=conform)


def _mirror(edge: np.ndarray) -> np.ndarray:
    """An edge of the +X half mirrored to the -X half, reversed (outline order)."""
    return (edge * [-1.0, 1.0])[::-1]


def _torso_outline(m: BodyMeasurements, *, hem_y: float, hem_half: float, chest_half: float,
                   waist_half: float | None, neck_width: float, neck_drop: float, neck_shape: str,
                   sleeves: bool) -> tuple[list, tuple]:
    """The edges of a front or back torso panel, counter-clockwise from the hem's middle.

    Returns:
        ``(edges, (shoulder point, underarm point))`` of the +X side.
    """
    # A flat panel in front of the body must also reach over the shoulder to its top: the
    # shoulder line is raised by about half the shoulder's depth.
    top = m.shoulder_y + _SHOULDER_LIFT + 0.03  # the neck is deeper than the shoulder's end
    neck_side = np.array([neck_width, top])
    shoulder = np.array([m.shoulder_x + 0.015, m.shoulder_y + _SHOULDER_LIFT - 0.015])
    under = np.array([chest_half, m.armpit_y - (0.08 if sleeves else 0.09)])
    centre = np.array([0.0, top - neck_drop])
    if neck_shape == "v":
        neck = line(centre, neck_side)
    else:
        a = np.linspace(0.0, np.pi / 2, 20)
        neck = np.stack([neck_width * np.sin(a), top - neck_drop * np.cos(a)], axis=1)
    mid_x = shoulder[0] - 0.01
    armhole = bezier(under, [mid_x + 0.01, under[1] + 0.01], [mid_x, shoulder[1] - 0.06], shoulder)
    if waist_half is None:
        side = line([hem_half, hem_y], under)
    else:
        side = bezier([hem_half, hem_y], [waist_half, hem_y + 0.5 * (under[1] - hem_y)], under, samples=16)
    hem_r = line([0.0, hem_y], [hem_half, hem_y])
    shoulder_edge = line(shoulder, neck_side)
    neck_r = neck[::-1]  # from the neck side point to the centre
    edges = [("hem_l", hem_r), ("side_l", side), ("armhole_l", armhole), ("shoulder_l", shoulder_edge),
             ("neck_l", neck_r), ("neck_r", _mirror(neck_r)), ("shoulder_r", _mirror(shoulder_edge)),
             ("armhole_r", _mirror(armhole)), ("side_r", _mirror(side)), ("hem_r", _mirror(hem_r))]
    return edges, (shoulder, under)


def _sleeves(m: BodyMeasurements, shoulder: np.ndarray, under: np.ndarray, length: float, ease: float,
             z_front: float, z_back: float) -> tuple[list[Panel], list[Seam]]:
    """Front and back halves of both sleeves, sewn to the torso's armholes."""
    cuff_x = shoulder[0] + length
    t = np.clip((cuff_x - m.shoulder_x) / max(m.wrist_x - m.shoulder_x, 1e-6), 0.0, 1.0)
    girth = (1 - t) * m.upper_arm_girth + t * m.wrist_girth + ease
    half = 0.5 * girth
    cuff_top, cuff_bottom = m.arm_y + 0.5 * half + 0.01, m.arm_y - 0.5 * half + 0.01
    mid_x = shoulder[0] - 0.01
    cap = bezier(shoulder, [mid_x, shoulder[1] - 0.06], [mid_x + 0.01, under[1] + 0.01], under)
    edges = [("cap", cap), ("under", line(under, [cuff_x, cuff_bottom])),
             ("cuff", line([cuff_x, cuff_bottom], [cuff_x, cuff_top])), ("top", line([cuff_x, cuff_top], shoulder))]
    panels, seams = [], []
    for side, sign in (("l", 1.0), ("r", -1.0)):
        for part, z, front in (("front", z_front, True), ("back", z_back, False)):
            e = [(n, edge * [sign, 1.0]) for n, edge in edges]
            if sign < 0:  # mirrored: reverse the outline to keep it counter-clockwise
                e = [(n, edge[::-1]) for n, edge in reversed(e)]
            panels.append(_panel(f"sleeve_{part}_{side}", e, z, front))
        seams += [Seam((f"sleeve_front_{side}", "top"), (f"sleeve_back_{side}", "top")),
                  Seam((f"sleeve_front_{side}", "under"), (f"sleeve_back_{side}", "under")),
                  Seam((f"sleeve_front_{side}", "cap"), ("front", f"armhole_{side}")),
                  Seam((f"sleeve_back_{side}", "cap"), ("back", f"armhole_{side}"))]
    return panels, seams


def _planes(m: BodyMeasurements) -> tuple[float, float]:
    return max(m.front_z, m.seat_front_z) + _CLEARANCE, min(m.back_z, m.seat_back_z) - _CLEARANCE


def _arm_planes(m: BodyMeasurements) -> tuple[float, float]:
    r = m.upper_arm_girth / (2 * np.pi)
    return r + _CLEARANCE, -r - _CLEARANCE


def _top(m: BodyMeasurements, *, name_suffix: str, hem_y: float, hem_half: float, chest_half: float,
         waist_half: float | None, design, sleeve_length: float) -> tuple[list[Panel], list[Seam]]:
    z_front, z_back = _planes(m)
    sleeves = sleeve_length > 0.0
    panels, shoulder, under = [], None, None
    for part, drop, z, front in (("front", design.neck_drop, z_front, True),
                                 ("back", design.back_neck_drop, z_back, False)):
        edges, (shoulder, under) = _torso_outline(
            m, hem_y=hem_y, hem_half=hem_half, chest_half=chest_half, waist_half=waist_half,
            neck_width=design.neck_width, neck_drop=drop, neck_shape=design.neck_shape if front else "round",
            sleeves=sleeves)
        if name_suffix:
            edges = [("hem", np.concatenate([edges[-1][1], edges[0][1][1:]]))] + edges[1:-1]
        panels.append(_panel(part, edges, z, front))
    seams = [Seam(("front", f"{e}_{s}"), ("back", f"{e}_{s}")) for e in ("side", "shoulder") for s in "lr"]
    if sleeves:
        arm_front, arm_back = _arm_planes(m)
        sp, ss = _sleeves(m, shoulder, under, sleeve_length, design.sleeve_ease, arm_front, arm_back)
        panels += sp
        seams += ss
    return panels, seams


def _tshirt(m: BodyMeasurements, d: TShirtDesign) -> Pattern:
    hem_y = m.waist_y - d.length
    chest_half = (m.chest_girth + d.ease) / 4.0
    hip_half = (m.hip_girth + d.ease) / 4.0 if hem_y < m.hip_y + 0.05 else 0.0
    hem_half = max(chest_half, hip_half) + d.flare
    panels, seams = _top(m, name_suffix="", hem_y=hem_y, hem_half=hem_half, chest_half=chest_half,
                         waist_half=None, design=d, sleeve_length=d.sleeve_length)
    return Pattern("tshirt", tuple(panels), tuple(seams))


def _skirt_panel(name: str, waist_y: float, waist_half: float, hip_half: float, length: float, flare: float,
                 z: float, front: bool) -> Panel:
    """A skirt panel: a sector of an annulus (a flared skirt) or a trapezoid (a straight one)."""
    hem_half = max(waist_half, hip_half) + flare
    if hem_half - waist_half < 0.02:
        edges = [("hem", line([-hem_half, waist_y - length], [hem_half, waist_y - length])),
                 ("side_l", line([hem_half, waist_y - length], [waist_half, waist_y])),
                 ("waist", line([waist_half, waist_y], [-waist_half, waist_y])),
                 ("side_r", line([-waist_half, waist_y], [-hem_half, waist_y - length]))]
        return _panel(name, edges, z, front)
    # Sector: waist arc length 2 waist_half at radius r1, hem arc 2 hem_half at r1 + length.
    phi = 2.0 * (hem_half - waist_half) / length
    r1 = 2.0 * waist_half / phi
    centre = np.array([0.0, waist_y + r1])
    down = -np.pi / 2
    hem = arc(centre, r1 + length, down - phi / 2, down + phi / 2, samples=48)
    waist = arc(centre, r1, down + phi / 2, down - phi / 2, samples=32)
    edges = [("hem", hem), ("side_l", line(hem[-1], waist[0])), ("waist", waist),
             ("side_r", line(waist[-1], hem[0]))]
    return _panel(name, edges, z, front)


def _dress(m: BodyMeasurements, d: DressDesign) -> Pattern:
    waist_y = m.waist_y
    chest_half = (m.chest_girth + d.ease) / 4.0
    waist_half = (m.waist_girth + d.waist_ease) / 4.0
    panels, seams = _top(m, name_suffix="bodice", hem_y=waist_y, hem_half=waist_half, chest_half=chest_half,
                         waist_half=None, design=d, sleeve_length=d.sleeve_length)
    hip_half = (m.hip_girth + d.waist_ease) / 4.0
    z_front, z_back = _planes(m)
    for part, z, front in (("skirt_front", z_front, True), ("skirt_back", z_back, False)):
        panels.append(_skirt_panel(part, waist_y, waist_half, hip_half, d.skirt_length, d.flare, z, front))
    seams += [Seam(("skirt_front", "side_l"), ("skirt_back", "side_l")),
              Seam(("skirt_front", "side_r"), ("skirt_back", "side_r")),
              Seam(("front", "hem"), ("skirt_front", "waist")), Seam(("back", "hem"), ("skirt_back", "waist"))]
    return Pattern("dress", tuple(panels), tuple(seams))


def _trousers(m: BodyMeasurements, d: TrousersDesign) -> Pattern:
    top_y = m.natural_waist_y + d.rise
    crotch = m.crotch_y - d.crotch_drop
    hem_y = crotch + d.length * (m.ankle_y + 0.02 - crotch)
    leg_x = 0.5 * (0.144 + 0.186) * (m.hip_girth / 1.0083)  # the legs' axis, scaled with the hips
    t_hem = np.clip((crotch - hem_y) / max(crotch - m.ankle_y, 1e-6), 0.0, 1.0)
    knee_t = np.clip((crotch - m.knee_y) / max(crotch - m.ankle_y, 1e-6), 0.0, 1.0)
    hem_girth = (np.interp(t_hem, [0.0, knee_t, 1.0], [m.thigh_girth, m.knee_girth, m.ankle_girth]) + d.hem_ease)
    hip_half = (m.hip_girth + d.hip_ease) / 4.0
    # The top is cut to the waist (less the hips: a low rise) with little ease: the hips below
    # it are wider, and hold the trousers up.
    top_girth = np.interp(top_y, [m.hip_y, m.natural_waist_y], [m.hip_girth, m.natural_waist_girth])
    top_half = (top_girth + d.waist_ease) / 4.0
    thigh_half = (m.thigh_girth + d.thigh_ease) / 2.0
    hem_half = hem_girth / 2.0
    # Leg panel (front left, +X), counter-clockwise from the inner hem corner.
    gap = 0.004
    inner_hem = np.array([max(leg_x - hem_half / 2, gap + 0.01), hem_y])
    outer_hem = np.array([inner_hem[0] + hem_half, hem_y])
    crotch_pt = np.array([gap, crotch])

    # Below the knee the leg narrows to the hem, but not inside the calf: no panel narrower
    # there than half the leg's girth and the ease (the slim cut's calves stretched to 1.10x).
    calf_y = [m.ankle_y + 0.04, min(m.calf_y, m.knee_y - 1e-3), m.knee_y]
    calf_girth = [m.ankle_girth, m.calf_girth, m.knee_girth]

    def calf_short(outseam: np.ndarray) -> float:
        """How far [m] the outseam falls inside what the calf needs, at worst (<= 0: nowhere)."""
        y = outseam[:, 1]
        below_knee = (y <= m.knee_y) & (y > hem_y)
        if not below_knee.any():
            return 0.0
        ease = np.interp(y, [hem_y, max(m.calf_y, hem_y + 1e-3)], [min(d.hem_ease, _CALF_EASE), _CALF_EASE])
        need = inner_hem[0] + (np.interp(y, calf_y, calf_girth) + ease) / 2.0
        return float(np.max(need[below_knee] - outseam[below_knee, 0]))

    def leg(seat: float) -> list:
        """The leg panel's edges; ``seat``: extra half width [m] at the hips and thigh (a back
        panel covers the seat, which the front does not)."""
        outer_thigh = np.array([max(thigh_half + gap, hip_half) + seat, crotch])

        def outseam(lower_x: float) -> np.ndarray:
            return bezier(outer_hem, [lower_x, 0.5 * (hem_y + crotch)], outer_thigh,
                          [hip_half + seat, m.hip_y], [top_half, top_y])

        # the lower control point moves out until the calf has its girth: the curve stays smooth
        lower_x = outer_hem[0]
        for _ in range(40):
            if calf_short(outseam(lower_x)) <= 0.0:
                break
            lower_x += 0.005
        return [("hem", line(inner_hem, outer_hem)),
                ("outseam", outseam(lower_x)),
                ("top", line([top_half, top_y], [gap, top_y])),
                ("centre", line([gap, top_y], crotch_pt)),
                ("inseam", bezier(crotch_pt, [inner_hem[0], crotch - 0.1], inner_hem))]

    z_front, z_back = _planes(m)
    panels = []
    for part, z, front in (("front", z_front, True), ("back", z_back, False)):
        edges = leg(0.0 if front else _SEAT)
        panels.append(_panel(f"{part}_l", edges, z, front, conform=True))
        mirrored = [(n, _mirror(e)) for n, e in reversed(edges)]
        panels.append(_panel(f"{part}_r", mirrored, z, front, conform=True))
    seams = [Seam(("front_l", "centre"), ("front_r", "centre")), Seam(("back_l", "centre"), ("back_r", "centre"))]
    for s in "lr":
        seams += [Seam((f"front_{s}", "outseam"), (f"back_{s}", "outseam")),
                  Seam((f"front_{s}", "inseam"), (f"back_{s}", "inseam"))]
    if d.waistband > 0:
        h = d.waistband
        for part, z, front in (("front", z_front, True), ("back", z_back, False)):
            band = [("bottom_r", line([-top_half, top_y], [-gap, top_y])),
                    ("bottom_l", line([gap, top_y], [top_half, top_y])),
                    ("side_l", line([top_half, top_y], [top_half, top_y + h])),
                    ("top", line([top_half, top_y + h], [-top_half, top_y + h])),
                    ("side_r", line([-top_half, top_y + h], [-top_half, top_y]))]
            # The middle gap is one short bottom edge between the halves.
            band.insert(1, ("bottom_mid", line([-gap, top_y], [gap, top_y])))
            panels.append(_panel(f"band_{part}", band, z, front, conform=True))
            seams += [Seam((f"band_{part}", "bottom_l"), (f"{part}_l", "top")),
                      Seam((f"band_{part}", "bottom_r"), (f"{part}_r", "top"))]
        seams += [Seam(("band_front", "side_l"), ("band_back", "side_l")),
                  Seam(("band_front", "side_r"), ("band_back", "side_r"))]
    held = ("band_front", "band_back") if d.waistband > 0 else ()
    return Pattern("trousers", tuple(panels), tuple(seams), held=held)


def draft(category: str, m: BodyMeasurements, design) -> Pattern:
    """The pattern of ``design`` (a :data:`DESIGNS` dataclass) for a body's measurements."""
    return {"tshirt": _tshirt, "dress": _dress, "trousers": _trousers}[category](m, design)
