"""Benchmark (not a test): how the skinning binding of a lower garment tears between the legs (issue #17).

For each garment stage (``--garment``, repeatable) worn over a real clip (``--clip``: brought
in with ``cloth-usd import-motion``), the garment is bound to the body
(:func:`cloth_usd.core.skinning.bind_garment`) with every ``--free`` threshold (``none``:
each vertex takes its nearest body point's weights; a number [m]: vertices farther than
that from the body take the harmonic blend of the others' weights over the garment) and
skinned over every frame. Per garment and threshold: each frame's 99th percentile and
maximum of edge length over the rest garment's, then the median frame's p99, the worst
frame's p99 and the largest edge of all; and the same over the edges whose midpoint lies
within 5 cm of the body's midline plane (x = 0) below the hips, where the crotch or the
skirt hangs between the legs.

Run: python bench/bench_binding.py --mocap MOCAP --clip cmu-daz_Przestr-motion-capture/10/10_04.bvh
         --garment samples/walk_trousers/trousers.usda [--garment ...] [--free none 0.005 0.01 0.02]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.frames import canonical_motion
from cloth_usd.core.skinning import bind_garment, skin_garment
from cloth_usd.datagen.simulate import unique_edges
from cloth_usd.usd.read import open_stage, read_motion, read_scene

CLI = [sys.executable, "-m", "cloth_usd.cli"]


def _stats(stretch: np.ndarray) -> tuple[float, float, float]:
    """(T, E) stretch -> median frame's p99, worst frame's p99, largest."""
    p99 = np.percentile(stretch, 99, axis=1)
    return float(np.median(p99)), float(p99.max()), float(stretch.max())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", required=True, help="the mocap folder")
    ap.add_argument("--clip", required=True, help="FILE[:A:B] under --mocap (file frames A..B)")
    ap.add_argument("--garment", action="append", required=True, help="a stage with one garment (repeatable)")
    ap.add_argument("--free", nargs="+", default=["none", "0.005", "0.01", "0.02", "0.04"],
                    help="free_beyond thresholds [m], or none")
    args = ap.parse_args(argv)
    body = load_body_model()
    name, *frames = args.clip.split(":")
    lines = ["| garment | free beyond | stretch p99 median frame / worst frame, max | between the legs: same |",
             "|---|---:|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for i, garment_stage in enumerate(args.garment):
            shot = Path(tmp) / f"shot{i}.usda"
            extra = ["--frames", f"{frames[0]}:{frames[1]}"] if frames else []
            subprocess.run([*CLI, "import-motion", str(Path(args.mocap) / name), "-o", str(shot), "--garment",
                            str(Path(garment_stage).resolve()), *extra], check=True, capture_output=True)
            stage = open_stage(shot)
            scene = read_scene(stage)
            garment, char = scene.garments[0], scene.characters[0]
            times = np.arange(stage.GetStartTimeCode(), stage.GetEndTimeCode() + 1)
            joints = shape_body(body, char.betas)[1]
            motion = canonical_motion(char, read_motion(stage, char, times), joints)  # as the baker reads it
            rest = motion.rest_points(garment.rest_points)
            poses, transl = motion.poses, motion.transl
            edges = unique_edges(garment.triangles)
            mid = 0.5 * (rest[edges[:, 0]] + rest[edges[:, 1]])
            legs = (np.abs(mid[:, 0] - joints[0, 0]) < 0.05) & (mid[:, 1] < joints[0, 1])
            rest_len = np.linalg.norm(rest[edges[:, 1]] - rest[edges[:, 0]], axis=1)
            for free in args.free:
                threshold = None if free == "none" else float(free)
                binding = bind_garment(body, char.betas, rest, faces=garment.triangles, free_beyond=threshold)
                pts = skin_garment(binding, poses, transl, body.parents)
                length = np.linalg.norm(pts[:, edges[:, 1]] - pts[:, edges[:, 0]], axis=-1)
                stretch = length / np.maximum(rest_len, 1e-4)
                a, b = _stats(stretch), _stats(stretch[:, legs]) if legs.any() else (np.nan,) * 3
                lines.append(f"| {Path(garment_stage).stem} | {free} | {a[0]:.3f} / {a[1]:.3f}, {a[2]:.2f} | "
                             f"{b[0]:.3f} / {b[1]:.3f}, {b[2]:.2f} |")
                print(lines[-1], flush=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
