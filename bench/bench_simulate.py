"""Frames per second of the ground-truth simulation (Newton VBD, self-contact, body collider).

    python bench/bench_simulate.py [--vertices 3500] [--frames 3] [--substeps 40] [--iterations 3]

Runs on CUDA when present (and prints that number), otherwise on the CPU. The first
simulated frame loads/compiles kernels and is excluded; frame 0 is the rest state.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cloth_usd.core.body import load_body_model
from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
from cloth_usd.datagen.simulate import SimConfig, resolve_device, simulate


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=int, default=3500)
    ap.add_argument("--frames", type=int, default=3, help="timed frames after the warm-up frame")
    ap.add_argument("--substeps", type=int, default=40)
    ap.add_argument("--iterations", type=int, default=3)
    ap.add_argument("--collider-faces", type=int, default=6000, help="0: the full body mesh")
    ap.add_argument("--device", default="auto")
    args = ap.parse_args(argv)
    body = load_body_model()
    betas = np.zeros(10)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=args.vertices))
    poses, root = walk_cycle(max(24, args.frames + 2))
    n = args.frames + 2  # rest frame + warm-up frame + timed frames
    cfg = SimConfig(substeps=args.substeps, iterations=args.iterations, device=args.device,
                    collider_faces=args.collider_faces or None)
    start = time.perf_counter()
    r = simulate(body, betas, verts, faces, poses[:n], root[:n], cfg)
    total = time.perf_counter() - start
    print(f"device {resolve_device(args.device)}: {verts.shape[0]} garment vertices, {faces.shape[0]} triangles, "
          f"collider {args.collider_faces or 'full'} faces, {args.substeps}x{args.iterations}")
    print(f"  warm: {r.seconds_per_frame * 1e3:.0f} ms/frame = {1.0 / max(r.seconds_per_frame, 1e-9):.2f} frames/s "
          f"(mean of {max(r.frames_done - 2, 1)} frames); total incl. setup/compile {total:.1f} s")
    print(f"  stable {r.is_stable}; penetration {np.round(r.penetration, 3).tolist()}; "
          f"max stretch {np.round(r.max_stretch, 3).tolist()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
