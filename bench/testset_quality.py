"""Report (not a test): the quality figures of a simulated data set, per split, from its shards.

For each split: sequences kept and rejected, evaluated frames (after each clip's warm-up),
the fraction of garment vertices inside the body (mean over frames, and the worst frame),
edge stretch against the rest garment (the median frame's 99th percentile, and the
largest edge of any frame), the simulation's seconds per frame; then the sequences whose
cloth lies furthest from the skinned garment (the largest vertex distance of any evaluated frame,
and that frame), with the largest share of the body the garment covers at rest that lies bare
(``SimConfig.max_bare``'s measure, which a data set made before the factory checked it was never
held to; past 0.1, a trouser leg has come off its thigh): the checks before it are of a simulation's
numbers, and a garment that left the body can pass them, so these are the frames to look at first
(``scripts/testset_frame.py DATA SEQUENCE FRAME`` and ``scripts/render_tiers.py --frame-file``);
then the per-frame error floor of the held poses (:func:`cloth_usd.datagen.floor.floor_report`).
Writes ``OUT/quality.md`` and ``OUT/quality.json`` (also printed).

Run: python bench/testset_quality.py DATA [--out DATA/report] [--furthest 8]
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from cloth_usd.core.mesh import vector_lengths
from cloth_usd.core.shards import Manifest
from cloth_usd.core.skinning import skin_garment
from cloth_usd.datagen.floor import FLOOR_SPLIT, floor_report
from cloth_usd.datagen.simulate import bare_shares, edge_ratios, unique_edges
from cloth_usd.nn.data import load_dataset


def furthest_from_skinning(clip, body) -> dict:
    """A sequence's largest vertex distance from the skinned garment [mm] over its evaluated frames,
    the frame (as ``cloth-usd evaluate`` counts them) and that frame's mean."""
    skinned = skin_garment(clip.pair.binding, clip.poses, clip.transl, body.parents)
    err = 1000.0 * vector_lengths(skinned - clip.positions.astype(np.float64))
    t = int(err.max(axis=1).argmax())
    return {"sequence": clip.name, "frame": t, "max_mm": float(err[t].max()), "frame_mean_mm": float(err[t].mean()),
            "sequence_mean_mm": float(err.mean())}


def bare_share(clip, body) -> dict:
    """A sequence's largest share of bare body (:func:`~cloth_usd.datagen.simulate.bare_shares`) over
    its evaluated frames, and that frame."""
    bare = bare_shares(body, clip.pair.betas, clip.rest_points, clip.pair.faces, clip.positions, clip.poses,
                       clip.transl)
    t = int(np.nanargmax(bare)) if np.isfinite(bare).any() else 0
    return {"bare_max": float(bare[t]), "bare_frame": t}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="a cloth-usd datagen folder")
    ap.add_argument("--out", help="report folder (default: DATA/report)")
    ap.add_argument("--furthest", type=int, default=8, help="sequences listed furthest from skinning (default 8)")
    args = ap.parse_args(argv)
    root = Path(args.data)
    out = Path(args.out) if args.out else root / "report"
    out.mkdir(parents=True, exist_ok=True)
    manifest = Manifest.read(root)
    acc: dict[str, dict] = defaultdict(lambda: defaultdict(list))
    for name, entry in sorted(manifest.sequences.items()):
        split = entry.get("meta", {}).get("split", "?")
        if split != FLOOR_SPLIT and entry.get("status") != "ok":
            acc[split]["rejected"].append(name)
    data = load_dataset(root)  # each kept sequence read once; the loader leaves the held poses of the floor out
    furthest = []
    for clip in data.clips:
        a = acc[clip.split.value]
        x = clip.positions.astype(np.float64)  # after the warm-up
        ratio = edge_ratios(x, clip.rest_points, unique_edges(clip.pair.faces))
        a["kept"].append(clip.name)
        a["frames"].append(x.shape[0])
        a["vertices"].append(clip.rest_points.shape[0])
        a["penetration"].extend(clip.penetration.tolist())
        a["stretch_p99"].extend(np.percentile(ratio, 99, axis=1).tolist())
        a["stretch_max"].append(float(ratio.max()))
        quality = manifest.sequences[clip.name].get("quality", {})
        a["s_per_frame"].append(float(quality.get("seconds_per_frame", np.nan)))
        furthest.append({**furthest_from_skinning(clip, data.body), **bare_share(clip, data.body)})
    furthest.sort(key=lambda r: -r["max_mm"])
    rows = []
    for split, a in sorted(acc.items()):
        pen = np.asarray(a["penetration"]) if a["penetration"] else np.zeros(1)
        rows.append({"split": split, "kept": len(a["kept"]), "rejected": len(a["rejected"]),
                     "rejected_names": a["rejected"], "frames": int(sum(a["frames"])),
                     "vertices": [int(min(a["vertices"], default=0)), int(max(a["vertices"], default=0))],
                     "penetration_mean": float(pen.mean()), "penetration_worst_frame": float(pen.max()),
                     "stretch_p99_median_frame": float(np.median(a["stretch_p99"])) if a["stretch_p99"] else 0.0,
                     "stretch_max": float(max(a["stretch_max"], default=0.0)),
                     "s_per_frame_median": float(np.nanmedian(a["s_per_frame"])) if a["s_per_frame"] else 0.0})
    floor = floor_report(root)
    lines = ["| split | kept | rejected | evaluated frames | vertices | inside body: mean / worst frame | "
             "stretch: median frame's p99 / max | s/frame |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['split']} | {r['kept']} | {r['rejected']} | {r['frames']} | "
                     f"{r['vertices'][0]}-{r['vertices'][1]} | {100 * r['penetration_mean']:.2f}% / "
                     f"{100 * r['penetration_worst_frame']:.2f}% | {r['stretch_p99_median_frame']:.3f} / "
                     f"{r['stretch_max']:.2f} | {r['s_per_frame_median']:.2f} |")
    if furthest:
        lines += ["", f"Furthest from the skinned garment ({min(args.furthest, len(furthest))} of {len(furthest)} "
                  "sequences; look at these frames first):", "",
                  "| sequence | frame | largest mm | that frame's mean mm | sequence mean mm | most bare (frame) |",
                  "|---|---:|---:|---:|---:|---:|"]
        lines += [f"| {f['sequence']} | {f['frame']} | {f['max_mm']:.1f} | {f['frame_mean_mm']:.1f} | "
                  f"{f['sequence_mean_mm']:.1f} | {100 * f['bare_max']:.1f}% ({f['bare_frame']}) |"
                  for f in furthest[:args.furthest]]
    if floor:
        lines += ["", "Per-frame error floor (moving garment against the same pose held until settled):", "",
                  "| sequence | frame | mean mm | p95 mm | max mm | last held step mm |", "|---|---:|---:|---:|---:|---:|"]
        lines += [f"| {f['sequence']} | {f['frame']} | {f['mean_mm']:.2f} | {f['p95_mm']:.2f} | {f['max_mm']:.2f} | "
                  f"{f['settle_mm']:.2f} |" for f in floor["frames"]]
        lines += ["", f"All held frames: mean {floor['mean_mm']:.2f} mm, p95 {floor['p95_mm']:.2f} mm."]
    text = "\n".join(lines) + "\n"
    (out / "quality.md").write_text(text)
    (out / "quality.json").write_text(json.dumps({"splits": rows, "furthest_from_skinning": furthest,
                                                        "floor": floor}, indent=1))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
