"""Build models/garments/hm08_map.npz: where each vertex of MakeHuman's hm08 base mesh lies on
the embedded body (see cloth_usd/garments/mhclo.py), so `cloth-usd garment fit` can place
MakeHuman clothes by their .mhclo binding.

    python scripts/build_hm08_map.py BASE.obj [-o models/garments/hm08_map.npz]

BASE.obj: MakeHuman's base mesh (makehumancommunity/makehuman, makehuman/data/3dobjs/base.obj,
CC0). Prints how far hm08's skin lies from the fitted body.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys

import numpy as np

from cloth_usd.core.body import load_body_model
from cloth_usd.garments.mhclo import build_hm08_map, default_hm08_map_path, save_hm08_map


def read_base(path: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """hm08 vertices [dm] and each group's vertex numbers."""
    points, groups, group = [], collections.defaultdict(list), None
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("v "):
                points.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("g "):
                group = line.split()[1]
            elif line.startswith("f "):
                groups[group].extend(int(t.split("/")[0]) - 1 for t in line.split()[1:])
    return np.asarray(points), {k: np.unique(v) for k, v in groups.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("base", help="MakeHuman's base.obj (hm08)")
    parser.add_argument("-o", "--output", default=str(default_hm08_map_path()))
    args = parser.parse_args(argv)
    points, groups = read_base(args.base)
    hmap = build_hm08_map(points, groups, load_body_model())
    save_hm08_map(hmap, args.output)
    sys.stdout.write(json.dumps({"mapped": int(len(hmap.hm_index)), "distance_mm": hmap.distance_mm,
                                 "betas": np.round(hmap.betas, 3).tolist()}) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
