"""Benchmark (not a test): peak memory of a long bake (issue #6: under 1 GB).

Authors a stage with a walking character in a ~4000-vertex T-shirt (default 300 frames),
then bakes it in a fresh subprocess and prints that process's peak resident set size
(``ru_maxrss``), next to the peak of a process that only imports cloth_usd and pxr and
bakes one frame (the fixed cost), and the cache size.

Run: python bench/bench_memory.py [--frames 300] [--vertices 4000] [--tier skinning] [--models DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: Runs in the child: bake, then report its own peak RSS [MiB] (Linux: ru_maxrss is KiB).
CHILD = """
import json, resource, sys, time
from cloth_usd.baking import bake
began = time.perf_counter()
result = bake(sys.argv[1], sys.argv[2], frames=sys.argv[3], tier=sys.argv[4], models=sys.argv[5] or None,
              force=True)
print(json.dumps({"peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "seconds": time.perf_counter() - began,
                  "vertices": result.garments[0].vertices, "frames": int(result.times.shape[0])}))
"""


def author(path: Path, frames: int, vertices: int) -> None:
    from pxr import Usd

    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
    from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

    body = load_body_model()
    betas = np.zeros(10)
    betas[:3] = [0.6, -0.4, 0.2]
    _, joints = shape_body(body, betas)
    points, faces = make_tshirt(body, betas, TShirtParams(target_vertices=vertices))
    poses, root = walk_cycle(frames)
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, start=1001, end=1000 + frames)
    skel = author_skeleton(stage, "/Character/Skeleton", joint_positions=joints, betas=betas, poses=poses,
                           root_positions=joints[0] + root, times=1001.0 + np.arange(frames))
    author_garment(stage, "/Character/Tshirt", points=points, faces=faces, body_path=skel)
    stage.GetRootLayer().Save()


def measure(scene: Path, cache: Path, frames: str, tier: str, models: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(cache), frames, tier, models],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--vertices", type=int, default=4000, help="target T-shirt vertex count")
    parser.add_argument("--tier", default="skinning")
    parser.add_argument("--models", default="", help="model bundle folder for the coarse and detail tiers")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene, cache = Path(tmp) / "scene.usdc", Path(tmp) / "cache.usdc"
        author(scene, args.frames, args.vertices)
        base = measure(scene, Path(tmp) / "one.usdc", "1001:1001", args.tier, args.models)
        full = measure(scene, cache, f"1001:{1000 + args.frames}", args.tier, args.models)
        size = cache.stat().st_size / 2**20
    print(f"{full['frames']}-frame {args.tier} bake of a {full['vertices']}-vertex shirt: "
          f"peak RSS {full['peak_rss_mib']:.0f} MiB ({full['seconds']:.1f} s); "
          f"a 1-frame bake peaks at {base['peak_rss_mib']:.0f} MiB; cache {size:.1f} MiB")
    print("under 1 GiB" if full["peak_rss_mib"] < 1024 else "OVER 1 GiB")


if __name__ == "__main__":
    main()
