"""Evaluation of a model bundle on the data set's test splits (issue #4, part 4).

For every test sequence the garment is animated by

- the skinning tier, exactly as the baker does it (:func:`cloth_usd.core.skinning.skin_garment`);
- the bundle's coarse and detail tiers through the runtime (onnxruntime,
  :class:`cloth_usd.runtime.LearnedGarment`, post-process included): what a bake gives;
- optional ablation runs (torch, through the same :func:`cloth_usd.core.pipeline.run_tiers`):
  a detail run on top of the bundle's coarse model, or a coarse run alone;

and compared with the simulated garment: the error of a vertex in a frame is its
Euclidean distance to the simulated position [mm]. Rows: every test split (unseen bodies,
unseen shirts, unseen motions), broken down by body build (thin / regular / fat) and shirt
length (short / long), and all of them together. Written to the report folder:
``report.md`` (the tables), ``metrics.json`` (every number, with the bundle's and data
set's hashes), ``histograms.npz`` (counts in 0.15 mm bins, as the paper plots them),
``histograms.png`` and ``means.png``. When the data set holds held-pose sequences
(:mod:`cloth_usd.datagen.floor`), the report gives the per-frame error floor beside the tables.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .core.body import BodyModel
from .core.pipeline import CoarseForm, run_tiers
from .core.skinning import skin_garment
from .datagen.floor import floor_report
from .errors import ArgumentError

__all__ = ["HIST_BIN_MM", "HIST_MAX_MM", "ErrorStats", "EvaluationReport", "evaluate_bundle",
           "body_label", "shirt_labels", "garment_reads", "learned_garment"]

log = logging.getLogger(__name__)

#: Histogram bin width [mm] (the paper's).
HIST_BIN_MM = 0.15
#: Errors above this [mm] are counted in the histogram's overflow bin.
HIST_MAX_MM = 150.0
REPORT_FORMAT = 1
_BUILDS = ("thin", "regular", "fat")
_SPLIT_TITLES = {"test_body": "unseen bodies", "test_garment": "unseen shirts", "test_motion": "unseen motions"}


@dataclass
class ErrorStats:
    """Running mean, maximum and 0.15 mm histogram of per-vertex errors [mm]."""

    total: float = 0.0
    count: int = 0
    maximum: float = 0.0
    counts: np.ndarray = field(default_factory=lambda: np.zeros(int(round(HIST_MAX_MM / HIST_BIN_MM)), np.int64))
    """Histogram counts of ``[k * 0.15, (k + 1) * 0.15)`` mm."""
    tail: list = field(default_factory=list)
    """The errors of :data:`HIST_MAX_MM` or more themselves (arrays [mm]), for the quantiles past
    the histogram's end."""

    def add(self, errors_mm: np.ndarray) -> None:
        e = np.asarray(errors_mm, dtype=np.float64).ravel()
        self.total += float(e.sum())
        self.count += e.size
        self.maximum = max(self.maximum, float(e.max(initial=0.0)))
        k = np.floor(e / HIST_BIN_MM).astype(np.int64)
        inside = k < self.counts.shape[0]
        self.counts += np.bincount(k[inside], minlength=self.counts.shape[0])
        if not inside.all():
            self.tail.append(e[~inside])

    @property
    def overflow(self) -> int:
        """How many errors were :data:`HIST_MAX_MM` or more."""
        return sum(t.size for t in self.tail)

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def quantile(self, q: float) -> float:
        """The ``q`` quantile [mm], to the histogram's resolution (bin centre), or exact past its
        end (:data:`HIST_MAX_MM`); NaN when empty."""
        if not self.count:
            return math.nan
        cum = np.cumsum(self.counts)
        k = int(np.searchsorted(cum, q * self.count, side="left"))
        if k < self.counts.shape[0]:
            return (k + 0.5) * HIST_BIN_MM
        tail = np.sort(np.concatenate(self.tail))
        rank = int(math.ceil(q * self.count - cum[-1])) - 1
        return float(tail[min(max(rank, 0), tail.size - 1)])


def body_label(meta: dict) -> str:
    """thin / regular / fat from the job's ``body_label`` or its body name (``medium_thin``...)."""
    if meta.get("body_label"):
        return str(meta["body_label"])
    body = str(meta.get("body", "?"))
    build = body.rsplit("_", 1)[-1]
    return build if build in _BUILDS else body


def shirt_labels(metas: Iterable[dict]) -> dict[int, str]:
    """short / long per shirt index: the job's ``shirt_label`` if the factory wrote one, else
    by hem height among the given shirts (highest hem: short, lowest: long, others: ``shirt<i>``)."""
    hems: dict[int, float | None] = {}
    labels: dict[int, str] = {}
    for meta in metas:
        i = int(meta.get("shirt", -1))
        if meta.get("shirt_label"):
            labels[i] = str(meta["shirt_label"])
        hems[i] = (meta.get("shirt_params") or {}).get("hem")
    known = {i: h for i, h in hems.items() if h is not None and i not in labels}
    if len(known) >= 2:
        ordered = sorted(known, key=lambda i: known[i])
        labels[ordered[0]], labels[ordered[-1]] = "long", "short"
    return {i: labels.get(i, f"shirt{i}") for i in hems}


@dataclass(frozen=True)
class EvaluationReport:
    """What :func:`evaluate_bundle` returns."""

    out_dir: Path
    tiers: tuple[str, ...]
    """Column names: skinning, coarse, detail, then the ablations."""
    rows: tuple[dict, ...]
    """One per test set: key, title, sequences, frames, and per tier mean / median / p95 [mm]."""
    metrics: dict
    """The content of ``metrics.json``."""


def garment_reads(bundle, clips) -> str:
    """Which rest of a data set's sequences ``bundle`` reads: ``draped`` (the garment the
    simulation starts from) or ``authored`` (the garment handed to the simulator, before its
    drape: :attr:`~cloth_usd.nn.data.Clip.authored_points`).

    A category's bundle reads the draped garment, as it always has. A garment's own bundle
    learned its displacement from one rest garment (:meth:`ModelBundle.trained_rest`): it reads
    the one of the two that is that garment on its own body (a garment handed over as the
    draped garment of another data set is the draped one there); without a record, the
    authored one, which a bake of the authored garment reads.
    """
    if bundle.garment is None:
        return "draped"
    for clip in clips:
        rest = bundle.trained_rest(clip.pair.betas)
        if rest is None or clip.rest_points.shape != rest.shape:
            continue  # another body (the garment carried there the same way both ways), or no record
        if clip.authored_points is not None and np.abs(clip.authored_points - rest).max() < 1e-4:
            return "authored"
        if np.abs(clip.rest_points - rest).max() < 1e-4:
            return "draped"
    return "authored" if all(c.authored_points is not None for c in clips) else "draped"


def learned_garment(bundle, body: BodyModel, clip, reads: str = "draped", **settings):
    """A test sequence's garment on ``bundle`` (a :class:`~cloth_usd.runtime.garment.LearnedGarment`,
    made with ``settings``: its ``smoothing``, for instance),
    reading its draped rest or, with ``reads="authored"`` (:func:`garment_reads`) and a data set
    that keeps it, the garment before the drape. (A garment's own model read from another rest
    than the one it learned from would, for instance, drape an already draped garment again.)
    """
    from .runtime.garment import LearnedGarment

    if reads == "authored" and clip.authored_points is not None:
        return LearnedGarment(bundle, body, clip.pair.betas, clip.authored_points, clip.pair.faces, **settings)
    return LearnedGarment(bundle, body, clip.pair.betas, clip.rest_points, clip.pair.faces, binding=clip.pair.binding,
                          **settings)


def _ablation_label(run) -> str:
    c = run.config
    parts = [p for p, off in (("no decomposition", not c.decompose),
                              ("no parser", run.tier.value == "detail" and not c.use_parser)) if off]
    if run.tier.value == "coarse":  # coarse runs differ in what they learn: say it
        parts += [f"{c.coarse_base.value} base", "Taubin target" if c.coarse_target.value == "taubin"
                  else "Laplacian target"]
    what = ", ".join(parts) if parts else f"run {run.path.name}"
    return f"{run.tier.value} ({what})"


def _row_keys(split: str, label: str | None) -> list[tuple[str, str]]:
    title = _SPLIT_TITLES.get(split, split)
    keys = [("all", "all test sets"), (split, f"{title} (all)")]
    if label is not None:
        keys.append((f"{split}:{label}", f"{title}: {label}"))
    return keys


def _row_order(key: str) -> tuple:
    if key == "all":
        return (9, 0, "")
    split, _, label = key.partition(":")
    rank = {"thin": 0, "regular": 1, "fat": 2, "short": 0, "long": 1}.get(label, 5)
    return (list(_SPLIT_TITLES).index(split) if split in _SPLIT_TITLES else 8, 0 if label else 1, rank, label)


def _session_coarse_fn(session):
    """A :data:`cloth_usd.core.pipeline.CoarseFn` over an onnxruntime session."""
    from .runtime.io import OUTPUT, coarse_inputs

    def run(features: np.ndarray, graph) -> np.ndarray:
        return session.run(coarse_inputs(features, graph.table))[OUTPUT]

    return run


def evaluate_bundle(data_dir: str | Path, bundle: str | Path, out_dir: str | Path, *,
                    ablation_runs: Sequence[str | Path] = (), body: BodyModel | None = None,
                    max_frames: int | None = None, batch_size: int = 16, device: str = "cpu",
                    splits: Sequence[str] = ("test_body", "test_garment", "test_motion"),
                    rest: str = "trained") -> EvaluationReport:
    """Evaluate a bundle (and ablation runs) on the test splits; write the report folder.

    Args:
        data_dir: a ``cloth-usd datagen`` folder.
        bundle: the model bundle folder (verified on load).
        out_dir: the report folder (created; its report files are replaced).
        ablation_runs: training run folders evaluated with torch: detail runs on the
            bundle's coarse model, coarse runs alone.
        body: the body model the data was simulated with (default: the embedded one).
        max_frames: evaluate only the first frames of each sequence.
        batch_size: frames per model call.
        device: torch device of the ablation runs (``cpu``, ``cuda``, ``auto``).
        splits: the test splits to evaluate.
        rest: the rest garment the tiers read. ``trained``: the learned tiers the one the
            bundle was trained on (:func:`garment_reads`), skinning the draped one the
            simulation starts from; ``authored``: every tier the garment as it was handed to
            the simulator, before its drape, as a bake of the authored garment reads it (needs
            a data set that keeps its drapes); ``draped``: every tier the draped one.
    Raises:
        ArgumentError: no test sequences, or a bad folder.
    """
    from .core.files import file_sha256
    from .nn.data import load_dataset
    from .runtime.bundle import load_bundle

    bundle_obj = load_bundle(bundle)
    data = load_dataset(data_dir, splits, body=body, max_frames=max_frames)
    clips = data.clips
    if not clips:
        raise ArgumentError(f"--data {data_dir}: no accepted sequences in the splits {', '.join(splits)}")
    body = data.body
    if bundle_obj.garment is not None:  # a garment's own bundle: the sequences that wear that garment
        worn = [c for c in clips if bundle_obj.garment.serves(len(c.rest_points), c.pair.faces)]
        if not worn:
            raise ArgumentError(f"--data {data_dir}: no sequence wears the garment bundle '{bundle_obj.name}' was "
                                f"trained for ({bundle_obj.garment.vertices} vertices)")
        if len(worn) < len(clips):
            log.warning("%s: %d of %d sequences wear other garments than bundle '%s''s; measuring the %d that wear "
                        "its own", data_dir, len(clips) - len(worn), len(clips), bundle_obj.name, len(worn))
        clips = worn
    if rest not in ("trained", "authored", "draped"):
        raise ArgumentError(f"--rest {rest!r}: expected trained, authored or draped")
    if rest == "authored":
        if ablation_runs:
            raise ArgumentError("--rest authored: the ablation runs read the draped garment; leave one of them out")
        missing = [c.name for c in clips if c.authored_points is None]
        if missing:
            raise ArgumentError(f"--rest authored: --data {data_dir} keeps no drape of {len(missing)} sequences "
                                f"({missing[0]}, ...): it has no garment from before the drape to read")
    reads = garment_reads(bundle_obj, clips) if rest == "trained" else rest
    trained_on = bundle_obj.manifest.get("training_data", {}).get("manifest_sha256")
    if trained_on != data.manifest_sha256:
        log.warning("%s: the bundle was trained on another data set (manifest sha256 %s...)", data_dir,
                    str(trained_on)[:12])
    shipped_coarse = _session_coarse_fn(bundle_obj.session("coarse"))
    # (label, models for run_tiers, how they run)
    runs: list[tuple[str, tuple, CoarseForm]] = []
    ablations: dict[str, dict] = {}
    if ablation_runs:
        from .nn.inference import pick_device, torch_coarse_fn, torch_detail_fn
        from .nn.runs import BEST, load_run

        dev = pick_device(device)

        shipped = (bundle_obj.manifest["models"]["coarse"].get("config", {}).get("train", {}) or {}).get("best_sha256")
        for path in ablation_runs:
            run = load_run(path, device=dev)
            label = _ablation_label(run)
            if label in ablations:
                label = f"{label} [{run.path.name}]"
            used = (run.info.get("coarse_run") or {}).get("best_sha256")
            record = {"run": str(run.path), "tier": run.tier.value, "config": run.config.to_json(),
                      "best_epoch": run.epoch, "best_sha256": file_sha256(run.path / BEST)}
            if run.tier.value == "detail":
                record["coarse_matches_bundle"] = used == shipped if shipped else None
                if shipped and used != shipped:
                    log.warning("%s: trained on another coarse model than the bundle's", run.path)
            ablations[label] = record
            if run.tier.value == "detail":  # on the bundle's coarse model
                runs.append((label, (shipped_coarse, torch_detail_fn(run.model, dev)), bundle_obj.form))
            else:
                runs.append((label, (torch_coarse_fn(run.model, dev),), run.config.coarse_form))
    tiers = ["skinning", "coarse"] + (["detail"] if "detail" in [t.value for t in bundle_obj.tiers] else []) \
        + [label for label, *_ in runs]
    test_garment = [c.meta for c in clips if c.split.value == "test_garment"]
    shirts = shirt_labels(test_garment)
    stats: dict[str, dict[str, ErrorStats]] = {}
    titles: dict[str, str] = {}
    seqs: dict[str, int] = {}
    frames: dict[str, int] = {}
    labels = {clip.name: body_label(clip.meta) if clip.split.value == "test_body" else
              shirts.get(int(clip.meta.get("shirt", -1))) if clip.split.value == "test_garment" else None
              for clip in clips}
    variety = {s: {labels[c.name] for c in clips if c.split.value == s} for s in {c.split.value for c in clips}}
    left = _left_the_body(body, clips)
    if left:
        first = left[0]
        log.warning("%s: Newton's garment left the body, or the body came through it, in %d frames of %d "
                    "sequences (%s: %.0f%% of the body it covers at rest bare at frame %d): the errors there "
                    "measure that, not the models; look at them (scripts/testset_frame.py) or make the test set "
                    "again (the factory now stops there)",
                    data_dir, sum(r["frames"] for r in left), len(left), first["sequence"],
                    100 * first["max_bare"], first["frame"])
    for clip in clips:
        split = clip.split.value
        keys = _row_keys(split, labels[clip.name] if len(variety[split]) > 1 else None)
        for key, title in keys:
            titles[key] = title
            seqs[key] = seqs.get(key, 0) + 1
            frames[key] = frames.get(key, 0) + clip.num_frames
            stats.setdefault(key, {t: ErrorStats() for t in tiers})
        learned = learned_garment(bundle_obj, body, clip, reads)
        truth = clip.positions.astype(np.float64)
        skin = learned.binding if rest == "authored" else clip.pair.binding
        outputs = {"skinning": skin_garment(skin, clip.poses, clip.transl, body.parents)}
        for tier in ("coarse", "detail"):
            if tier in tiers:
                outputs[tier] = learned.evaluate(tier, clip.poses, clip.transl, batch_size=batch_size).points
        for label_, models, form in runs:
            outputs[label_] = run_tiers(body, learned.pair, clip.poses, clip.transl, *models, batch_size=batch_size,
                                        margin=learned.margin, form=form)[0]
        for tier, pts in outputs.items():
            err = np.linalg.norm(pts - truth, axis=-1) * 1000.0
            for key, _ in keys:
                stats[key][tier].add(err)
        log.info("%s: %s", clip.name, ", ".join(f"{t} {stats[keys[-1][0]][t].mean:.2f} mm" for t in tiers))
    order = sorted(stats, key=_row_order)
    rows = []
    for key in order:
        row = {"key": key, "title": titles[key], "sequences": seqs[key], "frames": frames[key],
               "vertex_frames": stats[key][tiers[0]].count,
               "mean_mm": {t: stats[key][t].mean for t in tiers},
               "median_mm": {t: stats[key][t].quantile(0.5) for t in tiers},
               "p95_mm": {t: stats[key][t].quantile(0.95) for t in tiers},
               "max_mm": {t: stats[key][t].maximum for t in tiers}}
        rows.append(row)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics = {
        "format": REPORT_FORMAT,
        "bundle": {"path": str(Path(bundle).resolve()), "name": bundle_obj.name, "sha256": bundle_obj.sha256,
                   "files": dict(bundle_obj.manifest["files"]), "coarse_base": bundle_obj.form.base.value,
                   "heading": bundle_obj.form.heading.value, "coarse_features": bundle_obj.form.features.value,
                   "reads": reads, "skinning_reads": "authored" if rest == "authored" else "draped"},
        "data": {"path": str(Path(data_dir).resolve()), "manifest_sha256": data.manifest_sha256,
                 "same_as_training": trained_on == data.manifest_sha256, "max_frames": max_frames},
        "error": "Euclidean distance of each garment vertex to the simulated one, every frame [mm]; "
                 "learned tiers after the post-process",
        "histogram_bin_mm": HIST_BIN_MM,
        "tiers": tiers,
        "ablations": ablations,
        "rows": rows,
        "floor": floor_report(data_dir),
        "left_the_body": left,
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    np.savez(out / "histograms.npz", bin_mm=HIST_BIN_MM, edges_mm=np.arange(len(ErrorStats().counts) + 1) * HIST_BIN_MM,
             **{f"{key}|{t}": np.append(stats[key][t].counts, stats[key][t].overflow) for key in order for t in tiers})
    (out / "report.md").write_text(_markdown(metrics))
    _plot(stats, order, titles, tiers, out)
    return EvaluationReport(out_dir=out, tiers=tuple(tiers), rows=tuple(rows), metrics=metrics)


def _left_the_body(body: BodyModel, clips) -> list[dict]:
    """The test sequences whose simulated garment left the body in some evaluated frame (more of the
    body it covers at rest bare than :data:`~cloth_usd.datagen.simulate.MAX_BARE`, the share past which
    the data factory stops a sequence; a data set made before that check can hold such frames), most
    bare first: sequence, frames past the share, evaluated frames, the largest share and its frame."""
    from .datagen.simulate import MAX_BARE, bare_shares

    out = []
    for clip in clips:
        bare = bare_shares(body, clip.pair.betas, clip.rest_points, clip.pair.faces, clip.positions, clip.poses,
                           clip.transl)
        past = np.nan_to_num(bare) > MAX_BARE
        if past.any():
            t = int(np.nanargmax(bare))
            out.append({"sequence": clip.name, "frames": int(past.sum()), "of": int(bare.size),
                        "max_bare": float(bare[t]), "frame": t})
    return sorted(out, key=lambda r: -r["max_bare"])


def _fmt(x: float) -> str:
    return "-" if x is None or math.isnan(x) else f"{x:.2f}"


def _markdown(metrics: dict) -> str:
    tiers = metrics["tiers"]
    b, d = metrics["bundle"], metrics["data"]
    lines = [
        f"# Evaluation of bundle `{b['name']}`",
        "",
        f"- bundle: `{b['path']}` (manifest sha256 `{b['sha256'][:16]}...`)",
        f"- data: `{d['path']}` (manifest sha256 `{d['manifest_sha256'][:16]}...`; "
        f"{'the data set the bundle was trained on' if d['same_as_training'] else 'NOT the bundle training data set'})",
        f"- coarse model: displacement added to "
        f"{'the skinned garment' if b.get('coarse_base') == 'skinned' else 'the associated body vertices (I M_b)'}",
        f"- coarse features: the associated body vertex"
        f"{' and the nearest body (contact)' if b.get('coarse_features') == 'contact' else ' (body)'}",
        f"- heading: the models see the body "
        f"{'turned to face +Z (canonical)' if b.get('heading') == 'canonical' else 'as it stands (world)'}",
        "- the learned tiers read the garment " + ("as authored, before the drape" if b.get("reads") == "authored"
                                                   else "draped, as the simulation starts")
        + "; skinning skins the " + ("authored" if b.get("skinning_reads") == "authored" else "draped") + " garment",
        f"- error: {metrics['error']}",
        f"- histograms: {metrics['histogram_bin_mm']} mm bins (`histograms.png`, `histograms.npz`)",
    ]
    for label, a in metrics["ablations"].items():
        note = "" if a.get("coarse_matches_bundle") in (True, None) else " (trained on another coarse model)"
        lines.append(f"- {label}: torch run `{a['run']}`, epoch {a['best_epoch']}{note}")
    has_ratio = "detail" in tiers
    head = ["test set", "sequences", "frames", *tiers] + (["detail / coarse"] if has_ratio else [])
    left = metrics.get("left_the_body") or []
    if left:
        lines += ["", "## Test sequences whose simulated garment left the body", "",
                  "In these frames more than a tenth of the body the garment covers at rest lies bare in Newton's "
                  "frame (the share past which the data factory now stops a sequence): the errors there measure a "
                  "garment that came off, or that the body came through, not the models. Look at them "
                  "(`scripts/testset_frame.py DATA SEQUENCE FRAME`), or make the test set again.", "",
                  "| sequence | frames past it | most bare (frame) |", "|---|---:|---:|"]
        lines += [f"| {r['sequence']} | {r['frames']} of {r['of']} | {100 * r['max_bare']:.1f}% ({r['frame']}) |"
                  for r in left]
    lines += ["", "## Mean per-vertex error [mm]", "", "| " + " | ".join(head) + " |",
              "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    for r in metrics["rows"]:
        cells = [r["title"], str(r["sequences"]), str(r["frames"])] + [_fmt(r["mean_mm"][t]) for t in tiers]
        if has_ratio:
            cells.append(_fmt(r["mean_mm"]["detail"] / r["mean_mm"]["coarse"]) if r["mean_mm"]["coarse"] else "-")
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "## Median / 95th percentile [mm]", "", "| test set | " + " | ".join(tiers) + " |",
              "|---|" + "---:|" * len(tiers)]
    for r in metrics["rows"]:
        lines.append("| " + r["title"] + " | " + " | ".join(
            f"{_fmt(r['median_mm'][t])} / {_fmt(r['p95_mm'][t])}" for t in tiers) + " |")
    floor = metrics.get("floor") or {}
    if floor:
        lines += ["", "## Per-frame error floor", "",
                  f"The moving garment against the same pose held until it settles, at {len(floor['frames'])} "
                  f"frames: mean {_fmt(floor['mean_mm'])} mm, 95th percentile {_fmt(floor['p95_mm'])} mm. No "
                  "per-frame model can remove this part of the error (it is the garment's motion history).", "",
                  "| sequence | frame | mean mm | p95 mm | max mm | last held step mm |", "|---|---:|---:|---:|---:|---:|"]
        lines += [f"| {f['sequence']} | {f['frame']} | {_fmt(f['mean_mm'])} | {_fmt(f['p95_mm'])} | "
                  f"{_fmt(f['max_mm'])} | {_fmt(f['settle_mm'])} |" for f in floor["frames"]]
    lines += ["", "## Ordering on each test set", ""]
    for r in metrics["rows"]:
        m = r["mean_mm"]
        checks = [f"coarse < skinning: {'yes' if m['coarse'] < m['skinning'] else 'NO'}"]
        if has_ratio:
            checks.append(f"detail < coarse: {'yes' if m['detail'] < m['coarse'] else 'NO'}")
        lines.append(f"- {r['title']}: " + "; ".join(checks))
    return "\n".join(lines) + "\n"


def _plot(stats: dict, order: list[str], titles: dict, tiers: list[str], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    cols = min(3, len(order))
    nrows = math.ceil(len(order) / cols)
    fig = Figure(figsize=(5 * cols, 3.4 * nrows))
    axes = np.atleast_1d(fig.subplots(nrows, cols, squeeze=False)).ravel()
    for ax, key in zip(axes, order):
        top = max(s.quantile(0.99) for s in stats[key].values() if s.count)
        top = min(max(top, 10 * HIST_BIN_MM), HIST_MAX_MM)  # errors past the histogram's end are not drawn
        for i, tier in enumerate(tiers):
            s = stats[key][tier]
            if not s.count:
                continue
            k = min(int(math.ceil(top / HIST_BIN_MM)), s.counts.shape[0])
            edges = np.arange(k + 1) * HIST_BIN_MM
            ax.stairs(s.counts[:k] / s.count, edges, label=f"{tier} ({s.mean:.2f} mm)", color=f"C{i}")
        ax.set_title(titles[key], fontsize=10)
        ax.set_xlabel(f"per-vertex error [mm] ({HIST_BIN_MM} mm bins)")
        ax.set_ylabel("fraction")
        ax.legend(fontsize=7)
    for ax in axes[len(order):]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(str(out / "histograms.png"), dpi=90)

    fig = Figure(figsize=(max(6, 1.2 * len(order) * len(tiers) / 2), 4))
    ax = fig.subplots()
    width = 0.8 / len(tiers)
    x = np.arange(len(order))
    for i, tier in enumerate(tiers):
        ax.bar(x + i * width - 0.4 + width / 2, [stats[k][tier].mean for k in order], width, label=tier,
               color=f"C{i}")
    ax.set_xticks(x, [titles[k] for k in order], rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("mean per-vertex error [mm]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(str(out / "means.png"), dpi=90)
