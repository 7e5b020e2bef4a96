"""How closely a baked garment's sleeves follow the arms: for each frame of a baked shot,
the distance of every sleeve vertex to its arm's bone (shoulder to elbow, elbow to wrist,
as segments), against the same distance at rest.

    python scripts/measure_sleeves.py BAKED_SHOT.usda [--garment /Character/Tshirt] [--json OUT]

A sleeve vertex is one that lies, at rest, beyond its shoulder joint along the arm
(|x| > |x_shoulder| + 4 cm, the T-pose's arms are along +-X) and within 15 cm of its bone.
If the sleeves follow the arms, the distances stay as they were at rest.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from cloth_usd.core.body import lbs, load_body_model, shape_body
from cloth_usd.usd.read import garment_points_internal, open_stage, read_motion, read_scene

#: (shoulder, elbow, wrist) SMPL joints per side; +1 the left arm (+X), -1 the right.
ARMS = ((1.0, 16, 18, 20), (-1.0, 17, 19, 21))


def segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., N) distance of points (..., N, 3) to segments a-b (..., 1, 3)."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def arm_distance(points: np.ndarray, joints: np.ndarray, side: tuple) -> np.ndarray:
    """(T, N) distance of points (T, N, 3) to an arm's two bones (joints (T, J, 3))."""
    _, s, e, w = side
    upper = segment_distance(points, joints[:, None, s], joints[:, None, e])
    lower = segment_distance(points, joints[:, None, e], joints[:, None, w])
    return np.minimum(upper, lower)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("shot", help="a shot stage with the garment's cache composed (bake --shot)")
    parser.add_argument("--garment", default=None, help="garment prim (default: the first)")
    parser.add_argument("--json", help="write the figures here too")
    args = parser.parse_args(argv)
    stage = open_stage(args.shot)
    scene = read_scene(stage)
    garment = next(g for g in scene.garments if args.garment in (None, g.prim_path))
    character = next(c for c in scene.characters if c.prim_path == garment.body_path)
    times = np.arange(scene.stage.start_time_code, scene.stage.end_time_code + 1)
    motion = read_motion(stage, character, times)
    body = load_body_model()
    v, j = shape_body(body, character.betas)
    _, posed_joints = lbs(body, v, j, motion.poses, motion.root_position - j[0])
    points = np.stack([garment_points_internal(stage, garment.prim_path, float(t)) for t in times])
    rest = garment.rest_points
    report = {"shot": args.shot, "garment": garment.prim_path, "frames": int(len(times))}
    for side in ARMS:
        sign, s, e, w = side
        d_rest = arm_distance(rest[None], j[None], side)[0]
        sleeve = (sign * rest[:, 0] > sign * j[s, 0] + 0.04) & (d_rest < 0.15)
        if not sleeve.any():
            continue
        d = arm_distance(points[:, sleeve], posed_joints, side)
        change = np.abs(d - d_rest[sleeve][None])
        name = "left" if sign > 0 else "right"
        report[name] = {"sleeve_vertices": int(sleeve.sum()),
                        "rest_mm": {"p50": round(float(np.median(d_rest[sleeve])) * 1e3, 1),
                                    "max": round(float(d_rest[sleeve].max()) * 1e3, 1)},
                        "clip_mm": {"p50": round(float(np.median(d)) * 1e3, 1),
                                    "p95": round(float(np.percentile(d, 95)) * 1e3, 1),
                                    "max": round(float(d.max()) * 1e3, 1)},
                        "change_mm": {"p50": round(float(np.median(change)) * 1e3, 1),
                                      "p95": round(float(np.percentile(change, 95)) * 1e3, 1),
                                      "max": round(float(change.max()) * 1e3, 1)},
                        "wrist_travel_m": round(float(np.ptp(posed_joints[:, w], axis=0).max()), 2)}
    sys.stdout.write(json.dumps(report) + "\n")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
