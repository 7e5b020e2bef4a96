"""Build the sample scenes in samples/ (run once; the outputs are committed).

    python scripts/make_samples.py

Each sample is a character (an SMPL skeleton with betas and a walk) wearing a T-shirt
made by cloth_usd.datagen for that body, in the stage units and up axis named below.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from pxr import Usd

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

SAMPLES = {
    # name: (up axis, metres per unit, betas, frames, shirt)
    "walk_tshirt": ("Y", 1.0, [0.6, -0.4, 0.2], 96, TShirtParams()),
    "walk_tshirt_zup_cm": ("Z", 0.01, [-1.0, 1.2], 24, TShirtParams(sleeve=0.12, ease=0.02,
                                                                      target_vertices=3000)),
}


def build(name: str, out_dir: Path, start: float = 1001.0) -> Path:
    up, mpu, betas, frames, shirt = SAMPLES[name]
    body = load_body_model()
    betas = np.pad(np.asarray(betas, dtype=np.float64), (0, 10 - len(betas)))
    _, joints = shape_body(body, betas)
    poses, root_offset = walk_cycle(frames)
    times = start + np.arange(frames, dtype=np.float64)
    verts, faces = make_tshirt(body, betas, shirt)
    path = out_dir / name / "scene.usda"
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu, fps=24.0, start=times[0], end=times[-1])
    skel = author_skeleton(stage, "/Character/Skeleton", joint_positions=joints, betas=betas,
                           poses=poses, root_positions=joints[0] + root_offset, times=times)
    author_garment(stage, "/Character/Tshirt", points=verts, faces=faces, category="tshirt",
                   body_path=skel)
    stage.GetRootLayer().Save()
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default=Path(__file__).resolve().parents[1] / "samples", type=Path)
    parser.add_argument("names", nargs="*", default=list(SAMPLES))
    args = parser.parse_args()
    for name in args.names:
        print(build(name, args.out))


if __name__ == "__main__":
    main()
