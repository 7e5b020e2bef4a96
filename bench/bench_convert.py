"""Benchmark (not a test): what the game exports cost against the USD cache they come from.

For the sample walk (96 frames) and a 300-frame clip brought in with ``import-motion``
(CMU 05_18, a modern-dance take, file frames 1:1200 resampled to 30 fps), both baked
with the detail tier, prints a markdown table of the file size and the error to the
cache [mm] (per vertex, max and mean over all frames and vertices) of:

- the USD point cache (``.usdc``, what ``bake`` writes: the reference, error 0);
- ``convert`` to .glb with K = 16, 32 and 64 morph targets, and with the default
  ``--max-error 1`` (K chosen); positions read back from the file;
- ``convert --format vat``: half-float EXR and 16-bit PNG (both textures, mesh and
  JSON), positions decoded from the files as the stock VAT 3.0 soft-body shader does.

Run: OMP_NUM_THREADS=1 python bench/bench_convert.py --out /tmp/bench_convert \\
         --bvh MOCAP/cmu-mb2_chrystianosaraujo-motion-viewer/05/05_18.bvh
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from cloth_usd.cli import main as cli
from cloth_usd.export.convert import OutputFormat, convert, read_baked
from cloth_usd.export.gltf import read_accessor, read_glb
from cloth_usd.export.pca import vertex_errors
from cloth_usd.export.vat import TextureFormat

ROOT = Path(__file__).resolve().parents[1]


def glb_points(path: Path) -> np.ndarray:
    """(T, N, 3) the garment as a player shows it at each frame: base + weights @ targets."""
    doc, blob = read_glb(path.read_bytes())
    prim = doc["meshes"][0]["primitives"][0]
    base = read_accessor(doc, blob, prim["attributes"]["POSITION"]).astype(np.float64)
    targets = np.stack([read_accessor(doc, blob, t["POSITION"]) for t in prim["targets"]]).astype(np.float64)
    sampler = doc["animations"][0]["samplers"][0]
    weights = read_accessor(doc, blob, sampler["output"]).reshape(-1, targets.shape[0]).astype(np.float64)
    return base + np.einsum("tk,knc->tnc", weights, targets)


def measure(name: str, shot: Path, cache: Path, out: Path) -> list[dict]:
    anim, _ = read_baked(shot)
    rows = [{"shot": name, "what": "USD cache (.usdc)", "bytes": cache.stat().st_size, "max_mm": 0.0,
             "mean_mm": 0.0, "frames": anim.points.shape[0], "vertices": anim.points.shape[1]}]
    for label, kwargs in [("K = 16", {"targets": 16}), ("K = 32", {"targets": 32}), ("K = 64", {"targets": 64}),
                          ("--max-error 1", {})]:
        path = out / f"{name}_{label.replace(' ', '').replace('=', '').replace('-', '')}.glb"
        start = time.perf_counter()
        result = convert(shot, path, force=True, **kwargs)
        seconds = time.perf_counter() - start
        err = vertex_errors(glb_points(path), anim.points) * 1000
        rows.append({"shot": name, "what": f".glb, {label}" + (f" (K = {result.targets})" if not kwargs else ""),
                     "bytes": path.stat().st_size, "max_mm": float(err.max()), "mean_mm": float(err.mean()),
                     "seconds": seconds})
    for fmt in TextureFormat:
        folder = out / f"{name}_vat_{fmt.value}"
        start = time.perf_counter()
        result = convert(shot, folder, fmt=OutputFormat.VAT, vat_format=fmt, force=True)
        seconds = time.perf_counter() - start
        label = "half-float EXR" if fmt is TextureFormat.EXR else "16-bit PNG"
        rows.append({"shot": name, "what": f"VAT, {label}", "bytes": sum(f.stat().st_size for f in result.files),
                     "position_texture_bytes": result.files[1].stat().st_size,
                     "max_mm": result.max_error_mm, "mean_mm": result.mean_error_mm, "seconds": seconds})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_convert"))
    parser.add_argument("--bvh", type=Path, required=True, help="the clip (CMU 05_18 in the README's table)")
    parser.add_argument("--bvh-frames", default="1:1200", help="file frames (1:1200 at 120 fps -> 300 at 30 fps)")
    args = parser.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    sample = ROOT / "samples" / "walk_tshirt" / "scene.usda"
    shots = {}
    assert cli(["bake", str(sample), "-o", str(out / "walk_cache.usdc"), "--shot", str(out / "walk_shot.usda"),
                "--tier", "detail", "--no-progress", "--force"]) == 0
    shots["sample walk"] = (out / "walk_shot.usda", out / "walk_cache.usdc")
    assert cli(["import-motion", str(args.bvh), "-o", str(out / "clip_scene.usda"), "--garment", str(sample),
                "--frames", args.bvh_frames, "--force"]) == 0
    assert cli(["bake", str(out / "clip_scene.usda"), "-o", str(out / "clip_cache.usdc"), "--shot",
                str(out / "clip_shot.usda"), "--tier", "detail", "--no-progress", "--force"]) == 0
    shots[f"{args.bvh.stem} clip"] = (out / "clip_shot.usda", out / "clip_cache.usdc")
    rows = []
    for name, (shot, cache) in shots.items():
        rows += measure(name.split()[0], shot, cache, out)
    (out / "bench_convert.json").write_text(json.dumps(rows, indent=2) + "\n")
    names = [n.split()[0] for n in shots]
    frames = {r["shot"]: r["frames"] for r in rows if "frames" in r}
    header = " | ".join(f"{n} ({frames[n]} frames): size | max mm | mean mm" for n in names)
    print(f"| file | {header} |")
    print("|---|" + "---:|---:|---:|" * len(names))
    for what in dict.fromkeys(r["what"].split(" (K")[0] for r in rows):
        cells = []
        for n in names:
            r = next(r for r in rows if r["shot"] == n and r["what"].split(" (K")[0] == what)
            size = f"{r['bytes'] / 2 ** 20:.2f} MiB" if r["bytes"] >= 2 ** 20 else f"{r['bytes'] / 1024:.0f} KiB"
            k = f" (K {r['what'].split('K = ')[1].rstrip(')')})" if "(K" in r["what"] else ""
            cells.append(f"{size}{k} | {r['max_mm']:.3f} | {r['mean_mm']:.4f}")
        print(f"| {what} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
