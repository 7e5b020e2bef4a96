"""One frame of a simulated test sequence, as every tier makes it and as Newton simulated it,
for a side-by-side close-up (``scripts/render_tiers.py --frame-file``).

    .venv/bin/python scripts/testset_frame.py DATA SEQUENCE FRAME -o FRAME.npz \\
        [--bundle models/bundles/tshirt-v6 [--bundle B2 ...]] [--tiers coarse,detail] [--repeat DATA2]

DATA is a ``cloth-usd datagen`` folder (the test set), SEQUENCE a name from its manifest (or a
unique part of one), FRAME an evaluated frame (after the warm-up, as ``cloth-usd evaluate``
counts). The file holds the posed body and, per panel, the garment points (skinning, each
bundle's tiers, Newton; with several bundles a panel is named after its bundle and tier); the
script prints each panel's error against Newton at that frame. ``--repeat`` adds a last panel,
"Newton, again": the same sequence of a second simulation of the test set config
(``bench/bench_newton_repeat.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str]) -> int:
    from cloth_usd.core.body import load_body_model, posed_vertices
    from cloth_usd.core.skinning import skin_garment
    from cloth_usd.nn.data import load_dataset
    from cloth_usd.runtime.bundle import load_bundle
    from cloth_usd.evaluate import garment_reads, learned_garment

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data")
    ap.add_argument("sequence")
    ap.add_argument("frame", type=int)
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--bundle", action="append", help="a bundle (repeatable; default models/bundles/tshirt-v6)")
    ap.add_argument("--tiers", default="coarse,detail", help="the learned tiers to show (default coarse,detail)")
    ap.add_argument("--repeat", help="a second simulation of the same config: its frame is a last panel")
    args = ap.parse_args(argv)
    bundles = args.bundle or [str(Path(__file__).resolve().parents[1] / "models/bundles/tshirt-v6")]

    body = load_body_model()
    data = load_dataset(args.data, body=body)
    found = [c for c in data.clips if args.sequence in c.name]
    if len(found) != 1:
        names = ", ".join(c.name for c in found) if found else ", ".join(c.name for c in data.clips)
        raise SystemExit(f"{args.sequence!r} matches {len(found)} sequences: {names}")
    clip = found[0]
    t = args.frame
    if not 0 <= t < clip.num_frames:
        raise SystemExit(f"{clip.name}: frame {t} is outside 0..{clip.num_frames - 1}")
    poses, transl = clip.poses[t:t + 1], clip.transl[t:t + 1]
    # The learned tiers see the whole sequence up to the frame (the detail model is per frame,
    # but this keeps the call the one `evaluate` makes).
    panels = {"skinning": skin_garment(clip.pair.binding, poses, transl, body.parents)[0]}
    for path in bundles:
        bundle = load_bundle(path)
        learned = learned_garment(bundle, body, clip, garment_reads(bundle, data.clips))
        for tier in args.tiers.split(","):
            label = tier if len(bundles) == 1 else f"{bundle.name} {tier}"
            panels[label] = learned.evaluate(tier, clip.poses[:t + 1], clip.transl[:t + 1]).points[-1]
    panels["Newton"] = clip.positions[t].astype(np.float64)
    if args.repeat:
        twin = load_dataset(args.repeat, body=body, sequences=[clip.name]).clips  # that sequence alone
        if not twin or not np.allclose(twin[0].poses, clip.poses):
            raise SystemExit(f"--repeat {args.repeat}: no sequence {clip.name} of the same motion")
        panels["Newton, again"] = twin[0].positions[t].astype(np.float64)
    for label, pts in panels.items():
        err = np.linalg.norm(pts - panels["Newton"], axis=1) * 1000.0
        print(f"{label:9s} mean {err.mean():6.2f} mm  p95 {np.percentile(err, 95):6.2f} mm")
    body_vertices = posed_vertices(body, clip.pair.betas, poses, transl)[0]
    root = Rotation.from_rotvec(poses[0, :3])  # SMPL faces +Z at rest
    np.savez(args.output, body_vertices=body_vertices, body_faces=body.faces, garment_faces=clip.pair.faces,
             forward=root.apply([0.0, 0.0, 1.0]),
             labels=np.array(list(panels)), points=np.stack(list(panels.values())),
             sequence=clip.name, frame=t)
    print(f"wrote {args.output} ({clip.name}, frame {t})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
