"""Simulate a data set with Newton, then train the coarse and the detail tier on it, each against a clock.

The GPU lease's job: one command that makes the ground truth and both models in a fixed time,
and leaves what a bundle needs behind (the runs, the data set's manifest, fit model and
validation shards). It runs the same on the CPU, only slower.

1. ``cloth-usd datagen CONFIG --batch K --workers W --max-minutes SIM`` (a process of its own).
2. The data set is loaded once, then ``train coarse`` and ``train detail`` (predicted coarse
   input) run on it in turn; each stops after the first epoch that ends past its minutes (the
   best epoch so far is the run's model, as always). A training config whose ``objective`` is
   ``hybrid`` trains on the datagen config's energy plus the simulated frames instead
   (``cloth-usd train --objective hybrid --data CONFIG --sim-data DATA``).
3. ``--pack DIR``: ``runs.tar`` (both runs), ``data.tar`` (manifest.json, fit.npz, the
   validation shards: what ``cloth-usd export --data`` reads) and ``summary.json``.

Run: python scripts/simulate_and_train.py configs/datagen_gpu_tshirt.json --mocap MOCAP --data DATA \\
         --runs RUNS --batch 16 --workers 12 --sim-minutes 4 --coarse-minutes 2 --detail-minutes 2 --pack OUT
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import numpy as np

log = logging.getLogger("simulate_and_train")


class OutOfTime(Exception):
    """Raised from the epoch callback once a run's minutes are spent."""


def simulate(args: argparse.Namespace) -> float:
    """Run ``cloth-usd datagen`` in a process of its own; returns its seconds."""
    began = time.time()
    cmd = [sys.executable, "-c", "import sys; from cloth_usd.cli import main; sys.exit(main())", "datagen",
           args.config, "-o", args.data, "--batch", str(args.batch), "--workers", str(args.workers),
           "--max-minutes", str(args.sim_minutes), "--penetration-frames", str(args.penetration_frames)]
    if args.mocap:
        cmd += ["--mocap", args.mocap]
    log.info("%s", " ".join(cmd))
    done = subprocess.run(cmd, check=False)
    if done.returncode != 0:
        raise SystemExit(f"datagen failed (exit {done.returncode})")
    return time.time() - began


def train_tier(tier: str, dataset, args: argparse.Namespace, config_path: str, minutes: float,
               coarse_run: Path | None) -> dict:
    """Train one tier on the loaded data set (supervised) or on the datagen config's energy plus
    the simulated frames (hybrid) until its minutes are spent; returns its summary."""
    from cloth_usd.nn.physics_train import load_physics_config, train_physics
    from cloth_usd.nn.runs import load_run
    from cloth_usd.nn.train import train

    config, options = load_physics_config(config_path)
    run_dir = Path(args.runs) / tier
    deadline = time.time() + 60.0 * minutes
    history = []

    def progress(record) -> None:
        history.append(record)
        log.info("%s epoch %d: val %.3f mm, %.1f s", tier, record.epoch, record.val_mm, record.seconds)
        if time.time() > deadline:
            raise OutOfTime

    began = time.time()
    try:
        if config.objective.value == "hybrid":
            train_physics(args.config, run_dir, config, tier=tier, coarse_run=coarse_run, device=args.device,
                          progress=progress, options=options, mocap_dir=args.mocap, sim_data=args.data)
        else:
            train(tier, args.data, run_dir, config, coarse_run=coarse_run, device=args.device, dataset=dataset,
                  progress=progress)
        stopped = "epochs"
    except OutOfTime:
        stopped = "clock"
    if not history:
        raise SystemExit(f"{tier}: no epoch finished")
    # The run's own best (best.pt: the validation loss, or the training loss without validation).
    best = next(r for r in history if r.epoch == load_run(run_dir).epoch)
    return {"run": str(run_dir), "epochs": len(history), "stopped_by": stopped, "seconds": time.time() - began,
            "best_epoch": best.epoch, "best_val_mm": best.val_mm,
            "val_mm": [r.val_mm for r in history], "epoch_seconds": [r.seconds for r in history]}


def pack(args: argparse.Namespace, summary: dict) -> None:
    """The runs, and what ``cloth-usd export --data`` reads of the data set, into ``--pack``."""
    from cloth_usd.core.shards import Manifest

    out = Path(args.pack)
    out.mkdir(parents=True, exist_ok=True)
    with tarfile.open(out / "runs.tar", "w") as tar:
        tar.add(args.runs, arcname="runs")
    data = Path(args.data)
    manifest = Manifest.read(data)
    val = [e["shard"] for e in manifest.sequences.values()
           if e.get("status") == "ok" and (e.get("split") or e.get("meta", {}).get("split")) == "val"]
    with tarfile.open(out / "data.tar", "w") as tar:
        for name in ["manifest.json", "fit.npz", *val]:
            tar.add(data / name, arcname=f"data/{name}")
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", help="the datagen config")
    ap.add_argument("--mocap", help="the folder its BVH motions are relative to")
    ap.add_argument("--data", required=True, help="data set folder (made or continued)")
    ap.add_argument("--runs", required=True, help="folder for the coarse and detail runs")
    ap.add_argument("--batch", type=int, default=16, help="sequences simulated at once per worker (default 16)")
    ap.add_argument("--workers", type=int, default=1, help="simulation processes (default 1)")
    ap.add_argument("--penetration-frames", type=int, default=3, help="frames per sequence whose penetration "
                                                                      "is measured (default 3)")
    ap.add_argument("--sim-minutes", type=float, default=4.0, help="start no simulation after this (default 4)")
    ap.add_argument("--coarse-config", default="configs/train_coarse_gpu.json")
    ap.add_argument("--detail-config", default="configs/train_detail_gpu.json")
    ap.add_argument("--coarse-minutes", type=float, default=2.0, help="the coarse run's clock (default 2)")
    ap.add_argument("--detail-minutes", type=float, default=2.0, help="the detail run's clock (default 2)")
    ap.add_argument("--device", default="auto", help="torch device (default: CUDA when present)")
    ap.add_argument("--skip-simulation", action="store_true", help="train on --data as it is")
    ap.add_argument("--pack", help="folder for runs.tar, data.tar and summary.json")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    summary: dict = {"args": vars(args)}
    if not args.skip_simulation:
        summary["simulation_seconds"] = simulate(args)
    from cloth_usd.core.shards import Manifest
    from cloth_usd.nn.data import Split, load_dataset

    manifest = Manifest.read(Path(args.data))
    quality = [e.get("quality", {}) for e in manifest.sequences.values() if e.get("status") == "ok"]
    summary["sequences"] = {"ok": len(manifest.accepted), "rejected": len(manifest.rejected),
                            "frames": sum(int(q.get("frames_done", 0)) for q in quality),
                            "seconds_per_frame_p10_p50_p90": [
                                float(v) for v in np.percentile([float(q.get("seconds_per_frame", 0)) for q in quality]
                                                                or [0.0], [10, 50, 90])]}
    dataset = None
    if any(json.loads(Path(c).read_text()).get("objective", "supervised") == "supervised"
           for c in (args.coarse_config, args.detail_config)):
        began = time.time()
        dataset = load_dataset(args.data, (Split.TRAIN, Split.VAL))
        summary["load_seconds"] = time.time() - began
        log.info("loaded %d sequences in %.1f s", len(dataset.clips), summary["load_seconds"])
    summary["coarse"] = train_tier("coarse", dataset, args, args.coarse_config, args.coarse_minutes, None)
    summary["detail"] = train_tier("detail", dataset, args, args.detail_config, args.detail_minutes,
                                   Path(args.runs) / "coarse")
    if args.pack:
        pack(args, summary)
    print(json.dumps({k: v for k, v in summary.items() if k != "args"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
