"""Make a small test fixture from a BVH clip: some of its frames, fewer per second, one decimal.

    python tests/data/mocap/trim_bvh.py SOURCE.bvh OUT.bvh --first 1 --count 30 --step 4

The HIERARCHY is copied without its indentation; the MOTION keeps frames first,
first + step, ... (``count`` of them), the frame time grows by ``step`` and values keep
one decimal (0.1 degree, 0.1 file unit).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path


def trim(source: Path, out: Path, first: int, count: int, step: int) -> None:
    text = source.read_text().replace("\r\n", "\n")
    head, motion = re.split(r"^MOTION\s*$", text, maxsplit=1, flags=re.MULTILINE)
    lines = [ln for ln in motion.strip().split("\n") if ln.strip()]
    frame_time = float(lines[1].split(":")[1])
    rows = lines[2:][first:first + count * step:step]
    head = "\n".join(ln.strip() for ln in head.strip().split("\n"))
    body = "\n".join(" ".join(_short(float(v)) for v in row.split()) for row in rows)
    out.write_text(f"{head.rstrip()}\nMOTION\nFrames: {len(rows)}\nFrame Time: {frame_time * step:.7f}\n{body}\n")


def _short(v: float) -> str:
    s = f"{v:.1f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", type=Path)
    p.add_argument("out", type=Path)
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--count", type=int, default=30)
    p.add_argument("--step", type=int, default=4)
    a = p.parse_args()
    trim(a.source, a.out, a.first, a.count, a.step)
