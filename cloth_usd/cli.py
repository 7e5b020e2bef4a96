"""The ``cloth-usd`` command: ``inspect``, ``bake`` and ``doctor``."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import traceback
from typing import Sequence

from ._version import __version__
from .errors import ClothUsdError

__all__ = ["main"]

log = logging.getLogger("cloth_usd")

_JOINT_MAP_HELP = ("JSON object (or .toml table) {\"their joint name\": \"SMPL joint name\"} for skeletons "
                   "named in no known convention (smpl, smplx, smpl-fbx, meshcapade, phc)")


_VERBOSE_HELP = "debug logging and tracebacks on error"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cloth-usd", description="Learned garment animation for USD shots.")
    p.add_argument("--version", action="version", version=f"cloth-usd {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help=_VERBOSE_HELP)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # -v also after the command (`cloth-usd bake X -o Y -v`). SUPPRESS: a subcommand that is
    # not given -v sets nothing, so it never overwrites the top-level one's True.
    verbose = argparse.ArgumentParser(add_help=False)
    verbose.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help=_VERBOSE_HELP)

    def add_command(name: str, **kwargs) -> argparse.ArgumentParser:
        return sub.add_parser(name, parents=[verbose], **kwargs)

    i = add_command("inspect", help="list characters, garments, frame range, units and problems")
    i.add_argument("scene", help="USD stage to read")
    i.add_argument("--joint-map", metavar="FILE", help=_JOINT_MAP_HELP)
    i.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder the bake will use (default: embedded)")
    i.add_argument("--models", metavar="DIR",
                   help="the bake's model bundle folder, to name the bundle each garment's learned tiers would use "
                        "(default: the shipped models/bundles)")

    b = add_command("bake", help="write a garment point-cache layer")
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
    b.add_argument("--joint-map", metavar="FILE", help=_JOINT_MAP_HELP)
    b.add_argument("--force", action="store_true", help="replace existing output files")
    b.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    b.add_argument("--allow-any-size", action="store_true",
                   help="bake a garment more than 3 times its body's height (refused by default: "
                        "it is nearly always in the wrong units)")
    b.add_argument("--strict", action="store_true",
                   help="a learned frame that is not a garment (NaN, torn, far from the body) is an error "
                        "(exit 2, nothing written) instead of being replaced by the next safer tier")

    from .garments.command import register as register_garment

    register_garment(add_command)
    d = add_command("doctor", help="check the body model file(s) and the runtime")
    d.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    d.add_argument("--gender", default="neutral", help="file to pick inside a folder: neutral, female, male")
    g = add_command("datagen", help="simulate a ground-truth data set from a config (Newton)")
    g.add_argument("config", help="data set config (.json or .toml; see cloth_usd.datagen.factory)")
    g.add_argument("-o", "--output", required=True, help="folder for shards, manifest.json and fit.npz")
    g.add_argument("--workers", type=int, default=1, help="simulation processes (default 1)")
    g.add_argument("--batch", type=int, default=1, metavar="K",
                   help="simulate K sequences of equal length at once as one model, each in a world of its own "
                        "(on a GPU about the cost of one; default 1)")
    g.add_argument("--penetration-frames", type=int, metavar="N",
                   help="with --batch: measure each sequence's penetration at N evenly spread frames "
                        "(default every frame, about 0.1 s a frame on the CPU)")
    g.add_argument("--max-minutes", type=float, metavar="M",
                   help="start no simulation after M minutes (the one under way finishes); run the same command "
                        "again to simulate the rest")
    g.add_argument("--mocap", metavar="DIR", help="folder the config's BVH motions are relative to "
                                                 "(default: the config's mocap_dir, else $CLOTH_USD_MOCAP)")

    bt = add_command("batch", help="bake many jobs (a job file, stage list or globs) in workers or on Ray")
    bt.add_argument("jobs", nargs="+", metavar="JOBS",
                    help="JOBS.toml / JOBS.json (a list of jobs), STAGES.txt (one stage a line), stages or globs")
    bt.add_argument("--out-dir", help="folder for outputs a job does not name (default: beside each stage)")
    bt.add_argument("--frames", help="START:END[:STEP] for jobs that give none (default: each stage's range)")
    bt.add_argument("--garment", action="append", metavar="PRIM", help="garment for jobs that name none (repeatable)")
    bt.add_argument("--tier", help="tier for jobs that give none: skinning, coarse, detail")
    bt.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    bt.add_argument("--models", metavar="DIR", help="model bundle folder for jobs that give none")
    bt.add_argument("--joint-map", metavar="FILE", help="joint map for jobs that give none (see bake --joint-map)")
    bt.add_argument("--strict", action="store_true", default=None,
                    help="for jobs that do not say: a learned frame that is not a garment fails the job")
    bt.add_argument("--executor", default="local", choices=["local", "ray"],
                    help="local worker processes (default) or Ray (pip install 'cloth-usd[ray]')")
    bt.add_argument("--address", help="Ray cluster to join (default: start a local Ray)")
    bt.add_argument("--workers", type=int, help="parallel tasks (default: the CPU count)")
    bt.add_argument("--retries", type=int, default=2, help="re-runs of a task whose worker died (default 2)")
    bt.add_argument("--chunk-frames", type=int, metavar="N",
                    help="bake longer jobs in parallel chunks of N frames, stitched into one cache")
    bt.add_argument("--job-timeout", type=float, metavar="SECONDS", help="kill and retry a task running longer")
    bt.add_argument("--force", action="store_true", help="bake every job, even those up to date")
    bt.add_argument("--report", metavar="JSON", help="also write a machine-readable report")
    bt.add_argument("--dry-run", action="store_true",
                    help="list each job's `cloth-usd bake` command (for a farm scheduler); bake nothing")

    r = add_command("render", help="draw body and garments at some frames to a PNG (a preview)")
    r.add_argument("scene", help="USD stage or shot layer to read, or a data set shard (.npz)")
    r.add_argument("-o", "--output", required=True, help="PNG to write")
    r.add_argument("--frames", required=True,
                   help="START:END[:STEP] (inclusive, as for bake), or a comma list of time codes and ranges, "
                        "e.g. 1001:1096:24 or 1001,1030,1060 (frame indices for a shard)")
    r.add_argument("--view", default="three-quarter", help="front, side or three-quarter")
    r.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")

    tr = add_command("train", help="train the coarse or detail generator on a datagen data set, or the "
                                      "coarse one on the garment's physics")
    tr.add_argument("tier", choices=["coarse", "detail"], help="which generator")
    tr.add_argument("--data", required=True,
                    help="data set folder (cloth-usd datagen); with --objective physics or hybrid, a datagen config "
                         "file whose garments, bodies and motions are trained on without simulating them")
    tr.add_argument("--objective", choices=["supervised", "physics", "hybrid"],
                    help="supervised (simulated data), physics (the garment's energy, no simulation) or hybrid "
                         "(the energy plus the supervised term where --sim-data has simulated frames); "
                         "overrides the config's"),
    tr.add_argument("--sim-data", metavar="DIR",
                    help="hybrid: the cloth-usd datagen folder simulated from the --data config (the sequences "
                         "it holds add the supervised term, weighted by the config's supervised_weight)")
    tr.add_argument("-o", "--out", required=True, help="run folder: checkpoints, history.csv, curve.png")
    tr.add_argument("--config", help="training config (.json or .toml; see cloth_usd.nn.train.TrainConfig)")
    tr.add_argument("--coarse-run", help="detail: the trained coarse run folder (its predictions are M_coarse)")
    tr.add_argument("--device", default="auto", help="auto (default: cuda when available), cpu or cuda")
    tr.add_argument("--epochs", type=int, help="total epochs (overrides the config; also when resuming)")
    tr.add_argument("--resume", action="store_true", help="continue the run in --out after its last epoch")
    tr.add_argument("--init", metavar="RUN",
                    help="physics or hybrid: start from this trained run's best model (same tier and width; e.g. "
                         "one trained supervised where its simulated data stayed) instead of a fresh one; the "
                         "config's physics.anchor_weight keeps the result near it")
    tr.add_argument("--mocap", metavar="DIR", help="physics: the folder the data config's BVH motions are relative "
                                                  "to (default: the config's mocap_dir, else $CLOTH_USD_MOCAP)")
    tr.add_argument("--threads", type=int, help="torch CPU threads (default: torch's)")
    tr.add_argument("--body-model", help="SMPL-format .npz/.pkl the data was simulated with (default: embedded)")

    tg = add_command("train-garment", help="train and export a model bundle for a garment of your own (or several "
                                           "of one category), from the mesh alone (the physics objective; no "
                                           "simulation)")
    tg.add_argument("scene", nargs="+", help="USD stage(s), each with the garment (a cloth:category Mesh on an SMPL "
                                             "character); several train one bundle for their category")
    tg.add_argument("-o", "--out", required=True, help="bundle folder to write (bake with --models OUT; in a folder of "
                                                       "bundles it comes first for this garment)")
    tg.add_argument("--garment", metavar="PRIM", help="the garment prim (default: each stage's only garment)")
    tg.add_argument("--name", help="bundle name (default: the bundle folder's name)")
    tg.add_argument("--work", metavar="DIR", help="folder for the data config and the two runs (default: OUT.work)")
    tg.add_argument("--motions", metavar="JSON", help="the real training motions beside the seven procedural ones: "
                                                     "a JSON list of train_motions entries ({\"bvh\": ...} with "
                                                     "--mocap, procedural, or {\"stored\": ...}; see cloth-usd "
                                                     "datagen); [] for none (default: the 24 CMU stretches shipped "
                                                     "with cloth-usd)")
    tg.add_argument("--test-motions", metavar="JSON", help="the held-out motions of the Newton test set config the "
                                                          "work folder gets (testset.json: cloth-usd datagen of it "
                                                          "simulates them alone), entries as --motions (default: "
                                                          "three CMU stretches shipped with cloth-usd, 05_02, 01_01 "
                                                          "and 06_10, none trained on; not empty)")
    tg.add_argument("--mocap", metavar="DIR", help="the folder the --motions BVH clips are relative to")
    tg.add_argument("--form", choices=("garment", "paper"),
                    help="garment (the default for one garment): models of this garment alone (pose and shape to a "
                         "displacement of its vertices), the closest to cloth; paper (the default for several): the "
                         "paper's graph models (any topology; one bundle for several garments of a category)")
    tg.add_argument("--sim-data", metavar="DIR",
                    help="garment form: Newton's frames of some training sequences (cloth-usd datagen "
                         "WORK/hybrid.json -o DIR, after a first train-garment wrote the work folder): their batches "
                         "add the spring toward them (the hybrid objective)")
    tg.add_argument("--sim-weight", type=float, default=3.0e7,
                    help="garment form, with --sim-data: the spring toward Newton's frames [1/s^2] (default 3e7)")
    # nn.garment_model.SIM_TARGETS, written out: building the parser imports no torch
    tg.add_argument("--coarse-target", choices=("simulation", "taubin"), default="simulation",
                    help="garment form, with --sim-data: the coarse model learns Newton's frames (simulation, the "
                         "default) or them Taubin-smoothed (taubin: the paper's coarse tier, the wrinkles left to "
                         "the detail model)")
    tg.add_argument("--mirror", action="store_true",
                    help="garment form: train on every training sequence and its mirror image, left for right (a "
                         "symmetric garment only): twice the frames, Newton's included, from the same simulation")
    tg.add_argument("--sim-sequences", type=int, default=10, metavar="N",
                    help="garment form: the training sequences WORK/hybrid.json has cloth-usd datagen simulate "
                         "(default 10); a larger N keeps those a smaller one drew, so datagen into the same folder "
                         "simulates only the new ones")
    tg.add_argument("--steps", type=int, default=3000,
                    help="garment form: coarse model steps of 8 frames (default 3000)")
    tg.add_argument("--detail-steps", type=int, default=1500,
                    help="garment form: detail model steps of 8 frames (default 1500)")
    tg.add_argument("--coarse-epochs", type=int, default=8, help="paper form: coarse epochs (default 8)")
    tg.add_argument("--detail-epochs", type=int, default=3, help="paper form: detail epochs (default 3)")
    tg.add_argument("--batches", type=int, default=100, help="paper form: batches of 8 frames per coarse epoch "
                                                             "(default 100; the detail model takes 60%%)")
    tg.add_argument("--threads", type=int, help="torch CPU threads")
    tg.add_argument("--device", default="auto", help="torch device (default: CUDA when present)")
    tg.add_argument("--joint-map", metavar="FILE", help=_JOINT_MAP_HELP)
    tg.add_argument("--force", action="store_true", help="replace the bundle and the runs of an earlier call")

    ex = add_command("export", help="export trained runs to ONNX and write a verified model bundle")
    ex.add_argument("--coarse-run", required=True, help="trained coarse run folder (or a train-garment work "
                                                        "folder's coarse run, with --data its data.json)")
    ex.add_argument("--detail-run", help="trained detail run folder (optional)")
    ex.add_argument("--data", required=True, help="the data set the runs were trained on (fit.npz, manifest), or "
                                                  "the data set config of a physics-trained coarse run")
    ex.add_argument("-o", "--out", required=True, help="bundle folder to write")
    ex.add_argument("--name", required=True, help="bundle name, recorded in every cache it bakes")
    ex.add_argument("--category", help="garment category (default: a garment run's own garment's; tshirt for "
                                       "the paper's runs)")
    ex.add_argument("--metrics", help="metrics.json of cloth-usd evaluate, recorded in the manifest")
    ex.add_argument("--description", default="", help="one line about the training data")
    ex.add_argument("--body-model", help="SMPL-format .npz/.pkl the data was simulated with (default: embedded)")
    ex.add_argument("--parity-data", metavar="DIR",
                    help="check the ONNX files on this data set's sequences instead of --data's validation split "
                         "(for runs whose data set stayed where it was made: --data then needs only its manifest.json "
                         "and fit.npz)")
    ex.add_argument("--mocap", metavar="DIR", help="physics runs: the folder the data config's BVH motions are "
                                                  "relative to (default: $CLOTH_USD_MOCAP)")
    ex.add_argument("--force", action="store_true", help="write into a non-empty folder")

    ev = add_command("evaluate", help="per-vertex error of a bundle (and ablation runs) on the test splits")
    ev.add_argument("--data", required=True, help="data set folder (cloth-usd datagen)")
    ev.add_argument("--bundle", required=True, help="model bundle folder")
    ev.add_argument("--ablation-runs", nargs="+", default=[], metavar="RUN",
                    help="training runs evaluated with torch (detail runs on the bundle's coarse model)")
    ev.add_argument("-o", "--out", required=True, help="report folder: report.md, metrics.json, PNGs")
    ev.add_argument("--max-frames", type=int, help="only the first frames of every sequence")
    ev.add_argument("--rest", choices=("trained", "authored", "draped"), default="trained",
                    help="the rest garment the tiers read: trained (default: the learned tiers the one the bundle "
                         "was trained on, skinning the draped one), authored (every tier the garment before the "
                         "drape, as a bake of the authored garment reads it), draped (every tier the draped one)")
    ev.add_argument("--device", default="cpu", help="torch device of the ablation runs: cpu (default), cuda, auto")
    ev.add_argument("--body-model", help="SMPL-format .npz/.pkl the data was simulated with (default: embedded)")

    im = add_command("import-motion", help="a BVH or AMASS .npz motion as a new shot: an SMPL character "
                                           "wearing the given garments, ready to bake")
    im.add_argument("motion", metavar="FILE", help="BVH (CMU cgspeed MotionBuilder or Daz names, Mixamo, SMPL; "
                                                   "others with --joint-map) or AMASS-style .npz")
    im.add_argument("-o", "--output", required=True, help="shot stage to write (.usda, .usdc, .usd)")
    im.add_argument("--garment", action="append", default=[], metavar="GARMENT.usda",
                    help="USD file whose garment Mesh (cloth:category) is referenced and bound to the "
                         "character (repeatable)")
    im.add_argument("--betas", help="B0,B1,... body shape (default: the AMASS file's, else the garments' "
                                    "skeleton's, else the mean shape)")
    im.add_argument("--gender", choices=["neutral", "female", "male"],
                    help="smpl:gender (default: the AMASS file's, else neutral)")
    im.add_argument("--fps", type=float, help="frame rate of the shot (default 30; the motion is resampled)")
    im.add_argument("--frames", metavar="A:B", help="the file's frames A..B, 0-based, inclusive (default: all; "
                                                    "for CMU cgspeed files, all but their T-pose frame 0)")
    im.add_argument("--start", type=float, default=1001.0, help="first time code (default 1001)")
    im.add_argument("--joint-map", metavar="FILE",
                    help="JSON object (or .toml table) {\"BVH joint\": \"SMPL joint\"} for rigs not recognised; "
                         "its entries replace a recognised rig's")
    im.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    im.add_argument("--force", action="store_true", help="replace an existing output file")

    cv = add_command("convert", help="a baked shot or cache to glTF (compressed morph-target animation) or to "
                                     "vertex-animation textures, for game engines")
    cv.add_argument("source", metavar="SHOT_OR_CACHE", help="shot layer (bake --shot) or cache layer (bake -o)")
    cv.add_argument("-o", "--output", required=True, help="OUT.glb or OUT.gltf; with --format vat, a folder")
    cv.add_argument("--format", choices=["gltf", "vat"], default="gltf",
                    help="gltf (default): morph targets + weights; vat: SideFX Labs VAT 3.0 soft-body textures")
    k = cv.add_mutually_exclusive_group()
    k.add_argument("--max-error", type=float, metavar="MM",
                   help="glTF: fewest morph targets whose worst vertex of any frame is within MM of the cache "
                        "(default 1)")
    k.add_argument("--targets", type=int, metavar="K", help="glTF: exactly K morph targets")
    cv.add_argument("--with-body", action="store_true",
                    help="glTF: add the body as a skinned mesh animated by the SMPL skeleton")
    cv.add_argument("--garment", metavar="PRIM", help="the garment to convert (default: the only baked one)")
    cv.add_argument("--scene", help="the scene a cache layer was baked from (default: its provenance's)")
    cv.add_argument("--engine", choices=["unity", "unreal"], default="unity",
                    help="vat: axes and unit of the textures (unity: metres; unreal: centimetres)")
    cv.add_argument("--vat-format", choices=["exr", "png16"], default="exr",
                    help="vat: half-float EXR (raw offsets, default) or 16-bit PNG (offsets normalised to the bounds)")
    cv.add_argument("--max-width", type=int, default=8192, help="vat: widest texture; more vertices wrap to more "
                                                                 "rows per frame (default 8192)")
    cv.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    cv.add_argument("--force", action="store_true", help="replace existing output files")

    pv = add_command("preview", help="one self-contained HTML page that plays a baked shot (three.js) with a timeline")
    pv.add_argument("source", metavar="SHOT_OR_CACHE", help="shot layer (bake --shot) or cache layer (bake -o)")
    pv.add_argument("-o", "--output", required=True, help="the .html page to write")
    pk = pv.add_mutually_exclusive_group()
    pk.add_argument("--max-error", type=float, metavar="MM", help="as for convert (default 1)")
    pk.add_argument("--targets", type=int, metavar="K", help="as for convert")
    pv.add_argument("--no-body", action="store_true", help="the garment alone")
    pv.add_argument("--garment", metavar="PRIM", help="the garment to show (default: the only baked one)")
    pv.add_argument("--scene", help="the scene a cache layer was baked from (default: its provenance's)")
    pv.add_argument("--body-model", help="SMPL-format .npz/.pkl file or folder (default: embedded)")
    pv.add_argument("--force", action="store_true", help="replace an existing page")
    return p


def _render(args: argparse.Namespace) -> int:
    from .core.frame_range import parse_time_codes
    from .render import render_frames, render_shard, shard_frames

    times = parse_time_codes(args.frames)
    if args.scene.endswith(".npz"):
        out = render_shard(args.scene, shard_frames(times, args.frames), args.output, body_model=args.body_model,
                           view=args.view)
    else:
        out = render_frames(args.scene, times, args.output, body_model=args.body_model, view=args.view)
    sys.stdout.write(f"wrote {out}\n")
    return 0


def _datagen(args: argparse.Namespace) -> int:
    from .datagen.factory import load_config, run_factory

    import time

    from .errors import ArgumentError

    for flag, value, least in (("--workers", args.workers, 1), ("--batch", args.batch, 1),
                               ("--penetration-frames", args.penetration_frames, 1),
                               ("--max-minutes", args.max_minutes, 0)):
        if value is not None and value < least:
            raise ArgumentError(f"{flag} must be at least {least}, got {value:g}")
    deadline = time.time() + 60.0 * args.max_minutes if args.max_minutes is not None else None
    manifest = run_factory(load_config(args.config, mocap_dir=args.mocap), args.output, workers=args.workers,
                           batch=args.batch, penetration_frames=args.penetration_frames, deadline=deadline)
    from .datagen.simulate import LEFT_THE_BODY, SimulationError

    partial = f" ({len(manifest.partial)} of them unstable, their first frames kept)" if manifest.partial else ""
    left = sum(LEFT_THE_BODY in ((manifest.sequences[name].get("quality") or {}).get("failure") or "")
               for name in manifest.partial + manifest.rejected)
    off = f"; {left} of the unstable ones stopped where {LEFT_THE_BODY}" if left else ""
    sys.stdout.write(f"{len(manifest.accepted)} sequences simulated{partial}, {len(manifest.rejected)} rejected "
                     f"as unstable{off}; manifest in {args.output}/manifest.json\n")
    if manifest.rejected and not manifest.accepted:  # not a data set: nothing to train on or measure against
        first = manifest.rejected[0]
        failure = (manifest.sequences[first].get("quality") or {}).get("failure") or "unstable"
        advice = ("a garment that slid off the body is not cloth to learn from; set sim.keep_partial to keep "
                  "the frames before it, or sim.max_bare (0.1 unless set) if that much bare body is how the "
                  "garment is worn" if LEFT_THE_BODY in failure else
                  "where a hand, an elbow or a raised knee presses into the cloth Newton's own cloth can stretch "
                  "past the config's sim.max_stretch (1.6 unless set): raise it there to keep them, or set "
                  "sim.keep_partial to keep their frames before it")
        raise SimulationError(f"{args.config}: every sequence was rejected as unstable ({first}: {failure}); "
                              f"{advice}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from .inspection import format_report, inspect_stage

    report = inspect_stage(args.scene, joint_map=args.joint_map, body_model=args.body_model,
                           models=None if args.models is None else [args.models])
    sys.stdout.write(format_report(report) + "\n")
    return 1 if report.problems else 0


def _frames_and_tier(args: argparse.Namespace):
    """``--tier`` and ``--frames`` parsed once, here at the edge: ``(FrameRange | None, Tier | None)``."""
    from .baking import parse_frames, parse_tier

    tier = parse_tier(args.tier)
    return (None if args.frames is None else parse_frames(args.frames)), tier


def _bake(args: argparse.Namespace) -> int:
    from .baking import bake

    frames, tier = _frames_and_tier(args)
    result = bake(args.scene, args.output, shot=args.shot, frames=frames, garments=args.garment,
                  tier=tier, force=args.force, body_model=args.body_model, models=args.models,
                  joint_map=args.joint_map, progress=not args.no_progress and sys.stderr.isatty(),
                  strict=args.strict, allow_any_size=args.allow_any_size)
    try:
        return _bake_summary(result)
    except OSError as exc:
        raise _summary_failed(exc, [str(p) for p in (result.cache, result.shot) if p]) from exc


def _bake_summary(result) -> int:
    for g in result.garments:
        sys.stdout.write(f"{g.prim_path}: {g.frames} frames, {g.vertices} vertices, tier {g.tier.value}\n")
        if g.bundle is not None:
            sys.stdout.write(f"{g.prim_path}: bundle {g.bundle}, fit {' '.join(f'{a:.3f}' for a in g.fit)}, "
                             f"post-process moved {g.postprocess_moved} vertices "
                             f"({g.postprocess_moved / max(1, g.frames):.1f} per frame)\n")
            if g.fallback_coarse or g.fallback_skinning:
                sys.stdout.write(f"{g.prim_path}: guard replaced {g.fallback_coarse} frames by coarse and "
                                 f"{g.fallback_skinning} by skinning (not a garment; see the warnings)\n")
    per_frame = result.seconds / max(1, result.times.shape[0]) * 1000.0
    sys.stdout.write(f"wrote {result.cache} ({result.times.shape[0]} frames, {result.seconds:.2f} s, "
                     f"{per_frame:.1f} ms/frame)\n")
    if result.shot:
        sys.stdout.write(f"wrote {result.shot} (open this to see the animated garments)\n")
    sys.stdout.flush()
    return 0


def _summary_failed(exc: OSError, written: list[str]) -> ClothUsdError:
    """The error for a summary that stdout refused (a full disk, a closed pipe); stdout is
    pointed at /dev/null so that Python's flush at exit adds no traceback."""
    from .errors import OutputWriteError

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, AttributeError, ValueError):  # not a real file (captured in tests)
        pass
    files, many = " and ".join(written), len(written) > 1
    return OutputWriteError(f"stdout: cannot write the summary ({exc.strerror or exc}); {files} "
                            f"{'were' if many else 'was'} written and {'are' if many else 'is'} complete")


def _batch(args: argparse.Namespace) -> int:
    from .batch import describe_jobs, load_jobs, run_batch

    frames, tier = _frames_and_tier(args)
    jobs = load_jobs(args.jobs, out_dir=args.out_dir, frames=frames, garments=args.garment, tier=tier,
                     models=args.models, body_model=args.body_model, joint_map=args.joint_map, strict=args.strict)
    if args.dry_run:
        sys.stdout.write("".join(line + "\n" for line in describe_jobs(jobs)))
        return 0

    def show(job) -> None:
        detail = job.error if job.error else f"{job.frames} frames, {job.seconds:.1f} s"
        sys.stdout.write(f"{job.status.value:8s} {job.name}: {detail}\n")
        sys.stdout.flush()

    report = run_batch(jobs, executor=args.executor, workers=args.workers, retries=args.retries,
                       chunk_frames=args.chunk_frames, force=args.force, address=args.address,
                       job_timeout=args.job_timeout, on_job=show)
    sys.stdout.write("".join(line + "\n" for line in report.summary()))
    if args.report:
        sys.stdout.write(f"report: {report.write(args.report)}\n")
    return 1 if report.failed else 0


def _doctor(args: argparse.Namespace) -> int:
    from .doctor import run_checks

    def show(check) -> None:
        sys.stdout.write(f"{'ok  ' if check.ok else 'FAIL'}  {check.name}: {check.detail}\n")

    checks = run_checks(args.body_model, gender=args.gender, progress=show)
    return 0 if all(c.ok for c in checks) else 1


def _garment(args: argparse.Namespace) -> int:
    from .garments.command import run

    return run(args)


def _body(path: str | None):
    from .core.body import load_body_model

    return load_body_model(path) if path else None


def _train(args: argparse.Namespace) -> int:
    import dataclasses

    from .errors import ArgumentError
    from .nn.physics_train import PhysicsOptions, load_physics_config
    from .nn.train import resume_settings, train

    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    config_path, coarse_run = args.config, args.coarse_run
    if args.resume and (config_path is None or coarse_run is None):
        config, prior_coarse = resume_settings(args.out, epochs=args.epochs)
        coarse_run = coarse_run or prior_coarse
    options = PhysicsOptions()
    if config_path is not None or not args.resume:
        config, options = load_physics_config(config_path, epochs=args.epochs)  # TrainConfig keys + "physics"
    if args.objective:
        config = dataclasses.replace(config, objective=args.objective)

    hybrid = config.objective.value == "hybrid"
    physics = config.objective.value == "physics" or hybrid
    if not physics and options != PhysicsOptions():
        raise ArgumentError(f"--config {config_path}: its \"physics\" table applies to --objective physics or "
                            "hybrid only")
    if args.init and not physics:
        raise ArgumentError("--init: only a physics or hybrid run starts from a trained run (a supervised run "
                            "continues its own with --resume)")
    if args.mocap and not physics:
        raise ArgumentError("--mocap: only a physics run reads motions (a supervised run reads simulated data)")
    if hybrid != (args.sim_data is not None):
        raise ArgumentError("--sim-data: --objective hybrid needs it (the datagen folder simulated from --data), "
                            "and only the hybrid objective reads it")
    # physics: val is the energy [J] above the base garment's (skinned for coarse, M_coarse for detail);
    # hybrid: plus the supervised term, and the mm are the distance to the simulated target
    mm = ("mm from skinning" if args.tier == "coarse" else "mm from the coarse garment") if physics else "mm"
    if hybrid:
        mm = "mm from the simulation" + ("'s coarse target" if args.tier == "coarse" else "")
    elif physics and options.anchor_weight:
        mm = "mm from the initial run's garment"

    def show(r) -> None:
        sys.stdout.write(f"epoch {r.epoch + 1}/{config.epochs}: train {r.train_loss:.4g}, val {r.val_loss:.4g} "
                         f"({r.val_mm:.3f} {mm}), {r.seconds:.1f} s\n")
        sys.stdout.flush()

    if physics:
        from .nn.physics_train import train_physics

        if args.resume:
            raise ArgumentError(f"--objective {config.objective.value}: --resume is not supported yet; train into a "
                                "new --out")
        result = train_physics(args.data, args.out, config, tier=args.tier, coarse_run=coarse_run,
                               device=args.device, body=_body(args.body_model), progress=show, options=options,
                               mocap_dir=args.mocap, sim_data=args.sim_data, init_run=args.init)
    else:
        result = train(args.tier, args.data, args.out, config, coarse_run=coarse_run, device=args.device,
                       resume=args.resume, body=_body(args.body_model), progress=show)
    best = result.best
    sys.stdout.write(f"{args.tier}: best epoch {result.best_epoch + 1} (val {best.val_loss:.4g}, {best.val_mm:.3f} {mm}); "
                     f"run in {result.run_dir} (best.pt, history.csv, curve.png)\n")
    return 0


def _export(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from .errors import ArgumentError
    from .nn.export import export_bundle

    metrics = None
    if args.metrics:
        try:
            metrics = json.loads(Path(args.metrics).read_text())
        except (OSError, ValueError) as exc:
            raise ArgumentError(f"--metrics {args.metrics}: unreadable ({exc})") from exc
    if _is_garment_run(args.coarse_run):  # train-garment's garment form: its work folder's runs and data.json
        from .nn.garment_model import export_garment_bundle

        if args.parity_data:
            raise ArgumentError("--parity-data: a garment model's files are checked on its data config's validation "
                                "sequences; leave it out")
        out = export_garment_bundle(args.coarse_run, args.detail_run, args.data, args.out, name=args.name,
                                    category=args.category, description=args.description, force=args.force,
                                    mocap_dir=args.mocap, body=_body(args.body_model), metrics=metrics)
    else:
        out = export_bundle(args.coarse_run, args.detail_run, args.data, args.out, name=args.name,
                            category=args.category or "tshirt", metrics=metrics, description=args.description,
                            force=args.force, body=_body(args.body_model), mocap_dir=args.mocap,
                            parity_data=args.parity_data)
    checked = f"the sequences of {args.parity_data}" if args.parity_data else "the validation data"
    sys.stdout.write(f"wrote bundle {out} (ONNX checked against torch on {checked})\n")
    return 0


def _is_garment_run(run: str) -> bool:
    """Whether ``run`` is a garment model run (``train-garment --form garment``), by its run.json."""
    import json
    from pathlib import Path

    from .nn.garment_model import RUN, RUN_KIND

    try:
        return json.loads((Path(run) / RUN).read_text()).get("kind") == RUN_KIND
    except (OSError, ValueError, AttributeError):
        return False  # export_bundle names what is wrong with the run


def _evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate_bundle

    report = evaluate_bundle(args.data, args.bundle, args.out, ablation_runs=args.ablation_runs,
                             body=_body(args.body_model), max_frames=args.max_frames, device=args.device,
                             rest=args.rest)
    for row in report.rows:
        cells = ", ".join(f"{t} {row['mean_mm'][t]:.2f}" for t in report.tiers)
        sys.stdout.write(f"{row['title']}: {cells} mm\n")
    sys.stdout.write(f"wrote {report.out_dir}/report.md, metrics.json, histograms.png, means.png\n")
    return 0


def _train_garment(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    import numpy as np

    from .core.body import load_body_model, shape_body
    from .core.frames import worn_rest_points
    from .core.smpl import JOINT_NAMES
    from .datagen.factory import OwnGarment
    from .errors import ArgumentError
    from .nn.own_garment import HYBRID_CONFIG, TEST_SET_CONFIG, OwnGarmentPlan, train_own_garment
    from .usd.read import open_stage, read_scene

    plan = OwnGarmentPlan(coarse_epochs=args.coarse_epochs, detail_epochs=args.detail_epochs, batches=args.batches,
                          form=args.form, steps=args.steps, detail_steps=args.detail_steps,
                          sim_weight=args.sim_weight, sim_sequences=args.sim_sequences,
                          coarse_target=args.coarse_target, mirror=args.mirror)

    def motion_list(flag: str, path: str | None) -> tuple | None:
        if not path:
            return None
        try:
            found = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise ArgumentError(f"{flag} {path}: not a readable JSON list ({exc})") from None
        if not isinstance(found, list) or not all(isinstance(m, dict) for m in found):
            raise ArgumentError(f"{flag} {path}: expected a JSON list of motion entries (objects), got "
                                f"{type(found).__name__}")
        return tuple(found)

    motions = motion_list("--motions", args.motions)
    test_motions = motion_list("--test-motions", args.test_motions)
    if test_motions == ():
        raise ArgumentError(f"--test-motions {args.test_motions}: an empty list; the test set needs at least one "
                            "motion (leave the flag out for the three stored CMU test stretches)")
    body = load_body_model()
    owns, prims = [], []
    for path in args.scene:
        scene = read_scene(open_stage(path), joint_map=args.joint_map)
        garments = [g for g in scene.garments if args.garment in (None, g.prim_path)]
        if len(garments) != 1:
            found = ", ".join(g.prim_path for g in scene.garments) or "none"
            raise ArgumentError(f"{path}: " + (f"no garment {args.garment} (garments: {found})" if args.garment
                                else f"name the garment with --garment (garments: {found})"))
        garment = garments[0]
        char = next(c for c in scene.characters if c.prim_path == garment.body_path)
        rest = worn_rest_points(char, garment.rest_points, shape_body(body, char.betas)[1])
        if owns and garment.category.value != owns[0].category:
            raise ArgumentError(f"{path} <{garment.prim_path}>: a {garment.category.value}, but {args.scene[0]}'s "
                                f"garment is a {owns[0].category}: one bundle serves one category")
        owns.append(OwnGarment(vertices=rest, faces=np.asarray(garment.triangles, dtype=np.int64),
                               betas=np.asarray(char.betas, dtype=np.float64), category=garment.category.value))
        prims.append(garment.prim_path)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)

    def show(tier, r) -> None:
        start = 'skinning' if tier == 'coarse' else 'the coarse garment'
        if isinstance(r, dict):  # the garment form: a validation row
            sys.stdout.write(f"{tier} step {r['step']}: val {r['val_energy']:.4g} J a frame ({start} "
                             f"{r['val_start_energy']:.4g} J, {r['val_mm']:.2f} mm from it), {r['seconds']:.0f} s\n")
        else:
            sys.stdout.write(f"{tier} epoch {r.epoch + 1}: val {r.val_loss:+.4g} J ({r.val_mm:.2f} mm from "
                             f"{start}), {r.seconds:.0f} s\n")
        sys.stdout.flush()

    clips = any("bvh" in m for m in test_motions or ())  # the test set reads BVH clips
    mocap = f" --mocap {args.mocap or 'MOCAP'}" if clips else ""
    out = Path(args.out)
    result = train_own_garment(owns, out, name=args.name or out.name, work_dir=args.work, motions=motions,
                               test_motions=test_motions, mocap_dir=args.mocap, sim_data=args.sim_data, plan=plan,
                               force=args.force,
                               device=args.device, body=body, progress=show)
    t = result.seconds
    what = f"{prims[0]} ({owns[0].vertices.shape[0]} vertices)" if len(owns) == 1 else \
        f"{len(owns)} {owns[0].category} garments ({', '.join(str(g.vertices.shape[0]) for g in owns)} vertices)"
    sys.stdout.write(f"wrote bundle {result.bundle} for {what} in "
                     f"{t['total'] / 60:.1f} min (coarse {t['coarse'] / 60:.1f}, detail {t['detail'] / 60:.1f}, "
                     f"export {t['export']:.0f} s); runs and config in {result.work_dir}\n"
                     f"bake with: cloth-usd bake {args.scene[0]} -o CACHE.usdc --tier detail --models {result.bundle}\n"
                     f"a Newton test set for it: cloth-usd datagen {result.work_dir / TEST_SET_CONFIG} -o TESTSET"
                     f"{mocap}, then cloth-usd evaluate --data TESTSET "
                     f"--bundle {result.bundle}\n")
    read = result.pose_joints
    if read is not None:  # the garment form: the joints its models read (cloth_usd.core.garment_inputs.read_joints)
        unread = [n for n in JOINT_NAMES if n not in read]
        sys.stdout.write(f"its models read {len(read)} of {len(JOINT_NAMES)} joints"
                         + (f"; not {', '.join(unread)}, which cannot move it\n" if unread else "\n"))
    if not args.sim_data and (result.work_dir / HYBRID_CONFIG).exists():  # the garment form, trained on its energy
        mocap = f" --mocap {args.mocap}" if args.mocap else ""
        sys.stdout.write(f"Newton's frames to train on too (the hybrid objective): cloth-usd datagen "
                         f"{result.work_dir / HYBRID_CONFIG} -o SIMDATA{mocap}, then this command again with "
                         "--sim-data SIMDATA --force\n")
    return 0


def _import_motion(args: argparse.Namespace) -> int:
    from .motion_import import import_motion, parse_betas

    result = import_motion(args.motion, args.output, garments=args.garment,
                           betas=None if args.betas is None else parse_betas(args.betas), gender=args.gender,
                           fps=args.fps, frames=args.frames, joint_map=args.joint_map, force=args.force,
                           start=args.start, body_model=args.body_model)
    first, last = result.source_frames
    sys.stdout.write(f"{args.motion}: {result.rig}, file frames {first}:{last} -> {result.frames} frames at "
                     f"{result.fps:g} fps (time codes {result.start:g}:{result.start + result.frames - 1:g})\n")
    for g in result.garments:
        sys.stdout.write(f"{g}: bound to the character\n")
    sys.stdout.write(f"wrote {result.output}\n")
    return 0


def _convert(args: argparse.Namespace) -> int:
    from .export.convert import OutputFormat, convert
    from .export.vat import Engine, TextureFormat

    result = convert(args.source, args.output, fmt=OutputFormat(args.format), max_error_mm=args.max_error,
                     targets=args.targets, with_body=args.with_body, garment=args.garment, scene=args.scene,
                     body_model=args.body_model, engine=Engine(args.engine), vat_format=TextureFormat(args.vat_format),
                     max_width=args.max_width, force=args.force)
    what = f"{result.targets} morph targets" if result.targets is not None else "vertex-animation textures"
    sys.stdout.write(f"{result.frames} frames, {result.vertices} vertices as {what}: error to the cache "
                     f"max {result.max_error_mm:.3f} mm, mean {result.mean_error_mm:.4f} mm\n")
    for f in result.files:
        sys.stdout.write(f"wrote {f} ({f.stat().st_size / 1024:.0f} KiB)\n")
    return 0


def _preview(args: argparse.Namespace) -> int:
    from .export.preview import write_preview

    result = write_preview(args.source, args.output, max_error_mm=args.max_error, targets=args.targets,
                           with_body=not args.no_body, garment=args.garment, scene=args.scene,
                           body_model=args.body_model, force=args.force)
    sys.stdout.write(f"{result.frames} frames, {result.targets} morph targets (max error {result.max_error_mm:.3f} mm)"
                     f"\nwrote {result.path} ({result.path.stat().st_size / 1024:.0f} KiB; open it in a browser)\n")
    return 0


class _Terminated(BaseException):
    """SIGTERM (what farm schedulers send), raised where the process is, so that every
    ``with`` block and ``finally`` on the way out runs."""


def _on_sigterm(signum, frame) -> None:
    raise _Terminated()


#: The optional dependencies a command may import, and the extra (pyproject.toml) that installs each.
_EXTRAS = {"torch": "train", "smplx": "train", "sklearn": "train", "onnx": "train", "onnxscript": "train",
           "matplotlib": "preview", "trimesh": "datagen", "newton": "datagen", "warp": "datagen",
           "fast_simplification": "datagen", "ray": "ray", "OpenEXR": "game", "onnxruntime": "runtime"}
_TORCH_FIRST = " (pip install torch==2.13.0 first where that CPU build is at hand, or pip fetches a CUDA build)"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the process exit code."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="cloth-usd: %(levelname)s: %(message)s")
    installed = threading.current_thread() is threading.main_thread()  # signal.signal works there only
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if installed else None
    try:
        commands = {"inspect": _inspect, "bake": _bake, "doctor": _doctor, "render": _render, "batch": _batch,
                    "datagen": _datagen,
                    "train": _train, "export": _export, "evaluate": _evaluate,
                    "import-motion": _import_motion, "garment": _garment, "train-garment": _train_garment, "convert": _convert, "preview": _preview}
        return commands[args.command](args)
    except ClothUsdError as exc:
        if args.verbose:
            sys.stderr.write(traceback.format_exc())
        sys.stderr.write(f"cloth-usd: error: {exc}\n")
        return 2
    except ModuleNotFoundError as exc:
        extra = _EXTRAS.get((exc.name or "").split(".")[0])
        if extra is None:  # not an optional dependency: a bug, shown whole
            raise
        if args.verbose:
            sys.stderr.write(traceback.format_exc())
        sys.stderr.write(f"cloth-usd: error: cloth-usd {args.command} needs {exc.name}, which is not installed: "
                         f"pip install 'cloth-usd[{extra}]'{_TORCH_FIRST if extra == 'train' else ''}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("cloth-usd: interrupted; no output was written\n")
        return 130
    except _Terminated:  # the temporary files were removed on the way out (CacheLayerWriter)
        done = {"bake": "; nothing partial was left (a cache and its shot are written whole, together, or not at all)",
                "batch": "; jobs that had finished keep their outputs, the others wrote nothing"}
        sys.stderr.write(f"cloth-usd: interrupted (SIGTERM){done.get(args.command, '')}\n")
        return 128 + signal.SIGTERM
    finally:
        if installed:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


if __name__ == "__main__":
    sys.exit(main())
