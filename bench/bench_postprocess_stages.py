"""Benchmark (not a test): where the detail tier's long edges come from, stage by stage (issue #12).

For each shot (a stage ``bench/bench_mocap_tiers.py`` wrote, ``OUT/<clip>.usda``: a real clip
wearing a garment), the detail tier of a bundle is run as a bake runs it, and its garment is
measured after each step of the post-process: the models' garment, after the strain limiter
(``--rounds``, each a row, at ``--limit``; a bake runs
:data:`~cloth_usd.core.postprocess.STRAIN_ITERATIONS` rounds at
:data:`~cloth_usd.core.postprocess.STRAIN_LIMIT`) and after the push out of the body that follows
it, and the whole post-process (``pipeline.post_process``: a frame the limit and
the push leave more stretched than the models made it is pushed without the limit, as is one where the
limit would move more than 1% of the vertices past
:data:`~cloth_usd.core.postprocess.LIMIT_MOVE_BOUND`), without and then with its last step, the lift of
the triangles off the body (:class:`~cloth_usd.core.postprocess.TriangleLift`), as a bake runs it. Per
row, over every ``--every``-th frame:

- edge stretch against the rest garment: the median frame's 99th percentile, the worst frame's,
  the largest edge, and the frames with an edge longer than ``--long`` (1.5) times its rest;
- for the pushed rows: of the edges longer than ``--long`` after the push, how many already were
  before it, and how many the push made with one end moved alone or with both ends moved in
  opposite directions (torn between two body surfaces, e.g. a thigh raised into the belly);
- the share of vertices inside the body (the full SMPL mesh) and deeper than 1 mm in it;
- the body through the garment, which the push (vertex by vertex) does not see: the body vertices
  within 1 cm of a garment triangle (one off the garment's open edges) that lie in front of it along
  their own normal, more than 1 mm, per frame (the specks of skin a close-up render shows through a
  taut sleeve even when no garment vertex is inside the body); and of those, the ones the rest garment
  covers (:func:`~cloth_usd.core.postprocess.covered_at_rest`): a hand on a shirt's chest lies in front of it too;
  and the skin between the body's vertices, measured the same way at the midpoints of the body's edges
  between two covered vertices (their normals averaged): most of the specks a close-up shows on a tight top
  lie there, not at a vertex;
- each frame's largest vertex move from the models' garment (the median frame's and the most):
  the strain limiter's global solve can move a whole region to shorten its edges (a trouser leg
  drawn down off a thigh raised to the chest), and the frames whose 99th percentile of that move
  is past :data:`~cloth_usd.core.postprocess.LIMIT_MOVE_BOUND` (in the limited rows: the frames a
  bake pushes without the limit for it);
- wall time of the step per frame.

Run: python bench/bench_postprocess_stages.py --shot OUT/04.usda [--shot ...] [--bundle DIR]
         [--rounds 8 --rounds 16] [--limit 1.05] [--every 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from cloth_usd.core.body import load_body_model, posed_vertices
from cloth_usd.core.features import vertex_normals
from cloth_usd.core.pipeline import pose_body, post_process
from cloth_usd.core.postprocess import (LIMIT_CHECK_QUANTILE, LIMIT_MOVE_BOUND, STRAIN_LIMIT, THROUGH_DEPTH,
                                        edge_midpoints, inner_triangles, limit_slides, mesh_edges,
                                        push_out_of_surface)
from cloth_usd.datagen.simulate import body_side, edge_ratios
from cloth_usd.runtime.bundle import find_bundle, load_bundle
from cloth_usd.runtime.garment import LearnedGarment
from cloth_usd.usd.read import open_stage, read_scene

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mocap_tiers import _ahead, _covered, _stage_poses  # noqa: E402  (the held-out bench's)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shot", action="append", required=True, help="a stage bench_mocap_tiers.py wrote (repeatable)")
    ap.add_argument("--bundle", help="bundle folder (default: the shipped default for the shot's garment)")
    ap.add_argument("--rounds", action="append", type=int, help="strain limiter rounds (repeatable; default 4 and 8)")
    ap.add_argument("--limit", type=float, default=STRAIN_LIMIT,
                    help=f"the strain limit: the longest edge over its rest (default {STRAIN_LIMIT}, a bake's)")
    ap.add_argument("--every", type=int, default=2, help="measure every n-th frame (default 2)")
    ap.add_argument("--long", type=float, default=1.5, help="an edge this many times its rest is long (default 1.5)")
    ap.add_argument("--out", default="out/postprocess_stages")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    body = load_body_model()
    rows = []
    for shot in map(Path, args.shot):
        stage = open_stage(shot)
        garment = read_scene(stage).garments[0]
        bundle_dir = Path(args.bundle) if args.bundle else find_bundle(
            garment.category, worn=(len(garment.rest_points), garment.triangles)).path
        times = np.arange(stage.GetStartTimeCode(), stage.GetEndTimeCode() + 1)[::args.every]
        poses = _stage_poses(shot, times, body)
        learned = LearnedGarment(load_bundle(bundle_dir), body, poses["betas"], poses["rest"], poses["faces"],
                                 strain_limit=args.limit)
        edges, rest = mesh_edges(poses["faces"]), poses["rest"]
        inner, ring = inner_triangles(np.asarray(poses["faces"], dtype=np.int64), len(rest))
        model_poses, model_transl = poses["model_poses"], poses["model_transl"]
        start = time.perf_counter()
        raw = learned.evaluate("detail", model_poses, model_transl, postprocess=False).points
        model_ms = 1e3 * (time.perf_counter() - start) / len(times)
        posed = pose_body(body, learned.pair, model_poses, model_transl)
        bodies = posed_vertices(body, poses["betas"], model_poses, model_transl)
        normals = vertex_normals(bodies, body.faces)
        patch = learned.pair.patch
        covered = _covered(body, poses["betas"], rest, poses["faces"])
        # the skin between the body's vertices: the midpoints of its edges between two covered vertices
        ends = mesh_edges(body.faces)
        mids, mid_normals = edge_midpoints(bodies, normals, ends[covered[ends].all(axis=1)])

        def row(stage_name, x, ms, before=None):
            s = edge_ratios(x, rest, edges)
            moved = np.linalg.norm(x - raw, axis=-1).max(axis=1)  # each frame's largest move from the models' garment
            p99 = np.percentile(s, 99, axis=1)
            side = np.stack([body_side(x[t], bodies[t], body.faces) for t in range(len(times))])
            ahead = _ahead(x, bodies, normals, inner, ring)
            through = np.count_nonzero(ahead > THROUGH_DEPTH, axis=1)
            skin = np.count_nonzero((ahead > THROUGH_DEPTH) & covered, axis=1)
            between = np.count_nonzero(_ahead(x, mids, mid_normals, inner, ring) > THROUGH_DEPTH, axis=1)
            r = {"shot": shot.stem, "bundle": bundle_dir.name, "stage": stage_name, "frames": len(times),
                 "ms_per_frame": ms, "p99_median": float(np.median(p99)), "p99_worst": float(p99.max()),
                 "max": float(s.max()), "frames_long": int(np.sum(s.max(axis=1) > args.long)),
                 "inside": float(np.mean(side < 0)), "inside_1mm": float(np.mean(side < -1e-3)),
                 "through_median": float(np.median(through)), "through_max": int(through.max()),
                 "frames_through": int(np.count_nonzero(through)),
                 "covered_median": float(np.median(skin)), "covered_max": int(skin.max()),
                 "frames_covered": int(np.count_nonzero(skin)),
                 "between_median": float(np.median(between)), "between_max": int(between.max()),
                 "move_median_mm": float(np.median(1e3 * moved)), "move_max_mm": float(1e3 * moved.max()),
                 "frames_past_bound": int(np.sum(limit_slides(raw, x)))}  # the post-process's own rule
            if before is not None:  # the push: which long edges it made, and how
                f, k = np.nonzero(s > args.long)
                a = x[f, edges[k, 0]] - before[f, edges[k, 0]]
                b = x[f, edges[k, 1]] - before[f, edges[k, 1]]
                na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
                was = edge_ratios(before, rest, edges)[f, k] > args.long
                both = (na > 0) & (nb > 0) & ~was
                r.update(long_edges=int(f.size), long_before_push=int(was.sum()),
                         long_one_end_pushed=int(np.sum(~was & ((na > 0) != (nb > 0)))),
                         long_torn=int(np.sum(both & (np.einsum("ic,ic->i", a, b) < 0))),
                         long_push_mm_median=float(np.median(1e3 * np.maximum(na, nb))) if f.size else 0.0)
            rows.append(r)
            print(json.dumps(r), flush=True)

        row("models", raw, model_ms)
        for rounds in args.rounds or [4, 8]:
            learned.limiter.iterations = rounds
            start = time.perf_counter()
            limited = learned.limiter(raw)
            limit_ms = 1e3 * (time.perf_counter() - start) / len(times)
            row(f"limited to {args.limit:g} x{rounds}", limited, limit_ms)
            start = time.perf_counter()
            pushed = push_out_of_surface(limited, posed.patch_points, posed.patch_normals, patch.faces, patch.contact,
                                         margin=learned.margin, rings=patch.rings)[0]
            push_ms = 1e3 * (time.perf_counter() - start) / len(times)
            row(f"limited to {args.limit:g} x{rounds}, pushed", pushed, limit_ms + push_ms,
                before=limited)
            start = time.perf_counter()  # a frame the limit and the push tear is pushed alone
            checked = post_process(learned.pair, posed, raw, margin=learned.margin, limiter=learned.limiter)[0]
            row(f"limited to {args.limit:g} x{rounds}, pushed, checked", checked,
                1e3 * (time.perf_counter() - start) / len(times))
            start = time.perf_counter()  # as a bake runs it, the triangles lifted last
            baked = post_process(learned.pair, posed, raw, margin=learned.margin, limiter=learned.limiter,
                                 lift=learned.lift)[0]
            row(f"limited to {args.limit:g} x{rounds}, pushed, checked, lifted (a bake)", baked,
                1e3 * (time.perf_counter() - start) / len(times))
    (out / "postprocess_stages.json").write_text(json.dumps(rows, indent=1))
    lines = ["| shot | stage | ms/frame | stretch p99 median / worst, max | frames with an edge > "
             f"{args.long} | long edges after the push: already before / one end pushed / torn | inside "
             "(deeper than 1 mm) | body vertices through the garment: frames, median / most a frame | of those, "
             "ones the rest garment covers | covered skin between the body's vertices (its edges' midpoints): "
             "median / most a frame | largest "
             "move from the models' garment, median / most a frame [mm] | frames that move more than "
             f"{100 * (1 - LIMIT_CHECK_QUANTILE):g}% of the vertices past {1e3 * LIMIT_MOVE_BOUND:g} mm |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        made = (f"{r['long_edges']}: {r['long_before_push']} / {r['long_one_end_pushed']} / {r['long_torn']}"
                if "long_edges" in r else "")
        lines.append(f"| {r['shot']} | {r['stage']} | {r['ms_per_frame']:.1f} | {r['p99_median']:.3f} / "
                     f"{r['p99_worst']:.3f}, {r['max']:.2f} | {r['frames_long']} / {r['frames']} | {made} | "
                     f"{100 * r['inside']:.2f}% ({100 * r['inside_1mm']:.2f}%) | {r['frames_through']} / "
                     f"{r['frames']}, {r['through_median']:g} / {r['through_max']} | {r['frames_covered']} / "
                     f"{r['frames']}, {r['covered_median']:g} / {r['covered_max']} | {r['between_median']:g} / "
                     f"{r['between_max']} | {r['move_median_mm']:.0f} / "
                     f"{r['move_max_mm']:.0f} | {r['frames_past_bound']} / {r['frames']} |")
    text = "\n".join(lines) + "\n"
    (out / "postprocess_stages.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
