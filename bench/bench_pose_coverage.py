"""Benchmark (not a test): how much of real motion lies outside the poses a bundle was trained on.

A bake warns when a frame poses a joint its models read more than 10 degrees outside the
range of Euler angles the bundle's training motions span (the manifest's
``training_data.poses``; ``cloth_usd.core.limits.pose_outliers``, the bake's own test). This
bench runs that test over every BVH clip of a mocap folder, retargeted at 30 fps onto the
mean body (the converter's synthetic first frame left out), and prints per bundle the share of
frames a bake would warn on, how many clips it warns on at more than half of their frames,
and the joint angles most often outside.

Run: python bench/bench_pose_coverage.py --mocap MOCAP --bundle B [--bundle B2 ...] [--exclude 05/05_01.bvh ...]
"""

from __future__ import annotations

import argparse
import collections
import functools
import sys
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.limits import POSE_MARGIN_DEG, pose_excess, poses_to_euler
from cloth_usd.core.smpl import JOINT_NAMES
from cloth_usd.errors import ClothUsdError
from cloth_usd.motion_import import bvh_motion
from cloth_usd.runtime.bundle import load_bundle


@functools.cache
def _mean_joints() -> np.ndarray:
    return shape_body(load_body_model(), np.zeros(1))[1]


def clip_poses(path: Path) -> np.ndarray:
    """(T, 72) the clip as ``import-motion`` reads it, at 30 fps onto the mean body (its synthetic
    T-pose frame left out)."""
    return bvh_motion(path, _mean_joints(), 30.0, None, None)[0]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", required=True, type=Path, help="a folder of BVH clips (searched recursively)")
    ap.add_argument("--bundle", action="append", required=True, help="a bundle folder (repeatable)")
    ap.add_argument("--exclude", action="append", default=[],
                    help="leave out the clips whose path ends so, e.g. 05/05_01.bvh (repeatable)")
    args = ap.parse_args(argv)
    bundles = [load_bundle(b) for b in args.bundle]
    names = list(args.bundle)
    limits = []
    for name, b in zip(names, bundles):
        if b.pose_limits is None:
            sys.stderr.write(f"{name}: its manifest records no trained pose range (the bake checks fixed limits)\n")
            return 2
        limits.append(b.pose_limits)
    files = sorted(p for p in args.mocap.rglob("*.bvh") if not any(p.as_posix().endswith(e) for e in args.exclude))
    if not files:
        sys.stderr.write(f"--mocap {args.mocap}: no .bvh file under it (links to folders are not followed)\n")
        return 2
    shares = [[] for _ in bundles]  # per clip, the share of its frames warned on
    warned = [0 for _ in bundles]
    counts = [collections.Counter() for _ in bundles]
    frames, skipped = 0, []
    for path in files:
        try:
            euler = poses_to_euler(clip_poses(path))
        except (ClothUsdError, ValueError) as exc:
            skipped.append(f"{path.relative_to(args.mocap)} ({exc})")
            continue
        frames += len(euler)
        for k, lim in enumerate(limits):
            excess = pose_excess(euler, lim) > np.deg2rad(POSE_MARGIN_DEG)  # the bake's test (pose_outliers)
            outside = excess.any(axis=(1, 2))
            shares[k].append(outside.mean())
            warned[k] += int(outside.sum())
            for j, a in zip(*np.nonzero(excess.any(axis=0))):
                counts[k][f"{JOINT_NAMES[j + 1]} {'xyz'[a]}"] += int(excess[:, j, a].sum())
    if not frames:
        sys.stderr.write(f"--mocap {args.mocap}: none of its {len(files)} .bvh files could be read: {skipped[0]}\n")
        return 2
    print(f"{len(shares[0])} clips, {frames} frames at 30 fps under {args.mocap}"
          + (f"; {len(skipped)} unread: {'; '.join(skipped)}" if skipped else ""))
    print("| bundle | frames a bake warns on | clips warned on at more than half their frames | most often outside |")
    print("|---|---:|---:|---|")
    for name, share, n, count in zip(names, shares, warned, counts):
        share = np.asarray(share)
        top = ", ".join(f"{jk} {c / frames:.0%}" for jk, c in count.most_common(4)) or "-"
        print(f"| {name} | {n / frames:.1%} | {int((share > 0.5).sum())} of {len(share)} | {top} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
