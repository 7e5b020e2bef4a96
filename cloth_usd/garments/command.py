"""``cloth-usd garment make``: the command's arguments and what it does (imported by
:mod:`cloth_usd.cli`, cheaply: the simulator is imported only when a garment is made)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Callable

__all__ = ["register", "run"]


def register(add_command: Callable[..., argparse.ArgumentParser]) -> None:
    """Add the ``garment`` command (``garment make``, ``garment presets``) to the CLI."""
    from .designs import DESIGNS

    g = add_command("garment", help="make a garment from a sewing pattern, sewn and draped on a body (Newton)")
    sub = g.add_subparsers(dest="garment_command", required=True, metavar="ACTION")
    mk = sub.add_parser("make", help="cut a T-shirt, dress or trousers for a body, sew and drape it, write a "
                                     "garment USD file (the T-posed character and the garment with UVs)")
    mk.add_argument("category", choices=list(DESIGNS), help="garment category")
    mk.add_argument("-o", "--output", required=True, help="garment file to write (.usda, .usdc, .usd)")
    mk.add_argument("--betas", type=float, nargs="+", default=[], metavar="B",
                    help="body shape coefficients (up to 10; default zeros)")
    mk.add_argument("--preset", help="a named cut (see `cloth-usd garment presets`)")
    mk.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="set one design parameter (repeatable; see `cloth-usd garment presets`)")
    mk.add_argument("--vertices", type=int, default=None,
                    help="target pattern vertex count (default 3500)")
    mk.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    mk.add_argument("--report", metavar="JSON", help="also write the measurements and figures as JSON")
    mk.add_argument("--force", action="store_true", help="replace an existing output file")
    sub.add_parser("presets", help="list the named cuts and every design parameter with its default")
    fit = sub.add_parser("fit", help="bring a garment modelled elsewhere (.obj, .glb, .usd) onto the body: "
                                     "units, up axis, alignment, unposed to the T-pose, pushed out, draped")
    fit.add_argument("mesh", help="garment mesh: .obj, .glb/.gltf, .usd/.usda/.usdc (a MakeHuman .obj uses "
                                  "the .mhclo beside it)")
    fit.add_argument("-o", "--output", required=True, help="garment file to write (.usda, .usdc, .usd)")
    fit.add_argument("--category", required=True, choices=list(DESIGNS), help="garment category")
    fit.add_argument("--betas", type=float, nargs="+", default=[], metavar="B",
                     help="body shape coefficients (up to 10; default zeros)")
    fit.add_argument("--mhclo", help="MakeHuman binding (default: MESH with the suffix .mhclo, if present)")
    fit.add_argument("--no-mhclo", action="store_true", help="ignore a MakeHuman binding: fit by shape")
    fit.add_argument("--prim", help="the Mesh prim to read from a USD file (default: the first Mesh)")
    fit.add_argument("--drape-frames", type=int, default=16,
                     help="frames (24 fps) hung under gravity on the body (default 16; 0: no drape)")
    fit.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    fit.add_argument("--report", metavar="JSON", help="also write how it was fitted as JSON")
    fit.add_argument("--force", action="store_true", help="replace an existing output file")


def _parse_params(items: list[str]) -> dict[str, str]:
    from ..errors import ArgumentError

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ArgumentError(f"--param {item}: expected NAME=VALUE")
        out[name.strip()] = value.strip()
    return out


def _presets() -> int:
    import dataclasses

    from .designs import DESIGNS, PRESETS

    for category, cls in DESIGNS.items():
        sys.stdout.write(f"{category}\n  parameters: " + ", ".join(
            f"{f.name}={f.default}" for f in dataclasses.fields(cls)) + "\n")
        for name, values in PRESETS[category].items():
            text = " ".join(f"{k}={v}" for k, v in values.items()) or "(defaults)"
            sys.stdout.write(f"  --preset {name:14s} {text}\n")
    return 0


def _betas(values: list[float]):
    import numpy as np

    from ..errors import ArgumentError

    if len(values) > 10 or not all(np.isfinite(values)):
        raise ArgumentError(f"--betas: at most 10 finite values, got {len(values)}")
    betas = np.zeros(10)
    betas[: len(values)] = values
    return betas


def _write(args: argparse.Namespace, body, betas, *, points, faces, st, st_indices, key: str, report: dict):
    """Write the garment file (the report under ``custom[key]``) and ``--report``; returns its path."""
    from ..usd.garment_file import write_garment_file
    from .make import body_joints

    path = write_garment_file(args.output, points=points, faces=faces, st=st, st_indices=st_indices,
                              category=args.category, betas=betas, joints=body_joints(body, betas),
                              custom={key: json.dumps(report)}, force=args.force)
    if args.report:
        with open(args.report, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)
    return path


def _fit(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from ..core.body import load_body_model
    from ..errors import ArgumentError
    from ..usd.write import check_output_path
    from .fit import FitConfig, fit_garment, mhclo_beside
    from .mhclo import read_mhclo
    from .source import read_garment_mesh

    betas = _betas(args.betas)
    if args.drape_frames < 0:
        raise ArgumentError(f"--drape-frames {args.drape_frames}: 0 or more")
    check_output_path(args.output, force=args.force)
    if args.prim:
        if Path(args.mesh).suffix.lower() not in (".usd", ".usda", ".usdc"):
            raise ArgumentError(f"--prim {args.prim}: only for a USD file, not {Path(args.mesh).name}")
        from ..usd.mesh_read import read_usd_mesh

        src = read_usd_mesh(args.mesh, args.prim)
    else:
        src = read_garment_mesh(args.mesh)
    binding = None if args.no_mhclo else (Path(args.mhclo) if args.mhclo else mhclo_beside(args.mesh))
    mhclo = read_mhclo(binding) if binding is not None else None
    body = load_body_model(args.body_model)
    fitted = fit_garment(src, args.category, betas, body=body, mhclo=mhclo,
                         config=FitConfig(drape_frames=args.drape_frames))
    report = {**fitted.report, "category": args.category, "betas": [float(b) for b in betas]}
    faces = np.split(fitted.face_indices, np.cumsum(fitted.face_counts)[:-1])
    path = _write(args, body, betas, points=fitted.points, faces=faces, st=fitted.uv, st_indices=fitted.uv_indices,
                  key="garment_fit", report=report)
    sys.stdout.write(f"wrote {path}: {args.category} fitted by {report['method']} "
                     f"({report['units_m']:g} m per unit, {report['up_axis']} up, "
                     f"{'turned %g deg, ' % report['turned_deg'] if report.get('turned_deg') else ''}"
                     f"arm pose {report['arm_pose']:g}), "
                     f"{report['vertices']} vertices, median {report['median_distance_mm']:.1f} mm from the body, "
                     f"{100 * report['inside_fraction']:.1f}% inside, "
                     f"{_through(report)}"
                     f"{'%d piece(s) undraped (they fell off the body), ' % report['pieces_undraped'] if report.get('pieces_undraped') else ''}"
                     f"{report['seconds']:.0f} s\n")
    return 0


def _through(report: dict) -> str:
    """The summary's words on the skin through the garment at rest, before and after its lift off it."""
    if "skin_through" not in report:
        return ""
    return (f"skin through it at {report['skin_through']} body vertices ({report['skin_through_before']} before "
            "the lift), ")


def run(args: argparse.Namespace) -> int:
    """Run ``cloth-usd garment ...``; returns the exit code."""
    if args.garment_command == "presets":
        return _presets()
    if args.garment_command == "fit":
        return _fit(args)
    from ..core.body import load_body_model
    from ..usd.write import check_output_path
    from .designs import design_from_params
    from .make import DEFAULT_VERTICES, make_garment

    betas = _betas(args.betas)
    params = _parse_params(args.param)
    design_from_params(args.category, args.preset, params)  # a bad parameter fails before any work
    check_output_path(args.output, force=args.force)
    body = load_body_model(args.body_model)
    made = make_garment(args.category, betas, body=body, preset=args.preset, params=params,
                        target_vertices=args.vertices or DEFAULT_VERTICES)
    report = {**made.report(), "preset": args.preset, "betas": [float(b) for b in betas],
              "measurements": made.measurements.to_json()}
    path = _write(args, body, betas, points=made.points, faces=made.faces, st=made.st, st_indices=made.st_indices,
                  key="garment", report=report)
    sys.stdout.write(f"wrote {path}: {args.category} {args.preset or ''} {report['vertices']} vertices, "
                     f"{report['panels']} panels, edge stretch vs pattern p99 {report['stretch_p99']:.3f} "
                     f"(max {report['stretch_max']:.3f}), {_through(report)}{report['seconds']:.0f} s\n")
    return 0
