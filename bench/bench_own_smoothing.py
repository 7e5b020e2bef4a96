"""Benchmark (not a test): a garment's own bundle with its model's displacement smoothed, pass count by pass count,
against a Newton test set (issue #12).

A garment's own model (``cloth-usd train-garment``) gives every vertex its own displacement, and its error from
vertex to vertex shows as a dimpled grain over the garment in a close-up; the runtime smooths the displacement's
part along the rest garment's normals with Taubin passes (:data:`~cloth_usd.core.pipeline.OWN_SMOOTHING`,
:func:`~cloth_usd.core.pipeline.smooth_along_normals`) before skinning it. For each ``--passes K``
(the first is the reference) the coarse and the detail tier are run as ``cloth-usd evaluate`` runs them (the
post-process included) on every test sequence of ``--data``, and the bench prints, per tier and pass count:

- the mean vertex distance to Newton's garment [mm] on each split (as ``cloth-usd evaluate`` splits them) and on
  all, and all over the first pass count's;
- grain: the mean distance of a vertex of the models' garment, before the post-process, from the mean of its
  neighbours [mm], beside Newton's own garment's (a smooth garment keeps its curvature's share of it);
- the smoothing's wall time per frame [ms].

Writes ``OUT/own_smoothing.md`` and ``OUT/own_smoothing.json``.

Run: python bench/bench_own_smoothing.py --data TESTSET --bundle OWN_BUNDLE --passes 0 --passes 2 [--passes 4]
         [--out out/own_smoothing]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model
from cloth_usd.core.features import vertex_normals
from cloth_usd.core.mesh import laplacian_smooth, neighbour_mean
from cloth_usd.core.pipeline import smooth_along_normals
from cloth_usd.evaluate import _SPLIT_TITLES, garment_reads, learned_garment
from cloth_usd.nn.data import load_dataset
from cloth_usd.runtime.bundle import load_bundle

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_strain_limit import split_means, write_report  # noqa: E402  (its per-split means and files, alike)

TIERS = ("coarse", "detail")


def grain(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(T,) each frame's mean distance [m] of a vertex of ``points`` (T, N, 3) from the mean of its neighbours."""
    return np.linalg.norm(points - laplacian_smooth(points, faces, iterations=1, lam=1.0), axis=2).mean(axis=1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="a simulated test set (cloth-usd datagen)")
    ap.add_argument("--bundle", required=True, help="a garment's own bundle (cloth-usd train-garment)")
    ap.add_argument("--passes", action="append", type=int, required=True,
                    help="Taubin passes over the model's displacement (repeatable; the first is the reference)")
    ap.add_argument("--out", default="out/own_smoothing")
    args = ap.parse_args(argv)
    if any(k < 0 for k in args.passes):
        ap.error("--passes must be >= 0")
    body = load_body_model()
    data = load_dataset(args.data, body=body)
    bundle = load_bundle(args.bundle)
    if bundle.garment is None:
        ap.error(f"--bundle {args.bundle}: not a garment's own bundle (only their displacement is smoothed)")
    reads = garment_reads(bundle, data.clips)
    errors = {(k, t): {title: [] for title in _SPLIT_TITLES.values()} for k in args.passes for t in TIERS}
    grains = {(k, t): [] for k in args.passes for t in TIERS}
    newton_grain, seconds, frames = [], {k: 0.0 for k in args.passes}, 0
    for clip in data.clips:
        split = _SPLIT_TITLES.get(clip.split.value)
        if split is None:
            continue
        frames += len(clip.poses)
        faces = clip.pair.faces
        newton_grain.append(grain(clip.positions, faces))
        for k in args.passes:
            learned = learned_garment(bundle, body, clip, reads, smoothing=k)
            for tier in TIERS:
                raw = learned.evaluate(tier, clip.poses, clip.transl, postprocess=False).points
                grains[k, tier].append(grain(raw, faces))
                x = learned.evaluate(tier, clip.poses, clip.transl).points
                errors[k, tier][split].append(np.linalg.norm(x - clip.positions, axis=2).mean(axis=1))
            if k:  # the smoothing alone, as run_garment_model runs it (its neighbour means and normals made once)
                d = np.zeros((len(clip.poses), len(clip.rest_points), 3))
                mean, normals = neighbour_mean(faces, len(clip.rest_points)), vertex_normals(clip.rest_points, faces)
                start = time.perf_counter()
                smooth_along_normals(d, normals, faces, k, mean=mean)
                seconds[k] += time.perf_counter() - start
        print(f"{clip.name}: " + ", ".join(f"{k} passes {t} {1e3 * errors[k, t][split][-1].mean():.2f} mm"
                                         for k in args.passes for t in TIERS), flush=True)
    rows = []
    for k in args.passes:
        for t in TIERS:
            rows.append({"passes": k, "tier": t, "mm": split_means(errors[k, t]),
                         "grain_mm": 1e3 * float(np.concatenate(grains[k, t]).mean()),
                         "ms_per_frame": 1e3 * seconds[k] / max(frames, 1)})
    ref = {r["tier"]: r["mm"]["all"] for r in rows if r["passes"] == args.passes[0]}
    columns = list(rows[0]["mm"])
    newton = 1e3 * float(np.concatenate(newton_grain).mean())
    lines = [f"# Own model smoothing: bundle `{bundle.name}`, {frames} frames of `{Path(args.data).name}`", "",
             f"Newton's garment: grain {newton:.2f} mm.", "",
             "| passes | tier | " + " | ".join(f"{c} mm" for c in columns)
             + " | all / first | grain mm (before the post-process) | smoothing ms/frame |",
             "|---:|---|" + "---:|" * (len(columns) + 3)]
    for r in rows:
        lines.append(f"| {r['passes']} | {r['tier']} | " + " | ".join(f"{r['mm'][c]:.2f}" for c in columns)
                     + f" | {r['mm']['all'] / ref[r['tier']]:.3f} | {r['grain_mm']:.2f} | {r['ms_per_frame']:.2f} |")
    write_report(args.out, "own_smoothing", "\n".join(lines) + "\n",
                 {"bundle": bundle.name, "frames": frames, "newton_grain_mm": newton, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
