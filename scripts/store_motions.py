"""Write the CMU stretches that ``cloth-usd train-garment`` trains on by default.

    python scripts/store_motions.py MOCAP configs/own_garment_motions_v6.json -o models/motions/cmu_stretches.npz

MOCAP is the CMU BVH folder the list's ``bvh`` entries are relative to. Each stretch is
retargeted onto the embedded body model's mean shape, faced forward and eased in from the
rest pose, exactly as a data set config's ``bvh`` entry is (``cloth_usd.datagen.mocap``),
and stored in float32 with its name, warm-up and provenance (file, sha256, rig, frames).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cloth_usd.datagen.mocap import store_motions


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mocap", help="the CMU BVH folder")
    parser.add_argument("motions", help="a JSON list of bvh motion entries")
    parser.add_argument("-o", "--out", required=True, help="the .npz to write")
    args = parser.parse_args(argv)
    specs = json.loads(Path(args.motions).read_text())
    names = store_motions(specs, args.mocap, args.out)  # onto the embedded model's mean shape
    size = Path(args.out).stat().st_size
    sys.stdout.write(f"wrote {args.out}: {len(names)} stretches, {size / 1e6:.2f} MB\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
