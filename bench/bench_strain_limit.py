"""Benchmark (not a test): the detail tier's strain limit against a Newton test set, setting by setting (issue #12).

For a bundle and the simulated test set ``--data``, the detail tier is run as ``cloth-usd
evaluate`` runs it (the models, the strain limiter, the push out of the body, the lift of its
triangles off the body), once per
``--setting`` ``LIMIT/ROUNDS[/ANCHOR]`` (:class:`~cloth_usd.core.postprocess.StrainLimiter`: the
longest an edge may be over its rest length, the rounds, the weight holding each vertex where the
models put it; default anchor :data:`~cloth_usd.core.postprocess.STRAIN_ANCHOR`); ``none`` runs it
without the limiter. The models run once per sequence; only the post-process is repeated. Prints,
per setting, the mean vertex distance to Newton's garment [mm] on the unseen bodies, the unseen
motions and all sequences (as ``cloth-usd evaluate`` splits them), each setting's mean over the
first setting's, and the post-process's wall time per frame. Writes ``OUT/strain_limit.md`` and
``OUT/strain_limit.json``.

Run: python bench/bench_strain_limit.py --data TESTSET --bundle B --setting 1.10/8 --setting 1.05/16
         [--setting none] [--out out/strain_limit]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model
from cloth_usd.core.pipeline import pose_body, post_process
from cloth_usd.core.postprocess import STRAIN_ANCHOR
from cloth_usd.errors import ArgumentError
from cloth_usd.evaluate import _SPLIT_TITLES, garment_reads, learned_garment
from cloth_usd.nn.data import load_dataset
from cloth_usd.runtime.bundle import load_bundle


def split_means(errors: dict) -> dict:
    """``{split title: mean [mm]}`` of per-frame mean vertex errors [m] (``errors``: split title -> the (T,)
    arrays of its sequences, as ``cloth-usd evaluate`` splits them; an empty split left out), and ``"all"``
    over every frame."""
    per = {s: 1e3 * float(np.concatenate(v).mean()) for s, v in errors.items() if v}
    per["all"] = 1e3 * float(np.concatenate([np.concatenate(v) for v in errors.values() if v]).mean())
    return per


def write_report(out: str | Path, stem: str, text: str, payload: dict) -> None:
    """Write ``OUT/STEM.md`` (``text``) and ``OUT/STEM.json`` (``payload``), and print ``text``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.md").write_text(text)
    (out / f"{stem}.json").write_text(json.dumps(payload, indent=1))
    print(text)


def parse_setting(text: str) -> tuple[float, int, float] | None:
    """``LIMIT/ROUNDS[/ANCHOR]`` as ``(limit, rounds, anchor)``; ``none``: None (no limiter)."""
    if text == "none":
        return None
    parts = text.split("/")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        limit, rounds = float(parts[0]), int(parts[1])
        anchor = float(parts[2]) if len(parts) == 3 else STRAIN_ANCHOR
    except ValueError:
        raise ArgumentError(f"--setting {text!r}: expected LIMIT/ROUNDS[/ANCHOR] (e.g. 1.05/16) or none") from None
    return limit, rounds, anchor


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="a simulated test set (cloth-usd datagen)")
    ap.add_argument("--bundle", required=True, help="a model bundle with a detail tier")
    ap.add_argument("--setting", action="append", required=True,
                    help="LIMIT/ROUNDS[/ANCHOR] or none (repeatable; the first is the reference)")
    ap.add_argument("--out", default="out/strain_limit")
    args = ap.parse_args(argv)
    settings = [(s, parse_setting(s)) for s in args.setting]
    body = load_body_model()
    data = load_dataset(args.data, body=body)
    bundle = load_bundle(args.bundle)
    reads = garment_reads(bundle, data.clips)
    errors = {name: {title: [] for title in _SPLIT_TITLES.values()} for name, _ in settings}
    seconds = {name: 0.0 for name, _ in settings}
    frames = 0
    for clip in data.clips:
        split = _SPLIT_TITLES.get(clip.split.value)  # the test splits, as cloth-usd evaluate titles them
        if split is None:
            continue
        learned = learned_garment(bundle, body, clip, reads)
        raw = learned.evaluate("detail", clip.poses, clip.transl, postprocess=False).points
        posed = pose_body(body, learned.pair, clip.poses, clip.transl)
        frames += len(raw)
        for name, setting in settings:
            limiter = None if setting is None else learned.strain_limiter(
                limit=setting[0], iterations=setting[1], anchor=setting[2])  # factored once a garment, as a bake does
            start = time.perf_counter()
            x = post_process(learned.pair, posed, raw, margin=learned.margin, limiter=limiter,
                             lift=learned.lift)[0]
            seconds[name] += time.perf_counter() - start
            errors[name][split].append(np.linalg.norm(x - clip.positions, axis=2).mean(axis=1))
        print(f"{clip.name}: " + ", ".join(f"{name} {1e3 * errors[name][split][-1].mean():.2f} mm"
                                         for name, _ in settings), flush=True)
    rows = []
    for name, _ in settings:
        rows.append({"setting": name, "mm": split_means(errors[name]),
                     "ms_per_frame": 1e3 * seconds[name] / max(frames, 1)})
    ref = rows[0]["mm"]["all"]
    columns = list(rows[0]["mm"])
    lines = [f"# Strain limit settings: bundle `{bundle.name}`, {frames} frames of `{Path(args.data).name}`", "",
             "| setting (limit / rounds / anchor) | " + " | ".join(f"{c} mm" for c in columns)
             + " | all / first setting | post-process ms/frame |",
             "|---|" + "---:|" * (len(columns) + 2)]
    for r in rows:
        lines.append(f"| {r['setting']} | " + " | ".join(f"{r['mm'][c]:.2f}" for c in columns)
                     + f" | {r['mm']['all'] / ref:.3f} | {r['ms_per_frame']:.1f} |")
    write_report(args.out, "strain_limit", "\n".join(lines) + "\n", {"bundle": bundle.name, "frames": frames,
                                                                      "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
