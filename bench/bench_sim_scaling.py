"""Benchmark (not a test): a garment model's error against Newton by the simulated sequences it learns from (#12).

A garment's own model (:class:`~cloth_usd.nn.garment_model.GarmentNet`: pose and shape ->
displacement of every vertex, skinned) is fitted to Newton's frames alone, on nested subsets of
the simulated training sequences (``--counts``: the first n of one seeded order, so a larger
subset holds the smaller ones), one model per count and ``--seeds`` seed, and measured on a
Newton test set: the mean vertex distance [mm] over the frames after each sequence's warm-up,
the mean over the test sequences. It answers how many simulated sequences a target needs: the
error per doubling of the data is printed, fitted over the counts. No energy term: the hybrid
objective's physics (``train-garment --sim-data``) generalises further than these fits, so
their error is the supervised part's alone, measured side by side in one run.

``--motion`` adds a second model per count and seed whose inputs also hold the motion (the
pose features' velocity and acceleration over the last two frames, and the root's, in the
frame the models see): how much a model that knows how the body moves would gain over the
per-frame one the bundles ship. ``--mirror`` adds a model per count and seed fitted on the
sequences and their mirror images, left for right (:mod:`cloth_usd.nn.mirror`): twice the
frames from the same simulations. ``--hidden``, ``--layers``, ``--steps``, ``--weight-decay``
and ``--drop-joints`` (the pose of joints far from the garment zeroed) probe whether the model's
size, its training or its inputs limit the error rather than the data.

Inputs: ``--work`` a ``train-garment`` work folder (its ``data.json`` plans the sequences, its
``testset.json`` the test set's), ``--sim-data`` the ``cloth-usd datagen`` folder of its
``hybrid.json`` (``--sim-sequences``), ``--test-data`` the test set simulated from its
``testset.json``. Writes ``OUT/sim_scaling.md`` (also printed) and ``OUT/sim_scaling.json``.

Run: python bench/bench_sim_scaling.py --work WORK --sim-data HYB --test-data TSS --mocap MOCAP
         [--counts 2,4,8,16] [--seeds 0,1] [--steps 3000] [--hidden 256] [--layers 3] [--weight-decay 0]
         [--drop-joints J,J,...] [--motion] [--mirror] [--out out/sim_scaling]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from cloth_usd.core.body import load_body_model
from cloth_usd.core.garment_inputs import POSE_FEATURES, SHAPE_FEATURES, pose_features, shape_features, skin_parts
from cloth_usd.errors import ClothUsdError
from cloth_usd.nn.garment_model import GarmentNet, _first
from cloth_usd.nn.mirror import mirror_map, mirrored_clip
from cloth_usd.nn.physics_train import physics_set

#: The motion inputs' scales, so that a brisk motion's features are about as large as the pose's.
VELOCITY_SCALE, ACCELERATION_SCALE, ROOT_ACCELERATION_SCALE = 0.1, 0.01, 0.1


def motion_features(clip) -> np.ndarray:
    """(T, 2 * 216 + 6) a clip's pose-feature velocity and acceleration and its root's [per s,
    per s^2, scaled], from the frame and the two before it (the first frames repeat the first)."""
    f, root = pose_features(clip.poses), np.asarray(clip.transl, dtype=np.float64)

    def back(a):
        return np.concatenate([a[:1], a[:-1]])

    f1, r1 = back(f), back(root)
    f2, r2 = back(f1), back(r1)
    fps = clip.fps
    return np.concatenate([(f - f1) * fps * VELOCITY_SCALE, (f - 2 * f1 + f2) * fps ** 2 * ACCELERATION_SCALE,
                           (root - r1) * fps, (root - 2 * r1 + r2) * fps ** 2 * ROOT_ACCELERATION_SCALE], axis=1)


def mirrored(clip):
    """A simulated sequence mirrored left for right (:mod:`cloth_usd.nn.mirror`)."""
    return mirrored_clip(clip, mirror_map(clip.rest_points, clip.pair.faces, name=clip.name))


class MotionNet(GarmentNet):
    """:class:`GarmentNet` whose first layer also reads :func:`motion_features` (after the pose)."""

    def __init__(self, num_vertices: int, extra: int, **kwargs) -> None:
        super().__init__(num_vertices, **kwargs)
        first = self.body[0]
        self.body[0] = torch.nn.Linear(first.in_features + extra, first.out_features)


class Clip:
    """A sequence with Newton's frames: inputs and target as tensors, skinning made per batch."""

    def __init__(self, source, body, motion: bool) -> None:
        self.source, self.body = source, body
        self.first = _first(source)  # the first frame after the warm-up, as training takes it
        pose = pose_features(source.poses)
        if motion:
            pose = np.concatenate([pose, motion_features(source)], axis=1)
        self.pose = torch.from_numpy(pose.astype(np.float32))
        self.betas = torch.from_numpy(shape_features(source.pair.betas, source.num_frames).astype(np.float32))
        self.target = torch.from_numpy(np.asarray(source.target, dtype=np.float32))

    def garment(self, net, frames: np.ndarray) -> torch.Tensor:
        """(B, N, 3) the net's garment at ``frames`` (skinning alone when ``net`` is None) [m]."""
        src = self.source
        sk = skin_parts(src.pair.binding, src.poses[frames], src.transl[frames], self.body.parents)
        base, linear = torch.from_numpy(sk.base).float(), torch.from_numpy(sk.linear).float()
        if net is None:
            return base
        return base + torch.einsum("tnab,tnb->tna", linear, net(self.pose[frames], self.betas[frames]))


def test_mm(net, clips: list[Clip]) -> float:
    """The mean over ``clips`` of the mean vertex distance to Newton after the warm-up [mm]."""
    per = []
    with torch.no_grad():
        for c in clips:
            frames = np.arange(c.first, c.source.num_frames)
            per.append(1e3 * float((c.garment(net, frames) - c.target[frames]).norm(dim=-1).mean()))
    return float(np.mean(per))


def fit(clips: list[Clip], make_net, *, steps: int, seed: int, batch: int = 8, lr: float = 1e-3,
        lr_final: float = 1e-4, weight_decay: float = 0.0) -> torch.nn.Module:
    """Adam on the squared distance to Newton's frames (``batch`` frames of one sequence a step)."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = make_net()
    opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=weight_decay)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, (lr_final / lr) ** (1.0 / max(steps, 1)))
    for _ in range(steps):
        c = clips[int(rng.integers(len(clips)))]
        frames = np.sort(rng.integers(c.first, c.source.num_frames, batch))
        loss = ((c.garment(net, frames) - c.target[frames]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    return net


def per_doubling(frames: list[int], mm: list[float]) -> float:
    """The least-squares slope of mm against log2(frames): mm gained (negative) per doubling."""
    if len(set(frames)) < 2:
        return float("nan")
    return float(np.polyfit(np.log2(frames), mm, 1)[0])


def add_data_arguments(ap: argparse.ArgumentParser) -> None:
    """The inputs of a bench on a train-garment work folder and Newton's frames of its plans."""
    ap.add_argument("--work", type=Path, required=True, help="a train-garment work folder (data.json, testset.json)")
    ap.add_argument("--sim-data", type=Path, required=True, help="the datagen folder of WORK/hybrid.json")
    ap.add_argument("--test-data", type=Path, required=True, help="the Newton test set of WORK/testset.json")
    ap.add_argument("--mocap", type=Path, help="folder the configs' BVH motions are relative to")


def missing_data(a: argparse.Namespace, prog: str) -> bool:
    """Whether an input of :func:`add_data_arguments` is missing (one line naming it, on stderr)."""
    for flag, path in (("--work", a.work / "data.json"), ("--work", a.work / "testset.json"),
                       ("--sim-data", a.sim_data / "manifest.json"), ("--test-data", a.test_data / "manifest.json")):
        if not path.is_file():
            print(f"{prog}: {flag}: {path} not found", file=sys.stderr)
            return True
    return False


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_data_arguments(ap)
    ap.add_argument("--counts", default="2,4,8,16", help="simulated training sequences per model, comma separated")
    ap.add_argument("--seeds", default="0,1", help="seeds per count, comma separated")
    ap.add_argument("--order-seed", type=int, default=1, help="seed of the sequences' order (the subsets' nesting)")
    ap.add_argument("--steps", type=int, default=3000, help="Adam steps of 8 frames per model")
    ap.add_argument("--hidden", type=int, default=256, help="units of each hidden layer (the shipped width: 256)")
    ap.add_argument("--layers", type=int, default=3, help="hidden layers (shipped: 3)")
    ap.add_argument("--drop-joints", default="", help="SMPL joint indices whose pose features are zeroed (comma "
                    "separated): does a model that cannot see joints far from the garment generalise further?")
    ap.add_argument("--weight-decay", type=float, default=0.0, help="Adam's L2 weight decay")
    ap.add_argument("--mirror", action="store_true", help="also fit each count on its sequences and their mirror "
                    "images (left for right): twice the frames from the same simulations")
    ap.add_argument("--motion", action="store_true", help="also fit models that read the motion")
    ap.add_argument("--threads", type=int, default=2, help="torch threads")
    ap.add_argument("--out", type=Path, default=Path("out/sim_scaling"))
    a = ap.parse_args(argv)
    try:
        counts = sorted({int(c) for c in a.counts.split(",")})
        dropped = [int(j) for j in a.drop_joints.split(",") if j.strip()]
        seeds = [int(s) for s in a.seeds.split(",")]
    except ValueError:
        ap.error(f"--counts and --seeds take comma-separated integers, got {a.counts!r}, {a.seeds!r}")
    if min(counts) < 1 or min(a.steps, a.hidden, a.layers) < 1:
        ap.error("--counts, --steps, --hidden and --layers must be >= 1")
    if missing_data(a, "bench_sim_scaling"):
        return 2
    torch.set_num_threads(a.threads)
    body = load_body_model()
    began = time.perf_counter()
    try:
        train_set = physics_set(a.work / "data.json", body, mocap_dir=a.mocap, sim_data=a.sim_data)
        test_set = physics_set(a.work / "testset.json", body, mocap_dir=a.mocap, sim_data=a.test_data)
    except ClothUsdError as exc:
        print(f"bench_sim_scaling: {exc}", file=sys.stderr)
        return 2
    simulated = [c for c in train_set.split("train") if c.target is not None]
    tested = [c for c in test_set.clips if c.target is not None]
    if not simulated or not tested:
        print(f"bench_sim_scaling: {len(simulated)} simulated training and {len(tested)} simulated test sequences; "
              "need both", file=sys.stderr)
        return 2
    if max(counts) > len(simulated):
        print(f"bench_sim_scaling: --counts up to {max(counts)}, but {a.sim_data} holds {len(simulated)} simulated "
              "training sequences", file=sys.stderr)
        return 2
    planned = time.perf_counter() - began
    order = np.random.default_rng(a.order_seed).permutation(len(simulated))
    n = simulated[0].pair.num_vertices
    kinds = {"pose": False, **({"pose + motion": True} if a.motion else {}),
             **({"pose, mirrored too": False} if a.mirror else {})}
    rows = []
    skinning = None
    for kind, motion in kinds.items():
        train = [Clip(simulated[i], body, motion) for i in order]
        if kind == "pose, mirrored too":  # each sequence followed by its mirror image: a count takes both
            train = [c for i in order for c in (Clip(simulated[i], body, motion),
                                                 Clip(mirrored(simulated[i]), body, motion))]
        test = [Clip(c, body, motion) for c in tested]
        for c in train + test:
            c.pose[:, :POSE_FEATURES].reshape(-1, POSE_FEATURES // 9, 9)[:, dropped] = 0.0
        if skinning is None:
            skinning = test_mm(None, test)
        extra = train[0].pose.shape[1] - POSE_FEATURES  # the motion features' width (0: none)

        def make_net(extra=extra):
            width = {"hidden": a.hidden, "layers": a.layers}
            return MotionNet(n, extra, **width) if extra else GarmentNet(n, **width)

        for count in counts:
            for seed in seeds:
                t = time.perf_counter()
                shown = train[:count * (2 if kind == "pose, mirrored too" else 1)]
                net = fit(shown, make_net, steps=a.steps, seed=seed, weight_decay=a.weight_decay)
                row = {"inputs": kind, "sequences": count, "seed": seed,
                       "frames": int(sum(c.source.num_frames - c.first for c in shown)),
                       "test_mm": test_mm(net, test), "train_mm": test_mm(net, shown),
                       "seconds": time.perf_counter() - t}
                rows.append(row)
                print(json.dumps(row), flush=True)
    lines = [f"# Newton's frames and a garment model's error: {a.work.name}", "",
             f"- training: {len(simulated)} simulated sequences in `{a.sim_data.name}`, nested subsets "
             f"(order seed {a.order_seed}); {a.steps} Adam steps of 8 frames per model; {a.layers} hidden layers of "
             f"{a.hidden}; weight decay {a.weight_decay:g}; joints' pose zeroed {dropped or 'none'}; seeds {seeds}; "
             f"{n} vertices; shape inputs {SHAPE_FEATURES}",
             f"- test: {len(tested)} sequences of `{a.test_data.name}`, frames after the warm-up; skinning "
             f"{skinning:.2f} mm", f"- planning the sequences took {planned:.0f} s", "",
             "| inputs | sequences | frames | test mm (per seed) | test mm, mean | x skinning | training mm, mean |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    summary = {}
    for kind in kinds:
        means = []
        for count in counts:
            r = [x for x in rows if x["inputs"] == kind and x["sequences"] == count]
            mean = float(np.mean([x["test_mm"] for x in r]))
            means.append((r[0]["frames"], mean))
            per_seed = " / ".join(f"{x['test_mm']:.2f}" for x in r)
            lines.append(f"| {kind} | {count} | {r[0]['frames']} | {per_seed} | "
                         f"{mean:.2f} | {mean / skinning:.2f} | {np.mean([x['train_mm'] for x in r]):.2f} |")
        summary[kind] = per_doubling([f for f, _ in means], [m for _, m in means])
    lines.append("")
    for kind, slope in summary.items():
        lines.append(f"- {kind}: {slope:+.2f} mm per doubling of the simulated frames (least squares over the counts)")
    text = "\n".join(lines) + "\n"
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "sim_scaling.md").write_text(text)
    (a.out / "sim_scaling.json").write_text(json.dumps({"skinning_mm": skinning, "rows": rows,
                                                        "mm_per_doubling": summary}, indent=1) + "\n")
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
