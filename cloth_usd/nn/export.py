"""ONNX export of the generators (torch.onnx, dynamo exporter, opset 18).

Input and output names and shapes: :mod:`cloth_usd.runtime.io`. Every dimension is
dynamic: batch B, vertices N, neighbours K, pooled clusters N2, members P, pooled
neighbours K2, so one exported file serves every garment topology. Example inputs are
built on a small synthetic grid whose dimensions are all distinct and > 1 (the exporter
specialises dimensions that equal 0, 1 or each other in the example).

:func:`export_bundle` (``cloth-usd export``) exports trained runs, checks the ONNX files
against the torch models through the runtime's pipeline on the validation data, and writes
a model bundle (:func:`cloth_usd.runtime.bundle.write_bundle`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..core.features import ATTRIBUTE_FEATURES
from ..core.graph import build_graph
from ..core.pipeline import CoarseForm
from ..runtime.io import COARSE_INPUTS, DETAIL_INPUTS, OUTPUT, detail_inputs
from .models import CoarseGenerator, DetailGenerator

__all__ = ["OPSET", "export_coarse", "export_detail", "export_bundle"]

OPSET = 18
#: The node metadata torch's exporter fills with the exporting machine's source paths and
#: line numbers: dropped, so an export's bytes depend on the model alone (the bundle's
#: sha256 then names the same file for the same graph and weights, whichever checkout made it).
STACK_TRACE = "pkg.torch.onnx.stack_trace"


def _example(model: CoarseGenerator | DetailGenerator) -> tuple[dict[str, torch.Tensor], int]:
    """Example inputs on a 9 x 7 grid with a fan vertex, batch 2."""
    nx, ny = 9, 7
    xs, ys = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float) * 1.1)
    pos = np.stack([xs.ravel(), ys.ravel(), np.zeros(nx * ny)], 1)
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    graph = build_graph(faces, pos)
    rng = np.random.default_rng(0)
    batch = 2
    feats = rng.normal(size=(batch, nx * ny, model.config.in_features))
    inputs = detail_inputs(feats, rng.normal(size=(batch, ATTRIBUTE_FEATURES)), graph)
    return {k: torch.from_numpy(v) for k, v in inputs.items()}, batch


def _dynamic_axes(name: str, ndim: int) -> range:
    """Dynamic axes of an input: all but the feature axis of ``features`` / ``attributes`` (and
    of a garment's own model's ``pose`` / ``betas``)."""
    return range(ndim - 1) if name in ("features", "attributes", "pose", "betas") else range(ndim)


def _export(model: torch.nn.Module, names: tuple[str, ...], path: Path,
            example: dict[str, torch.Tensor]) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    args = tuple(example[n] for n in names)
    dynamic = tuple({a: torch.export.Dim.DYNAMIC for a in _dynamic_axes(n, example[n].ndim)} for n in names)
    model = model.eval()
    with torch.no_grad():
        program = torch.onnx.export(model, args, input_names=list(names), output_names=[OUTPUT],
                                    dynamic_shapes=dynamic, opset_version=OPSET, dynamo=True,
                                    optimize=True, verbose=False)
    for node in program.model.graph.all_nodes():  # the source paths and lines of the export's machine
        node.metadata_props.pop(STACK_TRACE, None)
    program.save(str(path))
    return path


def export_coarse(model: CoarseGenerator, path: str | Path) -> Path:
    """Write ``model`` to ``path`` as ONNX (inputs :data:`~cloth_usd.runtime.io.COARSE_INPUTS`).

    Returns:
        The path written.
    """
    example, _ = _example(model)
    return _export(model, COARSE_INPUTS, Path(path), example)


def export_detail(model: DetailGenerator, path: str | Path) -> Path:
    """Write ``model`` to ``path`` as ONNX (inputs :data:`~cloth_usd.runtime.io.DETAIL_INPUTS`).

    Returns:
        The path written.
    """
    example, _ = _example(model)
    return _export(model, DETAIL_INPUTS, Path(path), example)


def _parity(coarse_torch, detail_torch, coarse_onnx: Path, detail_onnx: Path | None, clips, body,
            frames: int, form: CoarseForm = CoarseForm()) -> dict:
    """Largest point difference [m] between the torch models and their ONNX files, through
    the runtime's pipeline (:func:`cloth_usd.core.pipeline.run_tiers`), on ``clips``."""
    from ..core.pipeline import run_tiers
    from ..runtime.io import coarse_inputs, detail_inputs
    from ..runtime.session import ModelSession
    from .inference import torch_coarse_fn, torch_detail_fn

    sessions = {"coarse": ModelSession(coarse_onnx, prefer_gpu=False)}
    if detail_onnx is not None:
        sessions["detail"] = ModelSession(detail_onnx, prefer_gpu=False)

    def onnx_coarse(feats, graph):
        return sessions["coarse"].run(coarse_inputs(feats, graph.table))[OUTPUT]

    def onnx_detail(feats, attrs, graph):
        return sessions["detail"].run(detail_inputs(feats, attrs, graph))[OUTPUT]

    t_coarse = torch_coarse_fn(coarse_torch)
    t_detail = torch_detail_fn(detail_torch) if detail_torch is not None else None
    worst = {"coarse": 0.0, "detail": 0.0}
    used = 0
    for clip in clips:
        k = min(frames, clip.num_frames)
        poses, transl = clip.poses[:k], clip.transl[:k]
        used += k
        for tier in worst:
            if tier == "detail" and t_detail is None:
                continue
            want, _ = run_tiers(body, clip.pair, poses, transl, t_coarse, t_detail if tier == "detail" else None,
                                form=form)
            got, _ = run_tiers(body, clip.pair, poses, transl, onnx_coarse,
                               onnx_detail if tier == "detail" else None, form=form)
            worst[tier] = max(worst[tier], float(np.abs(got - want).max()))
    return {"coarse_max_m": worst["coarse"], "detail_max_m": worst["detail"] if t_detail is not None else None,
            "sequences": len(clips), "frames": used}


def export_bundle(coarse_run: str | Path, detail_run: str | Path | None, data_dir: str | Path,
                  out_dir: str | Path, *, name: str, category: str = "tshirt",
                  metrics: dict | None = None, description: str = "", parity_frames: int = 4,
                  tolerance: float = 1e-4, force: bool = False, body=None,
                  mocap_dir: str | Path | None = None, parity_data: str | Path | None = None) -> Path:
    """Export trained runs to ONNX and write a verified model bundle.

    The best-validation model of each run is exported (:func:`export_coarse`,
    :func:`export_detail`); before the bundle is written, the ONNX files are run through
    the runtime's pipeline on the first ``parity_frames`` frames of every validation
    sequence and must match the torch models within ``tolerance`` [m].

    Args:
        coarse_run, detail_run: training run folders (detail optional).
        data_dir: the data set both were trained on (its ``fit.npz`` ships in the bundle,
            the sha256 of its ``manifest.json`` is recorded); for a coarse run trained on the
            physics or hybrid objective, the data set config it was trained on (the run's own
            ``fit.npz`` ships, the config's sha256 is recorded).
        out_dir: the bundle folder (see :func:`cloth_usd.runtime.bundle.write_bundle`).
        name, category: the bundle's name and garment category.
        metrics: evaluation metrics (``cloth-usd evaluate``'s ``metrics.json``) to record.
        description: one line about the training data.
        mocap_dir: for a physics run whose config names BVH motions, their folder.
        parity_data: a data set folder whose sequences (every split) the parity check runs
            on instead of ``data_dir``'s validation split: for runs whose data set stayed
            where it was made (only its ``manifest.json`` and ``fit.npz`` came along).
    Returns:
        The bundle folder, loaded once through :func:`cloth_usd.runtime.load_bundle`.
    Raises:
        ArgumentError: runs of the wrong tier, trained on other data, or a detail run
            trained on another coarse model.
        ClothUsdError: the ONNX files do not match the torch models.
    """
    import dataclasses
    import json
    import logging
    import tempfile

    from ..core.files import file_sha256
    from ..core.scene import Tier
    from ..errors import ArgumentError, ClothUsdError
    from ..runtime.bundle import load_bundle, write_bundle
    from .data import FIT, MANIFEST, Split, load_dataset
    from .config import CoarseInput
    from .runs import BEST, load_run

    log = logging.getLogger(__name__)
    data_dir = Path(data_dir)
    coarse = load_run(coarse_run)
    detail = load_run(detail_run) if detail_run is not None else None
    if coarse.tier is not Tier.COARSE:
        raise ArgumentError(f"--coarse-run {coarse_run}: is a {coarse.tier.value} run")
    if detail is not None and detail.tier is not Tier.DETAIL:
        raise ArgumentError(f"--detail-run {detail_run}: is a {detail.tier.value} run")
    planned = ("physics", "hybrid")  # the data kinds of runs trained on a data set config's planned sequences
    if coarse.info["data"].get("kind") in planned and parity_data is not None:
        raise ArgumentError("--parity-data: only for runs trained on simulated data (these were trained on the "
                            "physics or hybrid objective, whose data set config makes the parity data)")
    if coarse.info["data"].get("kind") in planned:
        from ..core.body import load_body_model
        from ..core.limits import betas_range_record, pose_range_record
        from ..datagen.factory import load_config, train_betas, train_poses
        from .physics_train import PHYSICS_FIT, physics_set

        if detail is not None and detail.info["data"].get("kind") not in planned:
            raise ArgumentError(f"--detail-run {detail_run}: trained on simulated data, the coarse run on a data set "
                                "config (physics or hybrid); a bundle's two runs share their data")
        from ..core.fit import FitModel

        body = body if body is not None else load_body_model()
        # the run's own fit attribute model: the config's, or an initial run's (cloth-usd train --init)
        data = physics_set(data_dir, body, heading=coarse.config.heading, splits=(Split.VAL,),
                           max_frames=parity_frames, mocap_dir=mocap_dir,
                           fit=FitModel.load(coarse.path / PHYSICS_FIT))
        data_sha256, fit_npz = data.config_sha256, coarse.path / PHYSICS_FIT
        # the joint angles the runs saw, which a bake of a learned tier checks a shot against
        factory = load_config(data_dir, mocap_dir=mocap_dir)
        poses = pose_range_record(train_poses(factory, body))
        bodies = betas_range_record(train_betas(factory))
    elif parity_data is not None:  # only the training data set's manifest and fit model are here
        if not (data_dir / MANIFEST).is_file() or not (data_dir / FIT).is_file():
            raise ArgumentError(f"--data {data_dir}: needs {MANIFEST} and {FIT} (of the data set the runs were "
                                "trained on)")
        data = load_dataset(parity_data, None, body=body, max_frames=parity_frames)
        body, data_sha256, fit_npz = data.body, file_sha256(data_dir / MANIFEST), data_dir / FIT
        poses = bodies = None
    else:  # a simulated data set records no poses here: the bake checks against JOINT_LIMITS
        data = load_dataset(data_dir, (Split.VAL,), body=body, max_frames=parity_frames)
        body, data_sha256, fit_npz, poses, bodies = data.body, data.manifest_sha256, data_dir / FIT, None, None
    for run in (coarse, detail):
        if run is not None and run.info["data"]["manifest_sha256"] != data_sha256:
            raise ArgumentError(f"{run.path}: trained on another data set than {data_dir} (sha256 "
                                f"{run.info['data']['manifest_sha256'][:12]}... vs {data_sha256[:12]}...)")
    if detail is not None:
        used = (detail.info.get("coarse_run") or {}).get("best_sha256")
        if used != file_sha256(coarse.path / BEST):
            msg = (f"--detail-run {detail.path} was trained on another coarse model "
                   f"({(detail.info.get('coarse_run') or {}).get('path')}) than {coarse.path}")
            if detail.config.coarse_input is CoarseInput.PREDICTED:
                raise ArgumentError(msg)
            log.warning("%s", msg)
    clips = data.clips if parity_data is not None else data.split(Split.VAL)
    if not clips and parity_data is not None:
        raise ArgumentError(f"--parity-data {parity_data}: no sequences for the export parity check")
    if not clips:
        raise ArgumentError(f"--data {data_dir}: no validation sequences for the export parity check "
                            "(--parity-data DIR checks on another data set's sequences)")

    def train_record(run) -> dict:
        return {**dataclasses.asdict(run.model.config), "train": {
            "config": run.info["config"], "best_epoch": run.epoch, "best_sha256": file_sha256(run.path / BEST),
            "run": str(run.path.resolve())}}

    def history(run) -> dict:
        rows = json.loads((run.path / "history.json").read_text())
        best = next((r for r in rows if r["epoch"] == run.epoch), rows[-1])
        return {"best_epoch": run.epoch, "val_mm": best["val_mm"], "val_loss": best["val_loss"],
                "epochs": len(rows)}

    with tempfile.TemporaryDirectory(prefix="cloth-usd-export-") as tmp:
        tmp = Path(tmp)
        coarse_path = export_coarse(coarse.model, tmp / "coarse.onnx")
        detail_path = export_detail(detail.model, tmp / "detail.onnx") if detail is not None else None
        parity = _parity(coarse.model, detail.model if detail else None, coarse_path, detail_path, clips,
                         body, parity_frames, coarse.config.coarse_form)
        worst = max(v for v in (parity["coarse_max_m"], parity["detail_max_m"]) if v is not None)
        if not worst <= tolerance:
            raise ClothUsdError(f"export parity failed: ONNX and torch differ by {worst * 1000:.4f} mm on the "
                                f"validation data (tolerance {tolerance * 1000:.4f} mm); nothing was written")
        configs = {"coarse": train_record(coarse)}
        if detail is not None:
            configs["detail"] = train_record(detail)
        summary = {"export_parity": parity,
                   "validation": {"coarse": history(coarse), **({"detail": history(detail)} if detail else {})}}
        if metrics:
            summary["evaluation"] = _check_evaluated(metrics, coarse_path, detail_path, log)
        n_train = coarse.info["data"].get("train_sequences")
        training = {"manifest_sha256": data_sha256,
                    "description": description or f"{n_train} training sequences of {data_dir.name}"}
        simulated = {run.tier.value: run.info["hybrid"]["sim_manifest_sha256"] for run in (coarse, detail)
                     if run is not None and run.info.get("hybrid")}
        if simulated:  # hybrid runs: the simulated data of their supervised term, per tier
            training["sim_manifest_sha256"] = simulated
        if poses is not None:
            training["poses"], training["bodies"] = poses, bodies
        out = write_bundle(out_dir, name=name, category=category, coarse_onnx=coarse_path,
                           detail_onnx=detail_path, fit_npz=fit_npz, configs=configs,
                           training_data=training, metrics=summary, opset=OPSET, force=force,
                           form=coarse.config.coarse_form)
    load_bundle(out)
    return out


def _check_evaluated(metrics: dict, coarse_onnx: Path, detail_onnx: Path | None, log) -> dict:
    """The evaluation metrics, marked whether they were measured on these very ONNX files."""
    from ..core.files import file_sha256

    files = (metrics.get("bundle") or {}).get("files", {})
    now = {"coarse.onnx": file_sha256(coarse_onnx)}
    if detail_onnx is not None:
        now["detail.onnx"] = file_sha256(detail_onnx)
    same = all(files.get(k) == v for k, v in now.items())
    if not same:
        log.warning("the evaluation metrics were measured on other model files than the ones exported now "
                    "(sha256 differ); they are recorded with same_models=false")
    return {**metrics, "same_models": same}
