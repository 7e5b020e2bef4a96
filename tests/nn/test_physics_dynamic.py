"""The dynamic physics objective: windows of three frames, the inertia term, the options, a run."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import TINY, one_thread  # noqa: E402,F401 (one_thread: an autouse fixture)

from cloth_usd.core.pipeline import CoarseBase  # noqa: E402
from cloth_usd.core.scene import Tier  # noqa: E402
from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.nn.data import Split  # noqa: E402
from cloth_usd.nn.physics import Material, garment_rest  # noqa: E402
from cloth_usd.nn.physics_train import (TERMS, VAL_TERMS, PhysicsClip, PhysicsOptions, _Inputs, _terms, _Tier,  # noqa: E402
                                        _window, _Window, load_physics_config, physics_set, train_physics,
                                        window_batches)
from cloth_usd.nn.train import TrainConfig, _Tensors, load_run  # noqa: E402

DYNAMIC = PhysicsOptions(dynamic=True)
STATIC = PhysicsOptions()


# --------------------------------------------------------------------------- options


def test_the_options_come_from_the_physics_table_of_the_run_config(tmp_path):
    path = tmp_path / "run.json"
    path.write_text(json.dumps({"objective": "physics", "epochs": 3,
                                "physics": {"dynamic": True, "detach_history": False}}))
    config, options = load_physics_config(path, epochs=5, batch=None)
    assert config.epochs == 5 and config.batch == TrainConfig().batch
    assert options == PhysicsOptions(dynamic=True, detach_history=False) and options.window == (-2, -1, 0)
    assert load_physics_config(None)[1] == STATIC and STATIC.window == (0,)
    path.write_text(json.dumps({"physics": {"dynamics": True}}))
    with pytest.raises(ArgumentError, match=r"unknown keys \['dynamics'\].*valid: dynamic, detach_history"):
        load_physics_config(path)
    with pytest.raises(ArgumentError, match="friction needs dynamic"):
        PhysicsOptions(friction=True)
    with pytest.raises(ArgumentError, match="true or false"):
        PhysicsOptions(dynamic="yes")
    with pytest.raises(ArgumentError, match="friction_epsilon"):
        PhysicsOptions(dynamic=True, friction=True, friction_epsilon=0.0)


@pytest.mark.parametrize("name, dynamic", [("train_detail_physics", False), ("train_detail_physics_dynamic", True)])
def test_the_detail_physics_configs_load(name, dynamic):
    from pathlib import Path

    config, options = load_physics_config(Path(__file__).resolve().parents[2] / "configs" / f"{name}.json")
    assert config.objective.value == "physics" and config.bending_scale == 1.0 and config.width == 0.125
    assert options.dynamic is dynamic and options.detach_history and not options.friction


# --------------------------------------------------------------------------- windows


def _fake(num_frames: int, **meta):
    return SimpleNamespace(num_frames=num_frames, meta=meta)


def test_every_window_is_three_consecutive_frames_of_one_clip():
    clips = [_fake(7), _fake(2), _fake(5, warmup_frames=3)]
    batches = window_batches(clips, 2, np.random.default_rng(0))
    seen = sorted((k, int(t)) for k, ts in batches for t in ts)
    assert seen == [(0, t) for t in range(2, 7)] + [(2, 3), (2, 4)]  # too short: none; warm-up: left out
    assert all(len(ts) <= 2 and len({k}) == 1 for k, ts in batches)
    static = window_batches(clips, 10, window=(0,))  # quasi-static: every frame
    np.testing.assert_array_equal(static[0][1], np.arange(7))
    np.testing.assert_array_equal(window_batches(clips, 10, frames=2)[0][1], [2, 6])
    with pytest.raises(ArgumentError, match="ending at 0"):
        window_batches(clips, 2, window=(-1, 1))


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    path = tmp_path_factory.mktemp("dynamic") / "tiny.json"
    path.write_text(json.dumps({**TINY, "garment_vertices": 300, "max_frames": 5}))
    return path, physics_set(path, splits=(Split.TRAIN, Split.VAL))


def test_the_window_inputs_are_the_clip_frames_t_minus_2_t_minus_1_t(planned):
    _, data = planned
    clip = data.split(Split.TRAIN)[0]
    assert clip.fps == 24.0 and clip.dt == pytest.approx(1 / 24)
    step = _Tier(Tier.COARSE, _body(), CoarseBase.SKINNED, _Tensors(torch.device("cpu")))
    t = np.array([4, 2, 3])
    win = _window(step, clip, t, DYNAMIC)
    assert win.index.shape == (3, 3) and win.inputs.base.shape[0] == 5  # frames 0..4, each computed once
    for w, offset in enumerate((-2, -1, 0)):
        alone = step.inputs(clip, t + offset)
        np.testing.assert_allclose(win.inputs.base[win.index[w]], alone.base, atol=1e-12)
        np.testing.assert_allclose(win.inputs.body_points[win.index[w]], alone.body_points, atol=1e-12)


def test_the_clip_rate_is_its_motion_spec_rate(tmp_path):
    path = tmp_path / "fps.json"
    at_30 = {key: [{**m, "fps": 30.0} for m in TINY[key]] for key in ("train_motions", "test_motions")}
    path.write_text(json.dumps({**TINY, **at_30, "garment_vertices": 300, "max_frames": 3,
                                "sim": {**TINY["sim"], "fps": 30.0}}))
    data = physics_set(path, splits=(Split.TRAIN,))
    assert {c.fps for c in data.clips} == {30.0}


# --------------------------------------------------------------------------- the energy


def _triangle_case():
    """One triangle (0.1 m legs) over three frames, a body plane 1 mm below it."""
    rest_points = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, 0.1]])
    faces = np.array([[0, 2, 1]])
    material = Material(density=0.2)
    rest = garment_rest(rest_points, faces, material, dtype=torch.float64)
    clip = PhysicsClip(name="tri", split=Split.TRAIN, pair=None, rest=rest, rest_points=rest_points,
                       poses=np.zeros((3, 72)), transl=np.zeros((3, 3)), meta={}, fps=30.0)
    x = torch.from_numpy(np.stack([rest_points + [0.0, -0.01 * k * k, 0.002 * k] for k in range(3)]))
    x[2, 1, 0] += 0.01  # stretch one edge at t
    body = np.broadcast_to(rest_points + [0.0, -0.025, 0.0], (3, 3, 3)).copy()
    normals = np.broadcast_to([0.0, 1.0, 0.0], (3, 3, 3)).copy()
    inputs = _Inputs(features=np.zeros((3, 3, 7)), attributes=None, base=x.numpy().copy(), body_points=body,
                     body_normals=normals, cloud_points=body, cloud_normals=normals)  # each vertex's nearest: its own
    return clip, material, rest, x, inputs


def test_the_dynamic_energy_is_the_static_one_plus_the_inertia_by_hand():
    clip, material, rest, x, inputs = _triangle_case()
    dynamic = _terms(clip, x, _Window(inputs, np.array([[0], [1], [2]])), material, DYNAMIC)
    static = _terms(clip, x, _Window(inputs, np.array([[2]])), material, STATIC)
    # by hand: m_i = density x area / 3, y = 2 x_1 - x_0, E = sum m |x_2 - y|^2 / (2 h^2), h = 1/30
    m = 0.2 * (0.5 * 0.1 * 0.1) / 3.0
    accel = x[2].numpy() - 2.0 * x[1].numpy() + x[0].numpy()
    inertia = m * np.sum(accel ** 2) / (2.0 * (1.0 / 30.0) ** 2)
    assert float(dynamic["inertia"]) == pytest.approx(inertia, rel=1e-12) and inertia > 0.0
    assert float(dynamic["total"]) == pytest.approx(float(static["total"]) + inertia, rel=1e-12)
    for name in ("membrane", "bending", "gravity", "contact"):
        assert float(dynamic[name]) == pytest.approx(float(static[name]), rel=1e-12, abs=1e-18)
    assert float(static["membrane"]) > 0.0 and float(static["inertia"]) == 0.0
    assert set(dynamic) == {*TERMS, "total"} and float(dynamic["friction"]) == 0.0


def test_detaching_the_history_keeps_the_value_and_stops_its_gradient():
    clip, material, _, x, inputs = _triangle_case()
    win = _Window(inputs, np.array([[0], [1], [2]]))
    grads = {}
    for detach in (True, False):
        xg = x.clone().requires_grad_(True)
        e = _terms(clip, xg, win, material, PhysicsOptions(dynamic=True, detach_history=detach))["total"].sum()
        (grads[detach],) = torch.autograd.grad(e, xg)
        grads[detach, "value"] = float(e.detach())
    assert grads[True, "value"] == pytest.approx(grads[False, "value"], rel=1e-12)
    assert float(grads[True][:2].abs().max()) == 0.0 and float(grads[False][:2].abs().max()) > 0.0
    torch.testing.assert_close(grads[True][2], grads[False][2], rtol=1e-12, atol=0.0)
    # backpropagated: d/dx_{t-1} of the inertia is -2 x d/dx_t of it
    g_inertia = (x[2] - 2 * x[1] + x[0]) * rest_mass(clip)[:, None] / (1.0 / 30.0) ** 2
    torch.testing.assert_close(grads[False][1], -2.0 * g_inertia, rtol=1e-9, atol=1e-12)


def rest_mass(clip):
    return clip.rest.masses


def test_friction_resists_sliding_along_the_body_and_not_across_it():
    clip, material, _, x, inputs = _triangle_case()
    inputs = _Inputs(inputs.features, None, inputs.base, inputs.base - [0.0, 1e-3, 0.0], inputs.body_normals,
                     inputs.base - [0.0, 1e-3, 0.0], inputs.body_normals)
    win = _Window(inputs, np.array([[0], [1], [2]]))
    options = PhysicsOptions(dynamic=True, friction=True)
    assert float(_terms(clip, x, win, material, options)["friction"]) == 0.0  # the body moved with it
    slid = inputs.body_points.copy()
    slid[2] += [0.01, 0.0, 0.0]  # the body slides 1 cm under the garment in the step t-1 -> t
    e = _terms(clip, x, _Window(_Inputs(inputs.features, None, inputs.base, slid, inputs.body_normals, slid,
                                        inputs.body_normals),
                                win.index), material, options)
    assert float(e["friction"]) > 0.0
    across = inputs.body_points.copy()
    across[2] += [0.0, 0.005, 0.0]  # along the normal: no friction
    e = _terms(clip, x, _Window(_Inputs(inputs.features, None, inputs.base, across, inputs.body_normals, across,
                                        inputs.body_normals),
                                win.index), material, options)
    assert float(e["friction"]) == 0.0


# --------------------------------------------------------------------------- a run


@pytest.mark.slow
def test_a_dynamic_run_trains_and_records_its_options(planned, tmp_path):
    path, _ = planned
    config = TrainConfig(objective="physics", coarse_base="skinned", width=0.0625, epochs=2, batch=2, max_batches=2,
                         stat_frames=2, bending_scale=10.0, lr=2e-3)
    options = PhysicsOptions(dynamic=True, friction=True)
    result = train_physics(path, tmp_path / "run", config, device="cpu", options=options)
    assert all(np.isfinite(r.train_loss) and np.isfinite(r.val_loss) and r.val_mm > 0 for r in result.history)
    run = load_run(tmp_path / "run")
    assert run.info["physics"]["options"] == options.to_json() and run.info["physics"]["fps"] == [24.0]
    rows = (tmp_path / "run" / VAL_TERMS).read_text().splitlines()
    assert len(rows) == 3 and "model_inertia" in rows[0] and "base_friction" in rows[0]
    last = dict(zip(rows[0].split(","), map(float, rows[-1].split(","))))
    assert last["model_total"] - last["base_total"] == pytest.approx(result.history[-1].val_loss, rel=1e-6)
    assert last["base_inertia"] > 0.0  # the skinned garment accelerates with the body


def _body():
    from cloth_usd.core.body import load_body_model

    return load_body_model()
