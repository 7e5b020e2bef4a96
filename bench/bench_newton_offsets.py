"""Benchmark (not a test): how far Newton's own garment goes from the skinned garment (#12, the guard).

The run-time guard (:mod:`cloth_usd.core.guard`) calls a learned frame "not a garment" when a
vertex, or its median vertex, is too far from where skinning puts it. A limit that Newton's own
cloth breaks would replace frames a perfect model makes. This bench measures Newton's frames
against skinning (the garment as the learned tiers read it, skinned with its binding: the base
a garment's own model adds its displacement to), per frame after each sequence's warm-up: the
distance of the farthest vertex, of the 99th, 95th and 90th percentile vertex and of the median
vertex, and the share of frames each limit of the guard (``--limits``, the largest vertex's) and
its median limit would replace.

Inputs: ``--work`` a ``train-garment`` work folder (its ``data.json`` plans the training
sequences, its ``testset.json`` the test set's), ``--sim-data`` the ``cloth-usd datagen`` folder
of its ``hybrid.json``, ``--test-data`` the test set simulated from its ``testset.json``. Writes
``OUT/newton_offsets.md`` (also printed) and ``OUT/newton_offsets.json``.

Run: python bench/bench_newton_offsets.py --work WORK --sim-data H60 --test-data TSS --mocap MOCAP
         [--limits 0.15,0.5] [--out out/newton_offsets]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model
from cloth_usd.core.garment_inputs import skin_parts
from cloth_usd.core.guard import guard_limits
from cloth_usd.errors import ClothUsdError
from cloth_usd.nn.garment_model import _first
from cloth_usd.nn.physics_train import physics_set

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_sim_scaling import add_data_arguments, missing_data  # noqa: E402  (the same inputs, checked alike)

#: Vertex quantiles of a frame's distances reported (1.0: the farthest vertex).
QUANTILES = (1.0, 0.99, 0.95, 0.9, 0.5)


def frame_offsets(clip, body) -> np.ndarray:
    """(T', len(QUANTILES)) a simulated sequence's per-frame vertex-distance quantiles from skinning
    [m], over the frames after its warm-up."""
    frames = np.arange(_first(clip), clip.num_frames)
    skinned = skin_parts(clip.pair.binding, clip.poses[frames], clip.transl[frames], body.parents).base
    distance = np.linalg.norm(skinned - np.asarray(clip.target, dtype=np.float64)[frames], axis=-1)
    return np.quantile(distance, QUANTILES, axis=1).T


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_arguments(ap)
    ap.add_argument("--limits", default="0.15,0.5", help="largest-vertex limits [m] to count frames past, "
                    "comma separated")
    ap.add_argument("--out", type=Path, default=Path("out/newton_offsets"))
    a = ap.parse_args(argv)
    try:
        limits = [float(x) for x in a.limits.split(",")]
    except ValueError:
        ap.error(f"--limits takes comma-separated numbers [m], got {a.limits!r}")
    if missing_data(a, "bench_newton_offsets"):
        return 2
    body = load_body_model()
    rows, summary, median_limit = [], {}, None
    for name, config, sim in (("training", a.work / "data.json", a.sim_data),
                              ("test", a.work / "testset.json", a.test_data)):
        try:
            clips = [c for c in physics_set(config, body, mocap_dir=a.mocap, sim_data=sim).clips
                     if c.target is not None]
        except ClothUsdError as exc:
            print(f"bench_newton_offsets: {exc}", file=sys.stderr)
            return 2
        if not clips:
            print(f"bench_newton_offsets: {sim} holds no simulated sequence of {config}", file=sys.stderr)
            return 2
        median_limit = guard_limits(clips[0].meta.get("category", "tshirt")).median_offset  # the garment's
        per = {c.name: frame_offsets(c, body) for c in clips}
        q = np.concatenate(list(per.values()))
        past = [float((q[:, 0] > x).mean()) for x in limits]
        past_median = float((q[:, -1] > median_limit).mean())
        summary[name] = {"sequences": len(clips), "frames": int(len(q)),
                         "quantiles": list(QUANTILES), "p99_mm": (1e3 * np.percentile(q, 99, axis=0)).tolist(),
                         "max_mm": (1e3 * q.max(axis=0)).tolist(), "past": dict(zip(map(str, limits), past)),
                         "past_median": past_median,
                         "per_sequence_max_mm": {k: float(1e3 * v[:, 0].max()) for k, v in per.items()}}
        cells = " | ".join(f"{1e3 * np.percentile(q[:, i], 99):.0f} / {1e3 * q[:, i].max():.0f}"
                           for i in range(len(QUANTILES)))
        rows.append(f"| {name} | {len(clips)} | {len(q)} | {cells} | "
                    + " | ".join(f"{100 * p:.1f}%" for p in past) + f" | {100 * past_median:.1f}% |")
    lines = ["# Newton's garment against skinning", "",
             f"Per frame after the warm-up: the distance [mm] of the farthest vertex, of the 99th, 95th and 90th "
             f"percentile vertex and of the median one; the largest over the frames and the 99th percentile of the "
             f"frames. The guard's median limit for this garment's category: {1e3 * median_limit:g} mm.", "",
             "| data | sequences | frames | " + " | ".join(f"q{q:g}: p99 / max" for q in QUANTILES) + " | "
             + " | ".join(f"frames past {1e3 * x:g} mm" for x in limits) + " | frames past the median limit |",
             "|---|---:|---:|" + "---:|" * (len(QUANTILES) + len(limits) + 1), *rows]
    text = "\n".join(lines) + "\n"
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "newton_offsets.md").write_text(text)
    (a.out / "newton_offsets.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
