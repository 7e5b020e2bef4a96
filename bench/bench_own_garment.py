"""Benchmark (not a test): a user's own garment, from mesh to bundle, timed and measured against Newton.

The garment is the test set's unseen shirt (``configs/datagen_testset.json``, variant 0
at its resolution), made for the slim body and written into a USD stage the way a user
would hand it over (an SMPL character wearing a ``cloth:category`` Mesh). ``cloth-usd
train-garment`` is run on it as a user runs it, and timed as a whole command. The bundle
it makes and the shipped default (trained on many shirts) are then evaluated side by side
on that shirt's sequences of the simulated test set (split ``test_garment``: the shirt on
four bodies, CMU 05_02 after the warm-up): mean and 95th-percentile vertex error [mm] per
tier, and the ratio of each to skinning.

Run: python bench/bench_own_garment.py --testset DATA [--mocap DIR --motions configs/own_garment_motions.json]
         [--reference models/bundles/tshirt-v4] [--out out/own_garment] [-- train-garment flags]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from pxr import Usd

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.datagen import make_tshirt
from cloth_usd.datagen.bodies import body_shapes
from cloth_usd.datagen.factory import load_config
from cloth_usd.datagen.tshirt import tshirt_variants
from cloth_usd.evaluate import evaluate_bundle
from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

ROOT = Path(__file__).resolve().parents[1]


def garment_stage(path: Path, config_path: Path, body_name: str = "slim") -> tuple[Path, int]:
    """The test set's unseen shirt, made for ``body_name``, as a user's stage (two rest frames)."""
    config = load_config(config_path)
    variant = tshirt_variants(config.shirts, seed=config.seed)[config.test_shirts[0]]
    if config.garment_vertices:
        variant = dataclasses.replace(variant, target_vertices=config.garment_vertices)
    body = load_body_model()
    betas = body_shapes([body_name])[0].betas
    _, joints = shape_body(body, betas)
    verts, faces = make_tshirt(body, betas, variant)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    stage = Usd.Stage.CreateNew(str(path))
    times = np.array([1.0, 2.0])
    set_stage_metadata(stage, up_axis="Y", meters_per_unit=1.0, fps=30.0, start=times[0], end=times[-1])
    skel = author_skeleton(stage, "/Character/Skeleton", joint_positions=joints, betas=betas,
                           poses=np.zeros((2, 72)), root_positions=np.repeat(joints[:1], 2, axis=0), times=times)
    author_garment(stage, "/Character/Shirt", points=verts, faces=faces, category="tshirt", body_path=skel)
    stage.GetRootLayer().Save()
    return path, int(verts.shape[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--testset", required=True, help="the simulated test set (cloth-usd datagen of the config)")
    ap.add_argument("--config", default=str(ROOT / "configs" / "datagen_testset.json"))
    ap.add_argument("--reference", default=str(ROOT / "models" / "bundles" / "tshirt-v4"))
    ap.add_argument("--mocap", help="the folder of the --motions clips")
    ap.add_argument("--motions", help="extra training motions for train-garment (JSON list)")
    ap.add_argument("--out", default="out/own_garment")
    ap.add_argument("--no-train", action="store_true",
                    help="evaluate the bundle an earlier run left in OUT/bundle (its time from timing.json)")
    ap.add_argument("extra", nargs="*", help="more train-garment flags, after --")
    args = ap.parse_args(argv)
    out = Path(args.out)
    stage, n = garment_stage(out / "garment.usda", Path(args.config))
    bundle = out / "bundle"
    cmd = [sys.executable, "-m", "cloth_usd.cli", "train-garment", str(stage), "-o", str(bundle), "--force",
           "--name", "own-shirt"]
    if args.motions:
        cmd += ["--motions", args.motions, "--mocap", args.mocap]
    cmd += args.extra
    if args.no_train:
        minutes = json.loads((out / "bundle.work" / "timing.json").read_text())["total"] / 60
    else:
        print(" ".join(cmd), flush=True)
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True)
        minutes = (time.perf_counter() - t0) / 60
    rows = {}
    for name, b in (("own", bundle), ("reference", Path(args.reference))):
        report = evaluate_bundle(args.testset, b, out / f"eval_{name}", splits=("test_garment",))
        metrics = json.loads((report.out_dir / "metrics.json").read_text())
        rows[name] = (report, metrics)
    first = rows["own"][0].rows[-1]
    lines = [f"A {n}-vertex shirt (the test set's unseen shirt, made for the slim body): `cloth-usd train-garment` "
             f"{minutes:.1f} min; error against Newton on its {first['sequences']} test_garment sequences "
             f"({first['frames']} frames; mean / p95 mm, and the mean over skinning's)", "",
             "| bundle | skinning | coarse | detail |", "|---|---:|---:|---:|"]
    for name, (report, _) in rows.items():
        row = report.rows[-1]
        skin = row["mean_mm"]["skinning"]
        cells = [f"{row['mean_mm'][t]:.2f} / {row['p95_mm'][t]:.2f} ({row['mean_mm'][t] / skin:.2f})"
                 for t in ("skinning", "coarse", "detail") if t in row["mean_mm"]]
        label = bundle.name if name == "own" else Path(args.reference).name
        lines.append(f"| {name}: {label} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    (out / "own_garment.md").write_text(text)
    (out / "own_garment.json").write_text(json.dumps({"minutes": minutes, "vertices": n,
                                                      "own": rows["own"][1], "reference": rows["reference"][1]},
                                                     indent=1, default=str))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
