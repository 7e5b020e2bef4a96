"""Benchmark (not a test): ground-truth accuracy against cost for the simulator's settings (issue #13).

One garment-body pair (a ``--vertices`` T-shirt on the mean body, draped once with the
default settings) and one stretch of a real clip (``--bvh`` under ``--mocap``, eased in
as the data factory does, :mod:`cloth_usd.datagen.mocap`) are simulated with each
setting below, side by side in one run. Every setting is compared with the reference
(many substeps and iterations, the full body mesh as the collider) on the frames after
the warm-up: mean and 95th-percentile vertex distance [mm], the fraction of garment
vertices inside the body, the 99th-percentile edge stretch, and seconds per frame
(after the first frame, which loads kernels). Ratios are against the default setting's
time in the same run.

With ``--floor K`` it also measures the error floor of a per-frame model: for K evaluated
frames spread over the clip, the same motion up to that frame, then the pose held for
``--hold`` frames until the cloth settles; the distance between the moving garment and
the settled one at that pose is what no per-frame (quasi-static) model can learn.

Writes ``OUT/settings.md`` (also printed) and ``OUT/settings.json``.

Run: python bench/bench_sim_settings.py --mocap DIR [--bvh cmu-mb/05/05_02.bvh] [--start 1.0]
         [--seconds 1.5] [--vertices 3500] [--floor 2] [--hold 30] [--out out/sim_settings]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.datagen.mocap import MocapSpec, mocap_motion
from cloth_usd.datagen.floor import held_frames, held_motion
from cloth_usd.datagen.simulate import SimConfig, drape, edge_ratios, simulate, unique_edges

#: name -> SimConfig overrides of the default; the first is the reference.
SETTINGS = {
    "reference 80x6, full body": {"substeps": 80, "iterations": 6, "collider_faces": None},
    "default 40x3, 6000 faces": {},
    "20x3": {"substeps": 20, "iterations": 3},
    "40x3, no self-contact": {"self_contact": False},
    "40x3, 3000 faces": {"collider_faces": 3000},
    "40x3, full body": {"collider_faces": None},
    "40x3, full body, no self-contact": {"collider_faces": None, "self_contact": False},
    "Style3D 40x3, full body": {"solver": "style3d", "collider_faces": None},
    "Style3D 10x10, full body": {"solver": "style3d", "substeps": 10, "iterations": 10, "collider_faces": None},
    "Style3D 40x3, full body, no self-contact": {"solver": "style3d", "collider_faces": None, "self_contact": False},
}
DEFAULT = "default 40x3, 6000 faces"


def _row(name: str, r, ref, warmup: int, edges, rest) -> dict:
    x = r.positions[warmup:].astype(np.float64)
    row = {"setting": name, "s_per_frame": r.seconds_per_frame, "stable": bool(r.is_stable),
           "frames": int(r.frames_done), "failure": r.failure}
    if ref is not None and r.frames_done == ref.frames_done:
        d = np.linalg.norm(x - ref.positions[warmup:], axis=-1) * 1e3
        row.update(mean_mm=float(d.mean()), p95_mm=float(np.percentile(d, 95)))
    row["penetration"] = float(np.mean(r.penetration[warmup:]))
    ratio = edge_ratios(x, rest, edges)
    row["stretch_p99"] = float(np.median(np.percentile(ratio, 99, axis=1)))  # the median frame's
    row["stretch_max"] = float(ratio.max())
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", required=True, help="the mocap folder")
    ap.add_argument("--bvh", default="cmu-mb2_chrystianosaraujo-motion-viewer/05/05_02.bvh")
    ap.add_argument("--start", type=float, default=1.0, help="start in the clip [s]")
    ap.add_argument("--seconds", type=float, default=1.5, help="clip played [s] (after a 0.5 s ease)")
    ap.add_argument("--vertices", type=int, default=3500)
    ap.add_argument("--floor", type=int, default=2, help="evaluated frames whose settled pose is simulated")
    ap.add_argument("--hold", type=int, default=30, help="frames a pose is held to settle")
    ap.add_argument("--only", nargs="*", help="settings to run (names as printed; default all)")
    ap.add_argument("--out", default="out/sim_settings")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    body = load_body_model()
    betas = np.zeros(10)
    spec = MocapSpec(bvh=args.bvh, start_seconds=args.start, seconds=args.seconds, fps=30.0, ease_seconds=0.5,
                     ramp_seconds=0.25)
    motion = mocap_motion(spec, args.mocap, smpl_joints=shape_body(body, betas)[1])
    poses, transl, warmup = motion.poses, motion.transl, motion.warmup_frames
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=args.vertices))
    base = SimConfig(fps=30.0)
    t0 = time.perf_counter()
    rest, _ = drape(body, betas, verts, faces, base)
    print(f"{verts.shape[0]} vertices, {len(poses)} frames ({warmup} warm-up) of {args.bvh} from {args.start:g} s; "
          f"drape {time.perf_counter() - t0:.0f} s", flush=True)
    edges = unique_edges(faces)
    rows, ref = [], None
    names = [n for n in SETTINGS if not args.only or n in args.only or n.startswith(tuple(args.only))]
    for name in names:
        cfg = dataclasses.replace(base, **SETTINGS[name])
        t0 = time.perf_counter()
        r = simulate(body, betas, rest, faces, poses, transl, cfg)
        np.save(out / f"positions_{len(rows)}.npy", r.positions)  # a later failure keeps the runs done
        row = _row(name, r, ref, warmup, edges, rest)
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        if name == names[0]:
            ref = r
        print(json.dumps(row), flush=True)
        (out / "settings.json").write_text(json.dumps({"rows": rows}, indent=1))

    floor = []
    if args.floor > 0:
        for k in held_frames(len(poses), warmup, args.floor):
            r = simulate(body, betas, rest, faces, *held_motion(poses, transl, k, args.hold), base)
            moving, settled = r.positions[k].astype(np.float64), r.positions[-1].astype(np.float64)
            d = np.linalg.norm(moving - settled, axis=-1) * 1e3
            last = np.linalg.norm(r.positions[-1] - r.positions[-2], axis=-1).max() * 1e3
            floor.append({"frame": int(k), "mean_mm": float(d.mean()), "p95_mm": float(np.percentile(d, 95)),
                          "last_step_mm": float(last)})
            print(json.dumps(floor[-1]), flush=True)
    (out / "settings.json").write_text(json.dumps({"rows": rows, "floor": floor, "bvh": args.bvh,
                                                    "start": args.start, "vertices": int(verts.shape[0]),
                                                    "frames": len(poses), "warmup": warmup}, indent=1))
    default = next((r for r in rows if r["setting"] == DEFAULT), None)
    lines = [f"{verts.shape[0]}-vertex T-shirt, {args.bvh} from {args.start:g} s, {len(poses) - warmup} evaluated "
             "frames at 30 fps; error against the first row", "",
             "| setting | mean mm | p95 mm | inside body | stretch p99 / max | s/frame | time / default |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        ratio = r["s_per_frame"] / default["s_per_frame"] if default else float("nan")
        lines.append(f"| {r['setting']} | {r.get('mean_mm', 0.0):.2f} | {r.get('p95_mm', 0.0):.2f} | "
                     f"{100 * r['penetration']:.2f}% | {r['stretch_p99']:.3f} / {r['stretch_max']:.2f} | "
                     f"{r['s_per_frame']:.2f} | {ratio:.2f} |")
    if floor:
        lines += ["", "Per-frame error floor (the moving garment against the same pose held "
                  f"{args.hold} frames):", "", "| frame | mean mm | p95 mm | last held step mm |", "|---:|---:|---:|---:|"]
        lines += [f"| {f['frame']} | {f['mean_mm']:.2f} | {f['p95_mm']:.2f} | {f['last_step_mm']:.2f} |" for f in floor]
    text = "\n".join(lines) + "\n"
    (out / "settings.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
