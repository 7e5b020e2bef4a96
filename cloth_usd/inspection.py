"""What ``cloth-usd inspect`` reports about a stage: characters, garments, range, units, problems,
and garments that do not look worn by their body."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

from .core.body import BodyModel
from .core.joint_names import JointMap
from .core.scene import Scene
from .errors import BodyModelError

__all__ = ["InspectReport", "inspect_stage", "format_report"]


@dataclass(frozen=True)
class InspectReport:
    """A stage as cloth_usd sees it."""

    scene: Scene
    problems: tuple[str, ...] = field(default=())
    """One line each: contract violations found (the bake would refuse these prims)."""
    skipped: tuple[str, ...] = field(default=())
    """One line each: Skeletons no garment targets that are not SMPL skeletons, why and what to do."""
    warnings: tuple[str, ...] = field(default=())
    """One line each: garments that read but do not look worn by their body (implausible
    size, far from its bones, :func:`cloth_usd.core.plausibility.scale_notes`; inside its
    shaped body or far from its surface at rest, :func:`cloth_usd.core.plausibility.body_notes`,
    the lines the bake warns with)."""
    bundles: Mapping[str, str] = field(default_factory=dict)
    """By garment prim path: the model bundle its coarse and detail tiers would bake with
    (``NAME (its own)`` for a garment's own bundle, ``NAME`` for its category's, ``none`` when
    no bundle serves it: skinning only)."""


def inspect_stage(path: str | Path, *,
                  joint_map: JointMap | Mapping[str, str] | str | PathLike | None = None,
                  body_model: str | PathLike | None = None,
                  models: Sequence[str | PathLike] | None = None) -> InspectReport:
    """Read a stage leniently: every contract violation becomes a problem line.

    Args:
        joint_map: ``{their joint name: SMPL joint name}`` or a JSON / TOML file of it
            (see :func:`cloth_usd.usd.read.read_scene`).
        body_model: the SMPL-format body model a bake would use (a file or folder; None for
            the embedded one): each garment is measured against its character's body shaped by
            its betas, and a body model that cannot serve a character is a problem, as in a bake.
        models: the bake's ``--models`` folders (None: the shipped bundles), to name the bundle
            each garment's learned tiers would use; a bundle that does not verify is a problem.
    """
    from .usd.read import open_stage, read_scene

    problems: list[str] = []
    skipped: list[str] = []
    scene = read_scene(open_stage(path), problems=problems, skipped=skipped, joint_map=joint_map)
    warnings = _scale_warnings(scene) + _body_warnings(scene, body_model, problems)
    bundles = _bundles(scene, models, problems)
    return InspectReport(scene=scene, problems=tuple(problems), skipped=tuple(skipped), warnings=tuple(warnings),
                         bundles=bundles)


def _bundles(scene: Scene, models: Sequence[str | PathLike] | None, problems: list[str]) -> dict[str, str]:
    """By garment prim path: the bundle a learned tier would bake it with, as the baker looks
    it up (:func:`cloth_usd.runtime.bundle.find_bundle`)."""
    from .errors import BundleError
    from .runtime.bundle import find_bundle

    found = {}
    for g in scene.garments:
        try:
            bundle = find_bundle(g.category, models, worn=(len(g.rest_points), g.triangles))
        except BundleError as e:
            problems.append(f"{g.prim_path}: {e}")
            continue
        if bundle is None:
            found[g.prim_path] = "none"
        elif bundle.garment is None:
            found[g.prim_path] = bundle.name
        elif bundle.garment.serves(len(g.rest_points), g.triangles):
            found[g.prim_path] = f"{bundle.name} (its own)"
        else:  # a --models folder that is another garment's own bundle
            found[g.prim_path] = f"{bundle.name} (another garment's)"
            problems.append(f"{g.prim_path}: bundle '{bundle.name}' ({bundle.path}) serves another garment "
                            f"({bundle.garment.vertices} vertices); its learned tiers would refuse this one")
    return found


def _scale_warnings(scene: Scene) -> list[str]:
    """A line for each garment whose size or place does not fit its body."""
    from .core.plausibility import garment_scale, scale_notes

    characters = {c.prim_path: c for c in scene.characters}
    lines = []
    for g in scene.garments:
        char = characters.get(g.body_path)
        if char is None:
            continue
        for note in scale_notes(garment_scale(g.rest_points, char.rest_joints)):
            lines.append(f"{g.prim_path}: {note}")
    return lines


def _worn_bodies(scene: Scene, body_model: str | PathLike | None, problems: list[str]) -> dict[str, BodyModel]:
    """By character prim path: the body model a bake would shape for each character that wears
    a garment. A character whose body model does not load, or lacks the shape components its
    betas use, is left out and adds a problem, as it would stop a bake."""
    from .baking.plan import check_shape_components
    from .core.body import load_body_model

    wearers = {g.body_path for g in scene.garments}
    by_gender: dict[str, BodyModel | None] = {}  # None: it does not load (named once)
    worn = {}
    for char in scene.characters:
        if char.prim_path not in wearers:
            continue
        if char.gender not in by_gender:
            try:
                by_gender[char.gender] = load_body_model(body_model, gender=char.gender)
            except BodyModelError as e:
                by_gender[char.gender] = None
                problems.append(f"<{char.prim_path}>: {e}")
        body = by_gender[char.gender]
        if body is None:
            continue
        try:
            check_shape_components(char, body, scene.stage.identifier)
        except BodyModelError as e:
            problems.append(str(e))
            continue
        worn[char.prim_path] = body
    return worn


def _body_warnings(scene: Scene, body_model: str | PathLike | None, problems: list[str]) -> list[str]:
    """A line for each garment inside its shaped body or far from it at rest (problems: see
    :func:`_worn_bodies`)."""
    from .core.body import shape_body
    from .core.frames import worn_rest_points
    from .core.plausibility import body_notes
    from .core.skinning import bind_worn

    characters = {c.prim_path: c for c in scene.characters}
    bodies = _worn_bodies(scene, body_model, problems)
    lines = []
    for g in scene.garments:
        body = bodies.get(g.body_path)
        if body is None:
            continue
        char = characters[g.body_path]
        rest = worn_rest_points(char, g.rest_points, shape_body(body, char.betas)[1])
        binding = bind_worn(body, char.betas, rest, g.triangles, g.category)
        lines += [f"{g.prim_path}: {note}" for note in body_notes(binding, body, char.betas, char.prim_path)]
    return lines


def format_report(report: InspectReport) -> str:
    """Human-readable text of an :class:`InspectReport`."""
    s = report.scene.stage
    rng = ("unauthored" if s.start_time_code is None or s.end_time_code is None
           else f"{s.start_time_code:g}..{s.end_time_code:g}")
    mpu = f"{s.meters_per_unit:g}" + ("" if s.meters_per_unit_authored else " (unauthored: USD default)")
    lines = [
        f"stage       {s.identifier}",
        f"units       upAxis {s.up_axis}, metersPerUnit {mpu}",
        f"time        {rng} at {s.time_codes_per_second:g} time codes/s, {s.frames_per_second:g} fps",
        f"characters  {len(report.scene.characters)}",
    ]
    for c in report.scene.characters:
        betas = ", ".join(f"{b:.2f}" for b in c.betas[:4]) + ", ..."
        lines.append(f"  {c.prim_path}  gender {c.gender}  betas [{betas}]"
                     + ("" if c.betas_authored else "  (smpl:betas missing: zeros)"))
    lines.extend(f"  skipped {line}" for line in report.skipped)
    lines.append(f"garments    {len(report.scene.garments)}")
    for g in report.scene.garments:
        state = "enabled" if g.enabled else "disabled"
        tier = g.tier.value if g.tier else "default"
        models = f"  models {report.bundles[g.prim_path]}" if g.prim_path in report.bundles else ""
        lines.append(f"  {g.prim_path}  {g.category.value}  body {g.body_path}  tier {tier}  {state}  "
                     f"{g.rest_points.shape[0]} vertices, {g.triangles.shape[0]} triangles{models}")
    lines.append(f"warnings    {len(report.warnings)}")
    lines.extend(f"  {w}" for w in report.warnings)
    lines.append(f"problems    {len(report.problems)}")
    lines.extend(f"  {p}" for p in report.problems)
    return "\n".join(lines)
