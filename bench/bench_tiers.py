"""Benchmark (not a test): speed and accuracy of every tier, fp32 and int8, side by side (issues #4 and #12).

For a model bundle, on the CPU:

- speed: a T-shirt of ``--vertices`` vertices (``make_tshirt``) on the default body, or
  ``--garment``'s garment (a dress or trousers bundle needs one of its category),
  animated by ``walk_cycle``: the skinning tier through ``core.skinning.skin_garment``, the
  coarse and detail tiers through ``LearnedGarment.evaluate`` (features, model, post-process:
  what a bake runs per frame; a learned bake also skins each frame for its fallback, i.e.
  adds the skinning row). ms/frame = wall time of ``--frames`` frames / ``--frames``
  (median of ``--repeats``), after one warm-up batch; setup (association, graph, fit
  attribute) is timed apart, as is loading the sessions.
- int8: the bundle's coarse.onnx / detail.onnx through onnxruntime's dynamic quantization
  (``quantize_dynamic``) into a temporary bundle; a model that fails to quantize, load or
  run is reported as ``n/a (reason)``.
- error (with ``--data``): mean and 95th percentile per-vertex error [mm] on the data set's
  test splits, by :func:`cloth_usd.evaluate.evaluate_bundle` (its reports are kept in
  ``OUT/eval_fp32`` and ``OUT/eval_int8``).

Writes ``OUT/table.md`` (also printed), ``OUT/pareto.png`` (ms/frame vs mean error, the
Pareto front marked; needs ``--data``) and ``OUT/bench.json``. Issue #12's targets (detail
<= 60 ms/frame, a fast tier <= 15 ms/frame, 4000-vertex shirt, 2 CPU cores) are printed
beside the measurements, never asserted. With torch installed, the detail model's
onnxruntime / torch eager speed at the bundle's width is printed too (random weights).

Run: python bench/bench_tiers.py [--bundle DIR] [--data DIR] [--vertices 4000 | --garment STAGE.usda]
         [--frames 48] [--threads 2] [--batch-size 4] [--out out/bench_tiers]
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import math
import os
import platform
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Sequence

import numpy as np

#: Issue #12's targets [ms/frame] for a 4000-vertex shirt on 2 CPU cores (issue #4 asked the
#: detail tier for 150).
TARGET_DETAIL_MS = 60.0
TARGET_FAST_MS = 15.0
TARGET_VERTICES = 4000
TARGET_THREADS = 2
TIERS = ("skinning", "coarse", "detail")


@dataclass
class Row:
    """One tier at one precision."""

    tier: str
    precision: str
    ms_per_frame: float = math.nan
    setup_ms: float = math.nan
    load_ms: float = math.nan
    """Creating the onnxruntime session(s) the tier runs [ms]."""
    mean_mm: float = math.nan
    p95_mm: float = math.nan
    na: str = ""
    """Why the row was not measured (empty when it was)."""
    runs_ms: list = field(default_factory=list)
    """ms/frame of each timed repeat."""
    model_ms: float = math.nan
    """Of ``ms_per_frame``, the time inside onnxruntime (mean over the repeats) [ms/frame]."""
    peak_rss_mb: float = math.nan
    """The process's peak resident memory once the row was timed [MiB] (monotonic over the rows)."""
    pareto: bool = False

    @property
    def label(self) -> str:
        return f"{self.tier} {self.precision}"


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:120] if text else ''}".rstrip(": ")


def _target(row: Row) -> str:
    if row.tier == "detail":
        limit, what = TARGET_DETAIL_MS, "detail"
    elif row.tier == "coarse":
        limit, what = TARGET_FAST_MS, "fast tier"
    else:
        return "- (no model)"
    if math.isnan(row.ms_per_frame):
        return f"<= {limit:g} ({what})"
    return f"<= {limit:g} ({what}): {'met' if row.ms_per_frame <= limit else 'NOT met'}"


def _cpu_sessions(bundle, threads: int) -> float:
    """Fill the bundle's session cache with CPU sessions of ``threads`` intra-op threads; ms taken.

    ``ModelBundle.session`` takes no thread count, so the sessions are made here with
    :class:`ModelSession`'s own ``intra_op_threads`` and put where ``session`` finds them.
    """
    from cloth_usd.runtime.bundle import SPINNING_TIERS
    from cloth_usd.runtime.session import ModelSession

    t = time.perf_counter()
    for tier in bundle.tiers:  # spinning as a bake's sessions spin
        bundle._sessions[tier] = ModelSession(bundle.model_path(tier), intra_op_threads=threads, prefer_gpu=False,
                                              spin=tier in SPINNING_TIERS)
    return (time.perf_counter() - t) * 1e3


def quantize_bundle(bundle, out_dir: Path) -> tuple[Path | None, dict[str, str]]:
    """An int8 copy of ``bundle`` (dynamic quantization of its models) in ``out_dir``.

    Returns:
        ``(bundle folder or None, {tier: reason})`` for the tiers that could not be quantized;
        a detail model that fails leaves a coarse-only bundle, a coarse one no bundle.
    """
    from onnxruntime.quantization import QuantType, quantize_dynamic

    from cloth_usd.runtime.bundle import write_bundle

    failed: dict[str, str] = {}
    models: dict[str, Path] = {}
    work = out_dir / "models"
    work.mkdir(parents=True, exist_ok=True)
    for tier in bundle.tiers:
        dst = work / f"{tier.value}.int8.onnx"
        try:
            quantize_dynamic(str(bundle.model_path(tier)), str(dst), weight_type=QuantType.QInt8)
            models[tier.value] = dst
        except Exception as exc:  # noqa: BLE001 - a benchmark reports and goes on
            failed[tier.value] = f"quantization failed: {_reason(exc)}"
    if "coarse" not in models:
        failed.setdefault("detail", "the coarse model did not quantize")
        return None, failed
    m = bundle.manifest
    path = write_bundle(out_dir / "bundle", name=f"{bundle.name}-int8", category=bundle.category,
                        coarse_onnx=models["coarse"], detail_onnx=models.get("detail"),
                        fit_npz=bundle.path / m["fit"]["file"],
                        configs={t: e.get("config", {}) for t, e in m["models"].items()},
                        training_data=m.get("training_data", {}),
                        metrics={"note": "int8 dynamic quantization of " + str(bundle.path)},
                        opset=int(m.get("opset", 18)), form=bundle.form, garment=bundle.garment,
                        detail_adds_coarse=bundle.detail_adds_coarse)
    return path, failed


def _clock_sessions(bundle) -> list[float]:
    """Make the bundle's (already made) sessions add their run time [s] to the returned cell."""
    clock = [0.0]
    for session in bundle._sessions.values():
        def timed(inputs, run=session.run):
            t = time.perf_counter()
            out = run(inputs)
            clock[0] += time.perf_counter() - t
            return out
        session.run = timed
    return clock


def _peak_rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def _progress(row: Row) -> None:
    print(f"  {row.label}: {row.ms_per_frame:.2f} ms/frame (peak RSS {row.peak_rss_mb:.0f} MiB)", file=sys.stderr,
          flush=True)


def _time_frames(fn, frames: int, repeats: int) -> list[float]:
    """ms/frame of each of ``repeats`` calls of ``fn`` (which evaluates ``frames`` frames)."""
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1e3 / frames)
    return out


def stage_garment(path: Path, body) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rest points in the canonical body frame, triangles, betas)`` of a stage's only garment."""
    from cloth_usd.core.body import shape_body
    from cloth_usd.core.frames import worn_rest_points
    from cloth_usd.usd.read import open_stage, read_scene

    scene = read_scene(open_stage(path))
    garment = scene.garments[0]
    char = next(c for c in scene.characters if c.prim_path == garment.body_path)
    rest = worn_rest_points(char, garment.rest_points, shape_body(body, char.betas)[1])
    return rest, np.asarray(garment.triangles, dtype=np.int64), np.asarray(char.betas, dtype=np.float64)


def measure_speed(bundles: dict[str, Path | None], rows: dict[tuple[str, str], Row], *, vertices: int,
                  frames: int, repeats: int, threads: int, batch_size: int,
                  garment: Path | None = None) -> tuple[dict, object]:
    """Fill the speed columns of ``rows``; returns the shirt and motion used, and the shirt's graph.
    ``garment``: a stage whose garment (and body shape) is timed instead of a made shirt (a
    garment's own bundle serves its garment alone)."""
    from cloth_usd.core.body import load_body_model
    from cloth_usd.core.skinning import bind_garment, skin_garment
    from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
    from cloth_usd.runtime.bundle import load_bundle
    from cloth_usd.runtime.garment import LearnedGarment

    body = load_body_model()
    if garment is not None:
        rest, faces, betas = stage_garment(garment, body)
    else:
        betas = np.zeros(body.shapedirs.shape[-1])
        rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=vertices))
    warm = min(batch_size, frames)
    poses, transl = walk_cycle(warm + frames)
    wp, wt, tp, tt = poses[:warm], transl[:warm], poses[warm:], transl[warm:]

    t = time.perf_counter()
    binding = bind_garment(body, betas, rest)
    setup = (time.perf_counter() - t) * 1e3

    def skin() -> None:
        for lo in range(0, frames, batch_size):
            skin_garment(binding, tp[lo:lo + batch_size], tt[lo:lo + batch_size], body.parents)

    skin_garment(binding, wp, wt, body.parents)
    row = rows[("skinning", "fp64")]
    row.setup_ms, row.runs_ms = setup, _time_frames(skin, frames, repeats)
    row.ms_per_frame, row.peak_rss_mb = statistics.median(row.runs_ms), _peak_rss_mb()
    _progress(row)

    graph = None
    for precision, path in bundles.items():
        if path is None:
            continue
        bundle = load_bundle(path)
        try:
            load = _cpu_sessions(bundle, threads)
            clock = _clock_sessions(bundle)
        except Exception as exc:  # noqa: BLE001
            for tier in ("coarse", "detail"):
                rows[(tier, precision)].na = rows[(tier, precision)].na or f"session failed: {_reason(exc)}"
            continue
        t = time.perf_counter()
        learned = LearnedGarment(bundle, body, betas, rest, faces)
        setup = (time.perf_counter() - t) * 1e3
        graph = learned.graph
        for tier in ("coarse", "detail"):
            row = rows[(tier, precision)]
            if row.na:
                continue
            if tier not in [t.value for t in bundle.tiers]:
                row.na = "the bundle has no detail model"
                continue
            try:
                learned.evaluate(tier, wp, wt, batch_size=batch_size)
                clock[0] = 0.0
                row.runs_ms = _time_frames(
                    lambda g=learned, t=tier: g.evaluate(t, tp, tt, batch_size=batch_size), frames, repeats)
            except Exception as exc:  # noqa: BLE001
                row.na = f"run failed: {_reason(exc)}"
                continue
            row.setup_ms, row.load_ms = setup, load
            row.model_ms = clock[0] * 1e3 / (frames * repeats)
            row.ms_per_frame, row.peak_rss_mb = statistics.median(row.runs_ms), _peak_rss_mb()
            _progress(row)
        bundle._sessions.clear()  # free this precision's sessions (and their arenas) before the next
        del learned, bundle, clock
        gc.collect()
    return {"garment": "T-shirt" if garment is None else str(garment), "vertices": int(rest.shape[0]),
            "triangles": int(faces.shape[0]), "motion": "walk_cycle",
            "warmup_frames": warm, "frames": frames, "repeats": repeats, "batch_size": batch_size}, graph


def measure_error(bundles: dict[str, Path | None], rows: dict[tuple[str, str], Row], data: Path, out: Path, *,
                  max_frames: int | None, batch_size: int) -> dict:
    """Fill the error columns of ``rows`` from :func:`evaluate_bundle` ("all test sets" row)."""
    from cloth_usd.evaluate import evaluate_bundle

    info = {}
    for precision, path in bundles.items():
        if path is None:
            continue
        try:
            report = evaluate_bundle(data, path, out / f"eval_{precision}", max_frames=max_frames,
                                     batch_size=batch_size)
        except Exception as exc:  # noqa: BLE001
            for tier in ("coarse", "detail"):
                rows[(tier, precision)].na = rows[(tier, precision)].na or f"evaluation failed: {_reason(exc)}"
            continue
        every = next(r for r in report.rows if r["key"] == "all")
        info[precision] = {"report": str(report.out_dir / "report.md"), "sequences": every["sequences"],
                           "frames": every["frames"], "data_manifest_sha256": report.metrics["data"]["manifest_sha256"]}
        for tier in report.tiers:
            key = ("skinning", "fp64") if tier == "skinning" else (tier, precision)
            if key in rows and (tier != "skinning" or math.isnan(rows[key].mean_mm)):  # skinning: first run's
                rows[key].mean_mm, rows[key].p95_mm = every["mean_mm"][tier], every["p95_mm"][tier]
    return info


def _torch_model(bundle, tier: str):
    """A random-weight torch model of the bundle's ``tier`` at its recorded config (width...)."""
    from cloth_usd.nn.models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator, ParserConfig

    config_type, model_type = (CoarseConfig, CoarseGenerator) if tier == "coarse" else (DetailConfig, DetailGenerator)
    cfg = dict(bundle.manifest["models"][tier].get("config", {}))
    if isinstance(cfg.get("parser"), dict):
        cfg["parser"] = ParserConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in cfg["parser"].items()})
    names = {f.name for f in fields(config_type)}
    cfg = {k: tuple(v) if isinstance(v, list) else v for k, v in cfg.items() if k in names}
    return model_type(config_type(**cfg)).eval(), cfg.get("width", 1.0)


def torch_ratio(bundle_path: Path, *, graph, threads: int, batch_sizes: Sequence[int] = (1, 4),
                repeats: int = 3) -> list[str]:
    """Each model alone, torch eager vs onnxruntime at the bundle's widths (random weights, best
    of ``repeats``), at each of ``batch_sizes`` frames per call (small: torch eager's
    activations at batch 16 on a 4000-vertex shirt take many GB). One line per model and batch."""
    try:
        import torch

        from cloth_usd.runtime import COARSE_INPUTS, DETAIL_INPUTS, coarse_inputs, detail_inputs
        from cloth_usd.runtime.bundle import load_bundle
    except ImportError as exc:
        return [f"onnxruntime / torch eager: n/a ({_reason(exc)})"]
    lines = []
    try:
        bundle = load_bundle(bundle_path)
        torch.set_num_threads(threads)
        _cpu_sessions(bundle, threads)
    except Exception as exc:  # noqa: BLE001
        return [f"onnxruntime / torch eager: n/a ({_reason(exc)})"]
    rng = np.random.default_rng(0)
    for tier in [t.value for t in bundle.tiers]:
        for batch in batch_sizes:
            try:
                model, width = _torch_model(bundle, tier)
                n = graph.num_vertices
                if tier == "coarse":
                    feed, names = coarse_inputs(rng.normal(size=(batch, n, 7)), graph.table), COARSE_INPUTS
                else:
                    feed = detail_inputs(rng.normal(size=(batch, n, 30)), rng.normal(size=(batch, 85)), graph)
                    names = DETAIL_INPUTS
                session = bundle.session(tier)
                args = [torch.from_numpy(feed[k]) for k in names]

                def best(fn, frames=batch) -> float:
                    fn()
                    return min(_time_frames(fn, frames, repeats))

                with torch.no_grad():
                    t_torch = best(lambda: model(*args))
                t_ort = best(lambda: session.run(feed))
            except Exception as exc:  # noqa: BLE001
                lines.append(f"{tier} onnxruntime / torch eager, batch {batch}: n/a ({_reason(exc)})")
                continue
            verdict = "met" if t_ort <= t_torch else "NOT met"
            lines.append(f"{tier} model only (width {width:g}), batch {batch}: torch eager / onnxruntime fp32 "
                         f"time {t_torch / t_ort:.2f}x (torch {t_torch:.1f}, onnxruntime {t_ort:.1f} ms/frame; "
                         f"target onnxruntime never slower, >= 1: {verdict})")
    bundle._sessions.clear()
    return lines


def pareto_front(rows: Sequence[Row]) -> list[Row]:
    """Rows no other row beats on both ms/frame and mean error (lower is better)."""
    pts = [r for r in rows if not (math.isnan(r.ms_per_frame) or math.isnan(r.mean_mm))]
    return [r for r in pts if not any(o is not r and o.ms_per_frame <= r.ms_per_frame and o.mean_mm <= r.mean_mm
                                      and (o.ms_per_frame < r.ms_per_frame or o.mean_mm < r.mean_mm) for o in pts)]


def plot_pareto(rows: Sequence[Row], front: Sequence[Row], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.subplots()
    colours = {t: f"C{i}" for i, t in enumerate(TIERS)}
    done = [r for r in rows if not (math.isnan(r.ms_per_frame) or math.isnan(r.mean_mm))]
    for r in done:
        ax.scatter(r.ms_per_frame, r.mean_mm, color=colours[r.tier], marker="s" if r.precision == "int8" else "o",
                   s=30, zorder=3)
        below = r.precision == "int8"  # fp32 labels above, int8 below: the pairs sit close together
        ax.annotate(r.label, (r.ms_per_frame, r.mean_mm), textcoords="offset points", xytext=(6, -11 if below else 4),
                    fontsize=8)
    f = sorted(front, key=lambda r: r.ms_per_frame)
    if f:
        xs, ys = [p.ms_per_frame for p in f], [p.mean_mm for p in f]
        ax.scatter(xs, ys, s=140, facecolors="none", edgecolors="k", zorder=4, label="Pareto front")
        if len(f) > 1:
            ax.step(xs, ys, where="post", color="k", lw=1, ls="--", zorder=2)
    ms = [r.ms_per_frame for r in done] + [TARGET_FAST_MS, TARGET_DETAIL_MS]
    ax.set_xlim(min(ms) / 1.6, max(ms) * 1.6)
    for limit, name in ((TARGET_FAST_MS, "fast tier target"), (TARGET_DETAIL_MS, "detail target")):
        ax.axvline(limit, color="0.6", lw=0.8, ls=":")
        ax.annotate(name, (limit, 1), xycoords=("data", "axes fraction"), xytext=(2, -4),
                    textcoords="offset points", fontsize=7, color="0.4", rotation=90, va="top")
    ax.set_xscale("log")
    ax.set_xlabel("ms / frame (CPU, log scale)")
    ax.set_ylabel("mean per-vertex error [mm]")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(str(path), dpi=100)


def _f(x: float, digits: int = 2) -> str:
    return "-" if x is None or math.isnan(x) else f"{x:.{digits}f}"


def _speedup(rows: dict, tier: str) -> str:
    a, b = rows[(tier, "fp32")], rows[(tier, "int8")]
    if b.na or a.na or math.isnan(a.ms_per_frame) or math.isnan(b.ms_per_frame):
        return f"{tier} int8 / fp32 speed: n/a ({b.na or a.na or 'not measured'})"
    err = ""
    if not (math.isnan(a.mean_mm) or math.isnan(b.mean_mm)):
        err = f", mean error {b.mean_mm - a.mean_mm:+.3f} mm"
    return f"{tier} int8 / fp32 speed: {a.ms_per_frame / b.ms_per_frame:.2f}x{err}"


def markdown(rows: dict, meta: dict, lines_after: Sequence[str]) -> str:
    s = meta["speed"]
    head = [
        f"# Tier speed / accuracy: bundle `{meta['bundle']['name']}`",
        "",
        f"- bundle: `{meta['bundle']['path']}` (manifest sha256 `{meta['bundle']['sha256'][:16]}...`)",
        f"- speed: {s['garment']} of {s['vertices']} vertices ({s['triangles']} triangles), {s['motion']}, "
        f"{s['frames']} frames after {s['warmup_frames']} warm-up, batch {s['batch_size']}, median of "
        f"{s['repeats']}; onnxruntime {meta['env']['onnxruntime']} CPU, {meta['threads']} intra-op threads "
        f"({meta['env']['cpu_count']} CPUs visible)",
        f"- error: {meta['error_source']}",
        f"- targets (issue #12, {TARGET_VERTICES}-vertex shirt, {TARGET_THREADS} CPU cores): detail <= "
        f"{TARGET_DETAIL_MS:g} ms/frame, a fast tier <= {TARGET_FAST_MS:g} ms/frame; printed, not asserted",
        "",
        "| tier | precision | ms/frame | setup ms | mean mm | p95 mm | target |",
        "|---|---|---:|---:|---:|---:|---|",
    ]
    body = []
    for r in rows.values():
        if r.na:
            body.append(f"| {r.tier} | {r.precision} | {r.precision}: n/a ({r.na}) | | | | {_target(r)} |")
        else:
            star = " *" if r.pareto else ""
            body.append(f"| {r.tier}{star} | {r.precision} | {_f(r.ms_per_frame)} | {_f(r.setup_ms, 0)} | "
                        f"{_f(r.mean_mm)} | {_f(r.p95_mm)} | {_target(r)} |")
    star = ["", "`*`: on the Pareto front of ms/frame and mean error."] if any(r.pareto for r in rows.values()) else []
    foot = star + [""] + [f"- {x}" for x in lines_after]
    return "\n".join(head + body + foot) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bundle", type=Path, help="model bundle folder, any category (default: the shipped tshirt "
                                                "bundle)")
    p.add_argument("--data", type=Path, help="a cloth-usd datagen folder: error on its test splits")
    p.add_argument("--vertices", type=int, default=TARGET_VERTICES, help="target shirt vertex count")
    p.add_argument("--garment", type=Path, help="a stage whose garment is timed instead of a made shirt (needed for "
                                                "a garment's own bundle: train-garment's stage; and for a dress or "
                                                "trousers bundle)")
    p.add_argument("--frames", type=int, default=48, help="timed frames (after one warm-up batch)")
    p.add_argument("--repeats", type=int, default=3, help="timed runs of the frames; the median is reported")
    p.add_argument("--threads", type=int, default=TARGET_THREADS, help="onnxruntime intra-op (and BLAS) threads")
    p.add_argument("--batch-size", type=int, default=4,
                   help="frames per model call (bake's default is 16; peak memory grows with it)")
    p.add_argument("--eval-frames", type=int, help="error on only the first frames of each test sequence")
    p.add_argument("--no-torch", action="store_true", help="skip the torch eager comparison")
    p.add_argument("--out", type=Path, default=Path("out/bench_tiers"), help="output folder")
    a = p.parse_args(argv)
    if min(a.frames, a.repeats, a.threads, a.batch_size, a.vertices) < 1:
        p.error("--frames, --repeats, --threads, --batch-size and --vertices must be >= 1")
    warnings.filterwarnings("ignore")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(logging.ERROR)  # quantize_dynamic's advice to pre-process (root logger)
    logging.getLogger("cloth_usd").setLevel(logging.WARNING)
    import onnxruntime
    from threadpoolctl import threadpool_limits

    from cloth_usd.errors import ClothUsdError
    from cloth_usd.runtime.bundle import MANIFEST, find_bundle, load_bundle

    if a.bundle is not None and not a.bundle.is_dir():
        print(f"bench_tiers: --bundle {a.bundle}: no such folder", file=sys.stderr)
        return 2
    try:  # a bundle folder of any category; a folder of bundles (or none) gives its T-shirt bundle
        if a.bundle is not None and (a.bundle / MANIFEST).is_file():
            bundle = load_bundle(a.bundle)
        else:
            bundle = find_bundle("tshirt", [a.bundle] if a.bundle else None)
    except ClothUsdError as exc:
        print(f"bench_tiers: {exc}", file=sys.stderr)
        return 2
    if bundle is None:
        print("bench_tiers: no shipped tshirt bundle yet; pass --bundle DIR", file=sys.stderr)
        return 2
    if bundle.category.value != "tshirt" and a.garment is None:
        print(f"bench_tiers: --bundle {a.bundle} is a {bundle.category.value} bundle and the made garment a T-shirt; "
              f"pass --garment STAGE.usda with a {bundle.category.value}", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    rows = {("skinning", "fp64"): Row("skinning", "fp64")}
    for tier in ("coarse", "detail"):
        for precision in ("fp32", "int8"):
            rows[(tier, precision)] = Row(tier, precision)
    if "detail" not in [t.value for t in bundle.tiers]:
        for precision in ("fp32", "int8"):
            rows[("detail", precision)].na = "the bundle has no detail model"
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_tiers_") as tmp:
        int8_path, failed = quantize_bundle(bundle, Path(tmp) / "int8")
        for tier, reason in failed.items():
            rows[(tier, "int8")].na = rows[(tier, "int8")].na or reason
        paths = {"fp32": bundle.path, "int8": int8_path}
        with threadpool_limits(limits=a.threads, user_api="blas"):
            speed, graph = measure_speed(paths, rows, vertices=a.vertices, frames=a.frames, repeats=a.repeats,
                                         threads=a.threads, batch_size=a.batch_size, garment=a.garment)
        if a.no_torch or graph is None or bundle.garment is not None:  # outside the BLAS limit: under it torch
            # eager runs 10x slower; a garment's own models are not the graph models it builds
            ratio = ["onnxruntime / torch eager: skipped" + (" (--no-torch)" if a.no_torch else "")]
        else:
            ratio = torch_ratio(bundle.path, graph=graph, threads=a.threads, batch_sizes=sorted({1, a.batch_size}))
        error_info = {}
        if a.data is not None:
            error_info = measure_error(paths, rows, a.data, a.out, max_frames=a.eval_frames, batch_size=a.batch_size)
    front = pareto_front(list(rows.values()))
    for r in front:
        r.pareto = True
    lines = [_speedup(rows, "coarse"), _speedup(rows, "detail")]
    c, d = rows[("coarse", "fp32")], rows[("detail", "fp32")]
    if not (c.na or d.na or math.isnan(c.ms_per_frame) or math.isnan(d.ms_per_frame)):
        lines.append(f"detail / coarse time (fp32): {d.ms_per_frame / c.ms_per_frame:.2f}x")
    inside = [f"{r.label} {r.model_ms:.1f} of {r.ms_per_frame:.1f}" for r in rows.values()
              if not (r.na or math.isnan(r.model_ms))]
    if inside:
        lines.append("ms/frame inside onnxruntime (the rest: body posing, features, post-process): "
                     + "; ".join(inside))
    lines.extend(ratio)
    for name, tier, limit in (("detail", "detail", TARGET_DETAIL_MS), ("fast tier", "coarse", TARGET_FAST_MS)):
        done = [r for r in rows.values() if r.tier == tier and not r.na and not math.isnan(r.ms_per_frame)]
        if done:
            b = min(done, key=lambda r: r.ms_per_frame)
            lines.append(f"target {name} <= {limit:g} ms/frame: best {tier} {b.precision} {b.ms_per_frame:.1f} "
                         f"ms/frame -> {'met' if b.ms_per_frame <= limit else 'NOT met'}")
    if speed["vertices"] != TARGET_VERTICES or a.threads != TARGET_THREADS:
        lines.append(f"note: measured at {speed['vertices']} vertices / {a.threads} threads; the targets are "
                     f"for {TARGET_VERTICES} / {TARGET_THREADS}")
    if a.data is None:
        lines.append("no --data: no error columns, no pareto.png")
    meta = {
        "bundle": {"path": str(bundle.path.resolve()), "name": bundle.name, "sha256": bundle.sha256},
        "speed": speed,
        "threads": a.threads,
        "env": {"onnxruntime": onnxruntime.__version__, "numpy": np.__version__, "python": platform.python_version(),
                "cpu_count": os.cpu_count(), "machine": platform.machine(), "processor": platform.processor()},
        "error_source": (f"`{a.data}` test splits, all sequences"
                         + (f" (first {a.eval_frames} frames each)" if a.eval_frames else "")
                         + " by cloth_usd.evaluate.evaluate_bundle (per-vertex distance to the simulation, "
                         "after the post-process)") if a.data else "none (no --data)",
    }
    table = markdown(rows, meta, lines)
    print(table, end="")
    (a.out / "table.md").write_text(table)
    if a.data is not None:
        plot_pareto(list(rows.values()), front, a.out / "pareto.png",
                    f"{bundle.name}: {speed['vertices']}-vertex garment, {a.threads} threads")
    result = {
        **meta,
        "data": {"path": str(a.data.resolve()), "max_frames": a.eval_frames, "evaluations": error_info}
        if a.data else None,
        "targets_ms_per_frame": {"detail": TARGET_DETAIL_MS, "fast_tier": TARGET_FAST_MS,
                                 "vertices": TARGET_VERTICES, "threads": TARGET_THREADS},
        "rows": [{**{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(r).items()},
                  "target": _target(r)} for r in rows.values()],
        "lines": lines,
        "seconds": time.perf_counter() - t0,
    }
    (a.out / "bench.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {a.out / 'table.md'}, {a.out / 'bench.json'}"
          + (f", {a.out / 'pareto.png'}" if a.data is not None else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
