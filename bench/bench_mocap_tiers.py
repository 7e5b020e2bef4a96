"""Benchmark (not a test): every tier of some bundles on held-out real clips, as a user bakes them (issue #12).

For each BVH clip (``--clip FILE[:A:B]``, file frames A..B, under ``--mocap``): the clip is
brought in with ``cloth-usd import-motion`` wearing the sample's T-shirt (or ``--garment``'s
garment), and baked with
``cloth-usd bake`` in the skinning tier and, for every ``--bundle``, in the coarse and the
detail tier. Per bake, over every frame of the clip:

- guard: frames the run-time guard replaced by the next safer tier (coarse, skinning);
- edge stretch: each frame's 99th percentile and maximum of edge length over the rest
  garment's, then the median frame's p99 (p50 col.), the worst frame's p99 and the largest
  edge of all; the same against the skinned shirt of that frame (skinning stretches too);
- offset: the largest vertex distance from the skinned shirt [mm];
- penetration: the fraction of vertices inside the posed body (the full SMPL mesh), and of
  those deeper than 1 mm, before the post-process (the models' garment as they made it,
  evaluated again here with ``LearnedGarment.evaluate(..., postprocess=False)``) and after it
  (the baked cache), on every fifth frame; and the post-process's count of the vertices it
  moved per frame;
- skin through the garment (the specks and holes a close-up shows where no garment vertex is in the
  body): on every fifth frame, the body vertices the rest garment covers
  (:func:`~cloth_usd.core.postprocess.covered_at_rest`) that lie more than
  :data:`~cloth_usd.core.postprocess.THROUGH_DEPTH` in front of the nearest of its inner triangles along
  their own normal (within 1 cm of it), the median frame's
  count and the most;
- where (learned tiers, before the post-process): of the vertices inside the body, the share
  also inside in the skinning tier's garment of that frame, and the share nearest to each
  body part (the body joint that skins the nearest body triangle's first corner most), so a
  clip's penetration reads as "the arms against the chest" rather than a bare percentage;
- bending: the dihedral bending energy of the material (``nn.physics``; needs torch) [J];
- posed outside: the frames a bake warns are posed outside the joint angles the bundle was
  trained on (``cloth_usd.core.limits.pose_outliers``, the bake's own test).

Writes ``OUT/mocap_tiers.md`` (also printed) and ``OUT/mocap_tiers.json``.

Run: python bench/bench_mocap_tiers.py --mocap DIR --clip cmu-mb.../05/05_02.bvh:120:400
         [--clip ...] [--bundle BUNDLE ...] [--garment GARMENT.usda] [--out out/mocap_tiers]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from pxr import Sdf

from cloth_usd.core.association import associate
from cloth_usd.core.body import load_body_model, posed_vertices, shape_body
from cloth_usd.core.features import vertex_normals
from cloth_usd.core.frames import canonical_motion
from cloth_usd.core.limits import pose_outliers
from cloth_usd.core.postprocess import THROUGH_DEPTH, body_ahead, covered_at_rest, inner_triangles
from cloth_usd.core.smpl import JOINT_NAMES
from cloth_usd.datagen.simulate import body_side, unique_edges
from cloth_usd.runtime.bundle import find_bundle, load_bundle
from cloth_usd.runtime.garment import LearnedGarment
from cloth_usd.usd.read import open_stage, read_motion, read_scene

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "samples" / "walk_tshirt" / "scene.usda"
CLI = [sys.executable, "-m", "cloth_usd.cli"]


def _run(*args: str) -> str:
    done = subprocess.run([*CLI, *args], capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"cloth-usd {' '.join(args)} failed:\n{done.stderr}")
    return done.stdout


def _points(cache: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """(T, N, 3) points and their time codes as the cache layer holds them, and its provenance."""
    layer = Sdf.Layer.FindOrOpen(str(cache))
    found: list[Sdf.Path] = []
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: found.append(p) if p.name == "points" else None)
    attr = layer.GetAttributeAtPath(found[0])
    times = np.array(sorted(layer.ListTimeSamplesForPath(attr.path)))
    pts = np.stack([np.asarray(layer.QueryTimeSample(attr.path, t), dtype=np.float64) for t in times])
    return pts, times, dict(layer.customLayerData)


def _stretch(points: np.ndarray, ref: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(T, E) edge length over the reference's (ref (N, 3) or (T, N, 3))."""
    length = np.linalg.norm(points[:, edges[:, 1]] - points[:, edges[:, 0]], axis=-1)
    ref = ref if ref.ndim == 3 else ref[None]
    ref_len = np.linalg.norm(ref[:, edges[:, 1]] - ref[:, edges[:, 0]], axis=-1)
    return length / np.maximum(ref_len, 1e-4)


def _side(points: np.ndarray, body_points: np.ndarray, body_faces: np.ndarray) -> np.ndarray | None:
    """(N,) each of ``points``' signed distance to the body [m], negative inside
    (``penetration_fraction``'s measure); None for a non-finite frame."""
    return body_side(points, body_points, body_faces) if np.isfinite(points).all() else None


def _ahead(points: np.ndarray, bodies: np.ndarray, normals: np.ndarray, inner: np.ndarray,
           ring: np.ndarray) -> np.ndarray:
    """(S, V) how far [m] each body vertex of ``bodies`` (S, V, 3), unit ``normals``, lies in front of
    the nearest of the garment ``points``' (S, N, 3) ``inner`` triangles (``ring`` around each vertex;
    :func:`~cloth_usd.core.postprocess.inner_triangles`) along its normal, NaN where none is within 1 cm
    (:func:`~cloth_usd.core.postprocess.body_ahead`)."""
    return np.stack([body_ahead(points[t], inner, ring, bodies[t], normals[t])[0] for t in range(len(points))])


def _covered(body, betas: np.ndarray, rest_points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) bool the vertices of the body of ``betas``, at rest, that the rest garment covers
    (:func:`~cloth_usd.core.postprocess.covered_at_rest`): the skin that can show through it."""
    at_rest = posed_vertices(body, betas, np.zeros((1, 72)), np.zeros((1, 3)))[0]
    return covered_at_rest(rest_points, faces, at_rest, vertex_normals(at_rest, body.faces))


def _inside(sides: list) -> tuple[np.ndarray, np.ndarray]:
    """Per frame of :func:`_side` arrays, the fractions of the vertices inside the body and
    deeper than 1 mm in it (NaN for a non-finite frame)."""
    rows = [(np.nan, np.nan) if side is None else (np.mean(side < 0.0), np.mean(side < -1e-3)) for side in sides]
    inside, deep = np.array(rows, dtype=np.float64).reshape(-1, 2).T
    return inside, deep


def _garment_report(provenance: dict) -> dict:
    """The first garment's record of a cache's provenance (``customLayerData["cloth_usd"]``)."""
    garments = dict(provenance.get("cloth_usd", {}).get("garments", {}))
    return dict(next(iter(garments.values()))) if garments else {}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", required=True, help="the mocap folder")
    ap.add_argument("--clip", action="append", required=True, help="FILE[:A:B] under --mocap (file frames A..B)")
    ap.add_argument("--bundle", action="append",
                    help="bundle folder (repeatable; default the shipped default for the garment's category)")
    ap.add_argument("--garment", default=str(SAMPLE),
                    help="a stage with the garment to wear (import-motion --garment; default the sample's T-shirt)")
    ap.add_argument("--out", default="out/mocap_tiers")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    body = load_body_model()
    garment = read_scene(open_stage(args.garment)).garments[0]  # the garment, as the baker reads it
    if args.bundle:
        bundles = args.bundle
    else:  # what a bake would run: the shipped bundle of this garment, else of its category
        shipped = find_bundle(garment.category, worn=(len(garment.rest_points), garment.triangles))
        if shipped is None:
            ap.error(f"no shipped bundle for a {garment.category.value}; name one with --bundle")
        bundles = [str(shipped.path)]
    rest, faces = garment.rest_points, garment.triangles
    edges = unique_edges(faces)
    energy = _bending(rest, faces)
    inner, ring = inner_triangles(np.asarray(faces, dtype=np.int64), len(rest))
    rows = []
    for clip in args.clip:
        name, *frames = clip.split(":")
        label = Path(name).stem
        shot = out / f"{label}.usda"
        extra = ["--frames", f"{frames[0]}:{frames[1]}"] if frames else []
        _run("import-motion", str(Path(args.mocap) / name), "-o", str(shot), "--garment", args.garment, "--force",
             *extra)
        skin_cache = out / f"{label}.skinning.usdc"
        _run("bake", str(shot), "-o", str(skin_cache), "--tier", "skinning", "--force")
        skinned, times, _ = _points(skin_cache)
        poses = _stage_poses(shot, times, body)
        bodies = posed_vertices(body, poses["betas"], poses["poses"], poses["transl"])
        sampled = np.arange(0, len(times), 5)
        normals = vertex_normals(bodies[sampled], body.faces)
        covered = _covered(body, poses["betas"], poses["rest"], faces)
        runs = [("skinning", None, skin_cache)]
        for bundle in bundles:
            for tier in ("coarse", "detail"):
                cache = out / f"{label}.{Path(bundle).name}.{tier}.usdc"
                _run("bake", str(shot), "-o", str(cache), "--tier", tier, "--models", bundle, "--force")
                runs.append((tier, bundle, cache))
        learned = {bundle: LearnedGarment(load_bundle(Path(bundle)), body, poses["betas"], poses["rest"], poses["faces"])
                   for bundle in bundles}  # one per bundle and clip: both tiers run it again before the post-process
        outside = {bundle: pose_outliers(poses["poses"], limits=g.bundle.pose_limits) for bundle, g in learned.items()}
        for tier, bundle, cache in runs:
            pts, _, prov = _points(cache)
            report = _garment_report(prov)
            vs_rest, vs_skin = _stretch(pts, rest, edges), _stretch(pts, skinned, edges)
            p99_rest, p99_skin = np.percentile(vs_rest, 99, axis=1), np.percentile(vs_skin, 99, axis=1)
            sides = [_side(pts[t], bodies[t], body.faces) for t in sampled]
            inside, deep = _inside(sides)
            through = np.count_nonzero((_ahead(pts[sampled], bodies[sampled], normals, inner, ring) > THROUGH_DEPTH)
                                       & covered, axis=1)
            where = {}
            if bundle is None:  # the skinning tier, first: its sides serve the learned tiers' "where" too
                before, skin_sides = (inside, deep), sides
            else:
                raw = _before(learned[bundle], poses, tier, sampled)
                raw_sides = [_side(raw[i], bodies[t], body.faces) for i, t in enumerate(sampled)]
                before = _inside(raw_sides)
                where = _where(raw, raw_sides, skin_sides, bodies[sampled], body)
            row = {"clip": label, "frames": len(times), "bundle": Path(bundle).name if bundle else "-", "tier": tier,
                   "fallback_coarse": int(report.get("fallback_coarse", 0)),
                   "fallback_skinning": int(report.get("fallback_skinning", 0)),
                   "stretch_rest_p99_median": float(np.median(p99_rest)), "stretch_rest_p99_worst": float(p99_rest.max()),
                   "stretch_rest_max": float(vs_rest.max()),
                   "stretch_skin_p99_median": float(np.median(p99_skin)), "stretch_skin_p99_worst": float(p99_skin.max()),
                   "stretch_skin_max": float(vs_skin.max()),
                   "offset_max_mm": float(np.linalg.norm(pts - skinned, axis=-1).max() * 1e3),
                   "postprocess_moved_per_frame": float(report.get("postprocess_moved", 0)) / max(len(times), 1),
                   "inside_before": float(np.mean(before[0])), "inside_1mm_before": float(np.mean(before[1])),
                   "inside_after": float(np.mean(inside)), "inside_1mm_after": float(np.mean(deep)),
                   "through_median": float(np.median(through)), "through_max": int(through.max()),
                   "bending_j": float(np.mean([energy(p) for p in pts[::5]])) if energy else float("nan"),
                   "posed_outside": 0 if bundle is None or outside[bundle] is None
                   else int(outside[bundle].frames.size),
                   **where}
            rows.append(row)
            print(json.dumps(row), flush=True)
    (out / "mocap_tiers.json").write_text(json.dumps(rows, indent=1))
    lines = ["| clip | frames | bundle | tier | guard: coarse / skinning | stretch vs rest p99 median / worst, max "
             "| vs skinning p99 median / worst, max | offset max mm | post-process moved / frame | inside before "
             "(deeper than 1 mm) | inside after (deeper than 1 mm) | skin through the garment: median / most a frame "
             "| bending J | frames posed outside training |",
             "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['clip']} | {r['frames']} | {r['bundle']} | {r['tier']} | {r['fallback_coarse']} / "
                     f"{r['fallback_skinning']} | {r['stretch_rest_p99_median']:.2f} / {r['stretch_rest_p99_worst']:.2f}, "
                     f"{r['stretch_rest_max']:.2f} | {r['stretch_skin_p99_median']:.2f} / "
                     f"{r['stretch_skin_p99_worst']:.2f}, {r['stretch_skin_max']:.2f} | {r['offset_max_mm']:.0f} | "
                     f"{r['postprocess_moved_per_frame']:.0f} | {100 * r['inside_before']:.2f}% "
                     f"({100 * r['inside_1mm_before']:.2f}%) | {100 * r['inside_after']:.2f}% ({100 * r['inside_1mm_after']:.2f}%) | "
                     f"{r['through_median']:g} / {r['through_max']} | {r['bending_j']:.2e} | "
                     f"{r['posed_outside'] if r['bundle'] != '-' else '-'} |")
    learned_rows = [r for r in rows if "inside_before_near" in r]
    if learned_rows:
        lines += ["", "Where the garment is inside the body before the post-process (every fifth frame):", "",
                  "| clip | bundle | tier | inside before | of them also inside in skinning | nearest body part |",
                  "|---|---|---|---:|---:|---|"]
        for r in learned_rows:
            near = ", ".join(f"{k} {100 * v:.0f}%" for k, v in list(r["inside_before_near"].items())[:5])
            lines.append(f"| {r['clip']} | {r['bundle']} | {r['tier']} | {100 * r['inside_before']:.2f}% | "
                         f"{100 * r['inside_before_in_skinning']:.0f}% | {near} |")
    text = "\n".join(lines) + "\n"
    (out / "mocap_tiers.md").write_text(text)
    print(text)
    return 0


def _stage_poses(shot: Path, times: np.ndarray, body) -> dict:
    """The shot's SMPL poses, root translations and betas at ``times``, read as the baker reads
    them, and its garment's rest points (in the body's frame, as the baker takes them) and triangles."""
    stage = open_stage(shot)
    scene = read_scene(stage)
    character, garment = scene.characters[0], scene.garments[0]
    motion = read_motion(stage, character, times)
    joints = shape_body(body, character.betas)[1]
    canonical = canonical_motion(character, motion, joints)  # what the bake hands the models
    return {"poses": motion.poses, "transl": motion.root_position - joints[0], "betas": character.betas,
            "model_poses": canonical.poses, "model_transl": canonical.transl,
            "rest": canonical.rest_points(garment.rest_points), "faces": garment.triangles}


def _before(learned: LearnedGarment, poses: dict, tier: str, sampled: np.ndarray) -> np.ndarray:
    """(S, N, 3) the ``tier`` garment of ``learned`` (the shot's garment on its bundle) before
    the post-process, at the ``sampled`` frames: the models run again as the bake runs them,
    with the post-process left out."""
    return learned.evaluate(tier, poses["model_poses"][sampled], poses["model_transl"][sampled],
                            postprocess=False).points


def _where(raw: np.ndarray, raw_sides: list, skin_sides: list, bodies: np.ndarray, body) -> dict:
    """Of the vertices of ``raw`` (S, N, 3) inside ``bodies`` (S, V, 3) (``raw_sides``, their
    :func:`_side` arrays): the share also inside in the skinning tier's garment of those frames
    (``skin_sides``; a frame whose skinned garment is not finite counts none), and the share
    nearest to each body part (the joint weighing most on the nearest triangle's first
    corner), largest first; empty shares when none is inside."""
    part = body.weights.argmax(axis=1)
    total = also = 0
    near = np.zeros(len(JOINT_NAMES), dtype=np.int64)
    for points, side, skin, verts in zip(raw, raw_sides, skin_sides, bodies):
        if side is None:
            continue
        inside = side < 0.0
        if not inside.any():
            continue
        total += int(inside.sum())
        also += int((inside & (skin < 0.0)).sum()) if skin is not None else 0
        hit = associate(points[inside], verts, body.faces).triangle
        near += np.bincount(part[body.faces[hit, 0]], minlength=len(JOINT_NAMES))
    order = np.argsort(-near, kind="stable")
    return {"inside_before_in_skinning": also / total if total else float("nan"),
            "inside_before_near": {JOINT_NAMES[j]: float(near[j] / total) for j in order if near[j]}}


def _bending(rest: np.ndarray, faces: np.ndarray):
    """points (N, 3) -> the material's bending energy [J], or None without torch."""
    try:
        import torch

        from cloth_usd.datagen.simulate import SimConfig
        from cloth_usd.nn.physics import Material, bending_energy, garment_rest
    except ImportError:
        return None
    material = Material.from_sim_config(SimConfig())
    state = garment_rest(rest, faces, material, dtype=torch.float64)
    return lambda p: float(bending_energy(torch.as_tensor(p[None]), state, material).sum())


if __name__ == "__main__":
    raise SystemExit(main())
