"""The ``cloth-usd`` command: ``inspect``, ``bake`` and ``doctor``."""

from __future__ import annotations

import argparse
import logging
import sys
import traceback
from typing import Sequence

from . import __version__
from .errors import ClothUsdError

__all__ = ["main"]

log = logging.getLogger("cloth_usd")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cloth-usd", description="Learned garment animation for USD shots.")
    p.add_argument("--version", action="version", version=f"cloth-usd {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging and tracebacks on error")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    i = sub.add_parser("inspect", help="list characters, garments, frame range, units and problems")
    i.add_argument("scene", help="USD stage to read")

    b = sub.add_parser("bake", help="write a garment point-cache layer")
    b.add_argument("scene", help="USD stage to read (never modified)")
    b.add_argument("-o", "--output", required=True, help="cache layer to write (.usdc, .usda)")
    b.add_argument("--shot", help="also write a shot layer that sublayers [cache, scene]")
    b.add_argument("--frames", help="START:END[:STEP], inclusive (default: the stage's range)")
    b.add_argument("--garment", action="append", metavar="PRIM", help="bake only this garment (repeatable)")
    b.add_argument("--tier", help="default tier for garments without cloth:tier: skinning, coarse, detail")
    b.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    b.add_argument("--models", metavar="DIR",
                   help="model bundle folder, or a folder of bundles, for the coarse and detail tiers "
                        "(default: the shipped models/bundles)")
    b.add_argument("--force", action="store_true", help="replace existing output files")
    b.add_argument("--no-progress", action="store_true", help="hide the progress bar")

    d = sub.add_parser("doctor", help="check the body model file(s) and the runtime")
    d.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    d.add_argument("--gender", default="neutral", help="file to pick inside a folder: neutral, female, male")
    g = sub.add_parser("datagen", help="simulate a ground-truth data set from a config (Newton)")
    g.add_argument("config", help="data set config (.json or .toml; see cloth_usd.datagen.factory)")
    g.add_argument("-o", "--output", required=True, help="folder for shards, manifest.json and fit.npz")
    g.add_argument("--workers", type=int, default=1, help="simulation processes (default 1)")

    r = sub.add_parser("render", help="draw body and garments at some frames to a PNG (a preview)")
    r.add_argument("scene", help="USD stage or shot layer to read")
    r.add_argument("-o", "--output", required=True, help="PNG to write")
    r.add_argument("--frames", required=True, help="comma-separated time codes, e.g. 1001,1030,1060")
    r.add_argument("--view", default="three-quarter", help="front, side or three-quarter")
    r.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    return p


def _render(args: argparse.Namespace) -> int:
    from .errors import ArgumentError
    from .render import render_frames

    try:
        frames = [float(f) for f in args.frames.split(",")]
    except ValueError:
        raise ArgumentError(f"--frames '{args.frames}': expected comma-separated time codes") from None
    out = render_frames(args.scene, frames, args.output, body_model=args.body_model, view=args.view)
    sys.stdout.write(f"wrote {out}\n")
    return 0


def _datagen(args: argparse.Namespace) -> int:
    from .datagen.factory import load_config, run_factory

    manifest = run_factory(load_config(args.config), args.output, workers=args.workers)
    sys.stdout.write(f"{len(manifest.accepted)} sequences simulated, {len(manifest.rejected)} rejected "
                     f"as unstable; manifest in {args.output}/manifest.json\n")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from .inspection import format_report, inspect_stage

    report = inspect_stage(args.scene)
    sys.stdout.write(format_report(report) + "\n")
    return 1 if report.problems else 0


def _bake(args: argparse.Namespace) -> int:
    from .baker import bake

    result = bake(args.scene, args.output, shot=args.shot, frames=args.frames, garments=args.garment,
                  tier=args.tier, force=args.force, body_model=args.body_model, models=args.models,
                  progress=not args.no_progress and sys.stderr.isatty())
    for g in result.garments:
        sys.stdout.write(f"{g.prim_path}: {g.frames} frames, {g.vertices} vertices, tier {g.tier.value}\n")
        if g.bundle is not None:
            sys.stdout.write(f"{g.prim_path}: bundle {g.bundle}, fit {' '.join(f'{a:.3f}' for a in g.fit)}, "
                             f"post-process moved {g.postprocess_moved} vertices "
                             f"({g.postprocess_moved / max(1, g.frames):.1f} per frame)\n")
    per_frame = result.seconds / max(1, result.times.shape[0]) * 1000.0
    sys.stdout.write(f"wrote {result.cache} ({result.times.shape[0]} frames, {result.seconds:.2f} s, "
                     f"{per_frame:.1f} ms/frame)\n")
    if result.shot:
        sys.stdout.write(f"wrote {result.shot} (open this to see the animated garments)\n")
    return 0


def _doctor(args: argparse.Namespace) -> int:
    from .doctor import run_checks

    def show(check) -> None:
        sys.stdout.write(f"{'ok  ' if check.ok else 'FAIL'}  {check.name}: {check.detail}\n")

    checks = run_checks(args.body_model, gender=args.gender, progress=show)
    return 0 if all(c.ok for c in checks) else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the process exit code."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="cloth-usd: %(levelname)s: %(message)s")
    try:
        commands = {"inspect": _inspect, "bake": _bake, "doctor": _doctor, "render": _render,
                    "datagen": _datagen}
        return commands[args.command](args)
    except ClothUsdError as exc:
        if args.verbose:
            sys.stderr.write(traceback.format_exc())
        sys.stderr.write(f"cloth-usd: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("cloth-usd: interrupted; no output was written\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
