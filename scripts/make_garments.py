"""Make every preset garment (9 T-shirts, 6 dresses, 6 trousers) and tabulate how well
each was sewn: one `cloth-usd garment make` per garment, run in this process so Newton
starts once.

    OMP_NUM_THREADS=1 python scripts/make_garments.py --out out/garments [--vertices 3500]
        [--only tshirt/classic dress/a-line ...]

Writes OUT/<category>_<preset>.usda and .json, and OUT/table.md (the README's table).
Bodies vary with the category so that the patterns are drafted for different shapes.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from cloth_usd.cli import main as cli
from cloth_usd.garments import PRESETS

#: The body each category is made for (betas).
BODIES = {"tshirt": ["0.6", "-0.4", "0.2"], "dress": ["-0.5", "0.8"], "trousers": ["1.0", "0.3"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("out/garments"))
    parser.add_argument("--vertices", type=int, default=3500)
    parser.add_argument("--only", nargs="*", help="CATEGORY/PRESET to make, in this order (default all)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    every = [f"{c}/{p}" for c, presets in PRESETS.items() for p in presets]
    for item in args.only or every:
        if item not in every:
            sys.exit(f"--only {item}: no such preset (valid: {', '.join(every)})")
        category, preset = item.split("/")
        stem = args.out / f"{category}_{preset}"
        argv = ["garment", "make", category, "--preset", preset, "--betas", *BODIES[category],
                "--vertices", str(args.vertices), "-o", f"{stem}.usda", "--report", f"{stem}.json", "--force"]
        print("cloth-usd " + shlex.join(argv), flush=True)
        if cli(argv) != 0:
            sys.exit(f"failed: {category} {preset}")
    # The table holds every garment made into OUT so far, in preset order.
    rows = [json.loads((args.out / f"{e.replace('/', '_')}.json").read_text()) for e in every
            if (args.out / f"{e.replace('/', '_')}.json").exists()]
    lines = ["| garment | panels | vertices | stretch p50 | stretch p99 | stretch max | skin through at rest: "
             "before the lift -> after | time [s] |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        through = f"{r['skin_through_before']} -> {r['skin_through']}" if "skin_through" in r else "-"
        lines.append(f"| {r['category']} {r['preset']} | {r['panels']} | {r['vertices']} | {r['stretch_p50']:.3f} | "
                     f"{r['stretch_p99']:.3f} | {r['stretch_max']:.3f} | {through} | {r['seconds']:.0f} |")
    (args.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
