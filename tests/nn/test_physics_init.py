"""Physics training from a trained run (``cloth-usd train --init``) and its anchor.

The initial run is the session's tiny supervised run (``train_data.tiny_runs``): the case this
is for is a model trained supervised where its simulated frames stayed, refined here on the
garment's energy.
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import one_thread, tiny_runs  # noqa: E402,F401 (one_thread: an autouse fixture)

from cloth_usd.core.body import load_body_model  # noqa: E402
from cloth_usd.core.fit import FitModel  # noqa: E402
from cloth_usd.core.scene import Tier  # noqa: E402
from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.nn.data import Split  # noqa: E402
from cloth_usd.nn.physics_train import PhysicsOptions, _Tier, physics_set, train_physics  # noqa: E402
from cloth_usd.nn.train import TrainConfig, _Tensors, load_run  # noqa: E402

pytestmark = pytest.mark.slow
#: The supervised tiny runs' model and form (train_data.TINY_TRAIN), on the physics objective.
PHYSICS = TrainConfig(objective="physics", width=0.125, epochs=1, batch=3, max_batches=3, val_frames=3, max_frames=3,
                      bending_scale=10.0, lr=2e-3)


@pytest.fixture(scope="module")
def init(tmp_path_factory):
    """``(data config, data set folder, supervised coarse run, supervised detail run)``."""
    data, coarse, detail = tiny_runs(tmp_path_factory)
    return data.parent / f"{data.name}.json", data, coarse, detail


def _garments(run_dir, config_path, fit) -> list[np.ndarray]:
    """The run's coarse garments on each validation clip's frames [m]."""
    run = load_run(run_dir)
    clips = physics_set(config_path, splits=(Split.VAL,), max_frames=3, fit=fit).clips
    step = _Tier(Tier.COARSE, load_body_model(), run.config.coarse_form.base, _Tensors(torch.device("cpu")))
    with torch.no_grad():
        return [step.forward(run.model, c, step.inputs(c, np.arange(c.num_frames))).numpy() for c in clips]


def test_a_run_starts_from_the_initial_model_and_its_fit(init, tmp_path):
    """At a learning rate that cannot move it, the run is the initial model: the anchor's
    distance is zero and the weights are the initial ones; the fit attribute model is the
    initial run's data set's, and run.json names the initial run."""
    config_path, data, coarse, _ = init
    options = PhysicsOptions(anchor_weight=1.0e6)
    result = train_physics(config_path, tmp_path / "run", dataclasses.replace(PHYSICS, lr=1e-12), device="cpu",
                           options=options, init_run=coarse)
    assert result.history[0].val_mm < 1e-6, result.history[0].val_mm  # mm from the initial run's garment
    start = load_run(coarse).model.state_dict()
    for key, value in load_run(tmp_path / "run").model.state_dict().items():
        torch.testing.assert_close(value, start[key], atol=1e-8, rtol=0)
    ours, theirs = FitModel.load(tmp_path / "run" / "fit.npz"), FitModel.load(data / "fit.npz")
    for field in dataclasses.fields(FitModel):
        np.testing.assert_array_equal(getattr(ours, field.name), getattr(theirs, field.name))
    info = load_run(tmp_path / "run").info
    assert info["init_run"]["path"] == str(coarse.resolve()) and info["physics"]["options"]["anchor_weight"] == 1.0e6
    header = (tmp_path / "run" / "val_terms.csv").read_text().splitlines()[0].split(",")
    assert header[-2:] == ["anchor", "anchor_mm"]


def test_the_anchor_keeps_the_garment_near_the_initial_model(init, tmp_path):
    config_path, data, coarse, _ = init
    fit = FitModel.load(data / "fit.npz")
    for name, weight in (("free", 0.0), ("anchored", 1.0e9)):
        train_physics(config_path, tmp_path / name, dataclasses.replace(PHYSICS, epochs=2), device="cpu",
                      options=PhysicsOptions(anchor_weight=weight), init_run=coarse)
    start = _garments(coarse, config_path, fit)
    moved = {name: np.mean([np.linalg.norm(g - s, axis=-1).mean()
                            for g, s in zip(_garments(tmp_path / name, config_path, fit), start)])
             for name in ("free", "anchored")}
    assert moved["free"] > 1e-4, moved  # the energy moves the model by more than 0.1 mm
    assert moved["anchored"] < 0.5 * moved["free"], moved


def test_an_anchored_run_exports_a_bundle_with_the_initial_fit(init, tmp_path):
    from cloth_usd.nn.export import export_bundle
    from cloth_usd.runtime.bundle import load_bundle

    config_path, data, coarse, _ = init
    train_physics(config_path, tmp_path / "run", PHYSICS, device="cpu", options=PhysicsOptions(anchor_weight=1e6),
                  init_run=coarse)
    bundle = load_bundle(export_bundle(tmp_path / "run", None, config_path, tmp_path / "bundle", name="init-test"))
    assert bundle.manifest["metrics"]["export_parity"]["coarse_max_m"] < 1e-4
    assert (tmp_path / "bundle" / "fit.npz").read_bytes() == (tmp_path / "run" / "fit.npz").read_bytes()


def test_runs_it_cannot_start_from_are_refused(init, tmp_path, capsys):
    from cloth_usd.cli import main

    config_path, _, coarse, detail = init
    with pytest.raises(ArgumentError, match="give --init RUN"):
        train_physics(config_path, tmp_path / "a", PHYSICS, device="cpu", options=PhysicsOptions(anchor_weight=1.0))
    with pytest.raises(ArgumentError, match="a detail run; this run trains the coarse tier"):
        train_physics(config_path, tmp_path / "b", PHYSICS, device="cpu", init_run=detail)
    with pytest.raises(ArgumentError, match="its width is 0.125"):
        train_physics(config_path, tmp_path / "c", dataclasses.replace(PHYSICS, width=0.0625), device="cpu",
                      init_run=coarse)
    with pytest.raises(ArgumentError, match="its coarse_base, heading and coarse_features"):
        train_physics(config_path, tmp_path / "d", dataclasses.replace(PHYSICS, coarse_base="skinned"), device="cpu",
                      init_run=coarse)
    lost = tmp_path / "lost"  # a run whose data set stayed where it was made
    shutil.copytree(coarse, lost)
    info = json.loads((lost / "run.json").read_text())
    info["data"]["path"] = str(tmp_path / "elsewhere")
    (lost / "run.json").write_text(json.dumps(info))
    with pytest.raises(ArgumentError, match="fit attribute model is not at hand"):
        train_physics(config_path, tmp_path / "e", PHYSICS, device="cpu", init_run=lost)
    assert main(["train", "coarse", "--data", str(init[1]), "--init", str(coarse), "--device", "cpu",
                 "-o", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--init" in err and "supervised" in err, err
    assert not any((tmp_path / name).exists() for name in "abcdef")
