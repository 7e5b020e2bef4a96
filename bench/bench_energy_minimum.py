"""Where the physics objective's minimum lies against Newton, on frames of the test set.

A model trained on the garment's energy can at best reach that energy's minimum. This
minimises the quasi-static energy (:func:`cloth_usd.nn.physics.garment_energy`, the training
objective's terms and material) over the vertex positions of single frames, by L-BFGS, and
prints side by side, per frame, the distance to Newton's garment [mm] of:

- skinning (the coarse tier's base),
- the minimum reached from skinning, with contact against each vertex's associated body
  point (what training uses) and against the nearest body point, recomputed,
- the minimum reached from Newton's own garment (how far Newton sits from a minimum),

and the energies and gradient norms at Newton's and the skinned garment. It measures the
objective, not a model: if its minimum is far from Newton, no network trained on it gets close.

    python bench/bench_energy_minimum.py TESTSET [--sequences 3] [--frames 2] [--iterations 300]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _nearest_body(body_vertices: np.ndarray, body_normals: np.ndarray, x: np.ndarray):
    """Nearest body vertex (and its normal) to each garment vertex."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(body_vertices).query(x)
    return body_vertices[idx], body_normals[idx]


def _minimise(x0, energy, iterations: int, refresh=None):
    """L-BFGS on the vertex positions; ``refresh(x)`` returns new contact points every 25 steps."""
    import torch

    x = torch.tensor(x0, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.LBFGS([x], lr=1.0, max_iter=25, history_size=20, line_search_fn="strong_wolfe")
    for _ in range(max(1, iterations // 25)):
        if refresh is not None:
            refresh(x.detach().numpy())

        def closure():
            opt.zero_grad()
            e = energy(x)
            e.backward()
            return e

        opt.step(closure)
    return x.detach().numpy()


def main(argv: list[str]) -> int:
    import torch

    from cloth_usd.core.body import lbs, load_body_model
    from cloth_usd.core.features import vertex_normals
    from cloth_usd.core.pipeline import pose_body
    from cloth_usd.core.skinning import skin_garment
    from cloth_usd.core.shards import Manifest
    from cloth_usd.datagen.simulate import SimConfig
    from cloth_usd.nn.data import load_dataset
    from cloth_usd.nn.physics import Material, garment_energy, garment_rest

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="a cloth-usd datagen folder (the test set)")
    ap.add_argument("--sequences", type=int, default=3, help="sequences (one per motion, the first found)")
    ap.add_argument("--frames", type=int, default=2, help="frames per sequence, spread over it")
    ap.add_argument("--iterations", type=int, default=300, help="L-BFGS iterations per minimisation")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)

    body = load_body_model()
    data = load_dataset(args.data, ("test_body", "test_garment", "test_motion"), body=body)
    material = Material.from_sim_config(SimConfig(**Manifest.read(args.data).config))
    seen, clips = set(), []
    for clip in data.clips:
        motion = clip.meta.get("motion")
        if motion not in seen:
            seen.add(motion)
            clips.append(clip)
    clips = clips[:args.sequences]
    rows = []
    head = ("skin", "min(skin) assoc", "min(skin) near", "min(Newton) near", "E newton assoc", "E newton near",
            "E skin assoc", "E skin near", "E min near", "Newton inside assoc", "Newton inside near")
    print(f"{'sequence':44s} {'frame':>5s} " + " ".join(f"{h:>{max(len(h), 8)}s}" for h in head))
    for clip in clips:
        rest = garment_rest(clip.rest_points, clip.pair.faces, material, dtype=torch.float64)
        for t in np.linspace(0, clip.num_frames - 1, args.frames + 2)[1:-1].round().astype(int):
            poses, transl = clip.poses[t:t + 1], clip.transl[t:t + 1]
            posed = pose_body(body, clip.pair, poses, transl)
            assoc = (torch.from_numpy(posed.garment_points), torch.from_numpy(posed.garment_normals))
            newton = clip.positions[t:t + 1].astype(np.float64)
            skin = skin_garment(clip.pair.binding, poses, transl, body.parents)
            verts, _ = lbs(body, clip.pair.v_shaped, clip.pair.joints, poses, transl)
            normals = vertex_normals(verts, body.faces)[0]
            near = {}

            def refresh(x):
                p, n = _nearest_body(verts[0], normals, x[0])
                near["p"], near["n"] = torch.from_numpy(p[None]), torch.from_numpy(n[None])

            def energy_assoc(x):
                return garment_energy(x, rest, material, body_points=assoc[0], body_normals=assoc[1]).total.sum()

            def energy_near(x):
                return garment_energy(x, rest, material, body_points=near["p"], body_normals=near["n"]).total.sum()

            def at(x, near_contact: bool) -> tuple[float, float]:
                """(energy [J], share of vertices behind their body point's tangent plane) of x."""
                if near_contact:
                    refresh(x)
                    points, nrm = near["p"], near["n"]
                else:
                    points, nrm = assoc
                xt = torch.from_numpy(x)
                inside = float((((xt - points) * nrm).sum(-1) < 0).double().mean())
                return float(garment_energy(xt, rest, material, body_points=points, body_normals=nrm).total), inside

            start = time.perf_counter()
            m_skin = _minimise(skin, energy_assoc, args.iterations)
            m_near = _minimise(skin, energy_near, args.iterations, refresh=refresh)
            m_newton = _minimise(newton, energy_near, args.iterations, refresh=refresh)
            seconds = time.perf_counter() - start

            def mm(a):
                return float(np.linalg.norm(a - newton, axis=-1).mean() * 1000.0)

            (e_na, in_na), (e_nn, in_nn) = at(newton, False), at(newton, True)
            (e_sa, _), (e_sn, _) = at(skin, False), at(skin, True)
            e_min = at(m_near, True)[0]
            row = (mm(skin), mm(m_skin), mm(m_near), mm(m_newton), e_na, e_nn, e_sa, e_sn, e_min, in_na, in_nn)
            rows.append(row)
            print(f"{clip.name:44s} {int(t):5d} " + " ".join(f"{v:>{max(len(h), 8)}.2f}" for h, v in zip(head, row))
                  + f"   ({seconds:.0f} s)", flush=True)
    mean = np.array(rows).mean(axis=0)
    print(f"{'mean':44s} {'':5s} " + " ".join(f"{v:>{max(len(h), 8)}.2f}" for h, v in zip(head, mean)))
    print("distances: mean over vertices to Newton's garment [mm]; E: quasi-static energy [J], contact against "
          "each vertex's associated body vertex (assoc, what training used) or the nearest body vertex (near); "
          "inside: share of Newton's vertices behind that body point's tangent plane")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
