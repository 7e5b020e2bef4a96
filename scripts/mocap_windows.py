"""Write a datagen config whose training motions are windows cut from every clip of a mocap folder.

Each BVH clip under ``--mocap`` gives up to ``--per-clip`` windows of ``--seconds`` (3 s by
default, 0.5 s in, one after another); a clip too short for one gives a single window of
``--short-seconds`` (2 s), and one too short for that (CMU's one-second runs) a window of 1.1 s
whose root movement ramps in. Clips named with ``--exclude`` (path suffixes, repeatable) are
left out: the test motions and the held-out clips of the benchmarks. Every other field comes
from ``--base``, a datagen config (its ``train_motions`` are replaced).

Run: python scripts/mocap_windows.py --mocap MOCAP --base configs/datagen_testset.json \
         --exclude 05/05_02.bvh ... -o configs/datagen_gpu_tshirt.json
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path


def clip_seconds(path: Path) -> float:
    """A BVH clip's length [s] from its MOTION header (frames x frame time)."""
    text = path.read_text(errors="replace")
    frames = re.search(r"^Frames:\s*(\d+)", text, re.M)
    step = re.search(r"^Frame Time:\s*([0-9.eE+-]+)", text, re.M)
    if not frames or not step:
        raise SystemExit(f"{path}: no 'Frames:' / 'Frame Time:' header (not a BVH clip?)")
    return int(frames.group(1)) * float(step.group(1))


def windows(rel: str, seconds: float, *, length: float, short: float, per_clip: int) -> list[dict]:
    """The motion entries cut from one clip ``seconds`` long."""
    out = []
    start = 0.5
    while len(out) < per_clip and start + length <= seconds - 0.1:
        out.append({"bvh": rel, "start_seconds": round(start, 2), "seconds": length})
        start += length
    if not out and short + 0.3 <= seconds:
        out.append({"bvh": rel, "start_seconds": 0.2, "seconds": short})
    if not out and seconds >= 1.15:
        out.append({"bvh": rel, "start_seconds": 0.0, "seconds": 1.1, "ramp_seconds": 0.25})
    return out


def _without_glitches(motions: list[dict], base: dict, root: Path) -> tuple[list[dict], list[str]]:
    """The windows the factory accepts: those whose retargeted body never jumps (a capture
    glitch, refused by ``cloth-usd datagen``), and the labels of those dropped."""
    import numpy as np

    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.datagen.factory import FactoryConfig, _motion
    from cloth_usd.errors import ClothUsdError

    body = load_body_model()
    # What a motion is read with: the clips' folder and the base's frame limit.
    config = FactoryConfig(mocap_dir=str(root), max_frames=base.get("max_frames"))
    joints = shape_body(body, np.zeros(1))[1]
    kept, dropped = [], []
    for i, m in enumerate(motions):
        try:
            _motion(m, config, f"train_motions[{i}]", joints, body)
        except ClothUsdError:  # a glitch, or a window the reader finds past the clip's end
            dropped.append(f"{m['bvh']}@{m['start_seconds']:g}s")
            continue
        kept.append(m)
    return kept, dropped


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mocap", required=True, help="the mocap folder (BVH clips, any depth)")
    ap.add_argument("--base", required=True, help="datagen config whose other fields the output keeps")
    ap.add_argument("--exclude", action="append", default=[], help="clip path suffix to leave out (repeatable)")
    ap.add_argument("--seconds", type=float, default=3.0, help="window length [s] (default 3)")
    ap.add_argument("--short-seconds", type=float, default=2.0, help="the one window of a shorter clip [s]")
    ap.add_argument("--per-clip", type=int, default=4, help="windows at most per clip (default 4)")
    ap.add_argument("--min-seconds", type=float, default=1.0, help="skip clips shorter than this [s]")
    ap.add_argument("-o", "--output", required=True, help="the config to write (.json)")
    args = ap.parse_args(argv)
    root = Path(args.mocap)
    base = json.loads(Path(args.base).read_text())
    motions, used, skipped = [], 0, []
    for path in sorted(root.rglob("*.bvh")):
        rel = path.relative_to(root).as_posix()
        seconds = clip_seconds(path)
        if any(rel.endswith(e) for e in args.exclude) or seconds < args.min_seconds:
            skipped.append(rel)
            continue
        cut = windows(rel, seconds, length=args.seconds, short=args.short_seconds, per_clip=args.per_clip)
        used += bool(cut)
        motions += cut
    motions, glitched = _without_glitches(motions, base, root)
    base["train_motions"] = motions
    Path(args.output).write_text(json.dumps(base, indent=1) + "\n")
    sys.stdout.write(f"{len(motions)} windows from {used} clips ({len(skipped)} left out: {', '.join(skipped)}; "
                     f"{len(glitched)} windows dropped (the body jumps, or past the end): {', '.join(glitched)}) "
                     f"-> {args.output}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
