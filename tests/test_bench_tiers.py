"""Smoke test of bench/bench_tiers.py: its main on a hand-built bundle and a tiny data set, few frames.

The bundle's models are one-MatMul ONNX graphs built with ``onnx.helper`` (exporting real
generators takes half a minute); the data set is the factory on a 2-shirt, 2-body config
with the fake simulator of ``tests/nn/train_data.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from script_module import ROOT, load_script

SMALL = {"shirts": 2, "test_shirts": [], "bodies": ["short_thin", "tall_fat"], "test_bodies": [],
         "garment_vertices": 300, "max_frames": 2, "train_motions": [{"kind": "walk", "seconds": 1.0, "seed": 0}],
         "test_motions": [{"kind": "dance", "seconds": 1.0, "seed": 5}],
         "sim": {"substeps": 2, "iterations": 2, "collider_faces": 2000}}


def _linear_model(path: Path, inputs: tuple[str, ...], in_features: int, seed: int) -> Path:
    """``delta = features @ W`` (W a few mm); every other input is declared and unused."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    shapes = {"features": (TensorProto.FLOAT, ["B", "N", in_features]), "attributes": (TensorProto.FLOAT, ["B", 85]),
              "cluster": (TensorProto.INT64, ["N"])}
    decl = [helper.make_tensor_value_info(n, *shapes.get(n, (TensorProto.BOOL if n.endswith("mask") else
                                                             TensorProto.INT64, ["A", "C"]))) for n in inputs]
    w = np.random.default_rng(seed).normal(0, 0.003, (in_features, 3)).astype(np.float32)
    graph = helper.make_graph([helper.make_node("MatMul", ["features", "W"], ["delta"])], "linear", decl,
                              [helper.make_tensor_value_info("delta", TensorProto.FLOAT, ["B", "N", 3])],
                              [numpy_helper.from_array(w, "W")])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)]), str(path))
    return path


@pytest.fixture(scope="module")
def bundle_and_data(tmp_path_factory):
    pytest.importorskip("onnxruntime", reason="the learned tiers need onnxruntime")
    pytest.importorskip("onnx", reason="building the test models and quantizing them needs onnx")
    pytest.importorskip("matplotlib", reason="the bench plots with matplotlib")
    from cloth_usd.runtime.bundle import write_bundle
    from cloth_usd.runtime.io import COARSE_INPUTS, DETAIL_INPUTS

    tmp_path = tmp_path_factory.mktemp("bench_tiers")
    train_data = load_script("train_data", ROOT / "tests" / "nn" / "train_data.py")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(train_data, "TINY", SMALL)
        data = train_data.build_tiny_dataset(tmp_path / "data")
    coarse = _linear_model(tmp_path / "coarse.onnx", COARSE_INPUTS, 7, 0)
    detail = _linear_model(tmp_path / "detail.onnx", DETAIL_INPUTS, 30, 1)
    bundle = write_bundle(tmp_path / "bundle", name="linear-tshirt", category="tshirt", coarse_onnx=coarse,
                          detail_onnx=detail, fit_npz=data / "fit.npz", configs={},
                          training_data={"manifest_sha256": "0" * 64, "description": "tests only"},
                          metrics={}, opset=18)
    return bundle, data


def test_bench_tiers_main_writes_table_plot_and_json(bundle_and_data, tmp_path, capsys, monkeypatch):
    from cloth_usd import evaluate

    bench = load_script("bench_tiers", ROOT / "bench" / "bench_tiers.py")
    monkeypatch.setattr(evaluate, "_plot", lambda *args, **kwargs: None, raising=False)  # its histograms: 2 s
    bundle, data = bundle_and_data
    out = tmp_path / "out"
    assert bench.main(["--bundle", str(bundle), "--data", str(data), "--vertices", "300", "--frames", "2",
                       "--repeats", "1", "--batch-size", "2", "--threads", "1", "--eval-frames", "1",
                       "--no-torch", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "| tier | precision | ms/frame | setup ms | mean mm | p95 mm | target |" in printed
    assert "detail int8 / fp32 speed:" in printed
    assert (out / "table.md").read_text() in printed
    assert (out / "pareto.png").stat().st_size > 0
    result = json.loads((out / "bench.json").read_text())
    rows = {(r["tier"], r["precision"]): r for r in result["rows"]}
    assert set(rows) == {("skinning", "fp64"), ("coarse", "fp32"), ("coarse", "int8"), ("detail", "fp32"),
                         ("detail", "int8")}
    for r in rows.values():
        assert r["na"] == "" and r["ms_per_frame"] > 0 and 0 < r["mean_mm"] < 100, r
    assert result["speed"]["vertices"] > 0 and result["threads"] == 1
    assert any(r["pareto"] for r in rows.values())


def test_failed_quantization_is_reported_not_raised(bundle_and_data, tmp_path, monkeypatch):
    import onnxruntime.quantization

    from cloth_usd.runtime.bundle import load_bundle

    bench = load_script("bench_tiers", ROOT / "bench" / "bench_tiers.py")

    def refuse(model_input, model_output, **kwargs):
        if "detail" in str(model_input):
            raise NotImplementedError("no int8 kernel for OpX")
        return real(model_input, model_output, **kwargs)

    real = onnxruntime.quantization.quantize_dynamic
    monkeypatch.setattr(onnxruntime.quantization, "quantize_dynamic", refuse)
    path, failed = bench.quantize_bundle(load_bundle(bundle_and_data[0]), tmp_path / "int8")
    assert failed == {"detail": "quantization failed: NotImplementedError: no int8 kernel for OpX"}
    assert [t.value for t in load_bundle(path).tiers] == ["coarse"]


def test_another_categorys_bundle_needs_a_garment_of_its_category(bundle_and_data, tmp_path, capsys):
    from cloth_usd.core.scene import Tier
    from cloth_usd.runtime.bundle import load_bundle, write_bundle

    bench = load_script("bench_tiers", ROOT / "bench" / "bench_tiers.py")
    shirt, data = bundle_and_data
    made = load_bundle(shirt)
    dress = write_bundle(tmp_path / "dress", name="linear-dress", category="dress",
                         coarse_onnx=made.model_path(Tier.COARSE), detail_onnx=made.model_path(Tier.DETAIL),
                         fit_npz=data / "fit.npz", configs={},
                         training_data={"manifest_sha256": "0" * 64, "description": "tests only"}, metrics={},
                         opset=18)
    assert bench.main(["--bundle", str(dress), "--no-torch", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"bench_tiers: --bundle {dress} is a dress bundle and the made garment a T-shirt; pass --garment "
                   "STAGE.usda with a dress")
    assert not (tmp_path / "out").exists()


def test_bench_strain_limit_measures_each_setting_against_the_simulation(bundle_and_data, tmp_path, capsys):
    """bench/bench_strain_limit.py: the detail tier's error per strain-limit setting, side by side; a
    tighter limit moves the garment, and a malformed setting is one line naming it."""
    from cloth_usd.errors import ArgumentError

    bench = load_script("bench_strain_limit", ROOT / "bench" / "bench_strain_limit.py")
    bundle, data = bundle_and_data
    assert bench.main(["--data", str(data), "--bundle", str(bundle), "--setting", "1.10/8", "--setting",
                       "1.01/16/1e-2", "--setting", "none", "--out", str(tmp_path / "out")]) == 0
    table = capsys.readouterr().out
    assert "| 1.10/8 |" in table and "| 1.01/16/1e-2 |" in table and "| none |" in table
    rows = json.loads((tmp_path / "out" / "strain_limit.json").read_text())["rows"]
    assert [r["setting"] for r in rows] == ["1.10/8", "1.01/16/1e-2", "none"]
    assert all(np.isfinite(r["mm"]["all"]) and r["mm"]["all"] > 0 for r in rows)
    assert rows[0]["mm"]["all"] != rows[2]["mm"]["all"]  # the limiter moved the garment
    assert bench.parse_setting("1.05/16") == (1.05, 16, bench.STRAIN_ANCHOR) and bench.parse_setting("none") is None
    with pytest.raises(ArgumentError, match="1.05x16"):
        bench.parse_setting("1.05x16")


def test_bench_newton_cloth_measures_newton_and_each_tier(bundle_and_data, tmp_path, capsys):
    """bench/bench_newton_cloth.py: Newton's own frames (zero error to themselves), skinning and the
    bundle's tiers, with each frame's stretch (median and worst frame) and the share inside the body."""
    pytest.importorskip("torch", reason="the energies are the physics objective's (torch)")
    bench = load_script("bench_newton_cloth", ROOT / "bench" / "bench_newton_cloth.py")
    bundle, data = bundle_and_data
    assert bench.main(["--data", str(data), "--bundle", str(bundle), "--out", str(tmp_path / "out")]) == 0
    assert "| Newton |" in capsys.readouterr().out
    table = json.loads((tmp_path / "out" / "newton_cloth.json").read_text())
    assert {"Newton", "skinning", "linear-tshirt coarse", "linear-tshirt detail"} <= set(table)
    assert table["Newton"]["mm_after"] == 0.0 and table["skinning"]["mm_after"] > 0
    for row in table.values():
        assert 0.0 < row["p99_stretch"] <= row["p99_stretch_worst"] <= row["max_stretch_worst"]
        assert row["max_stretch"] <= row["max_stretch_worst"] and 0 <= row["frames_past_1p5"] <= row["frames_measured"]
        assert 0.0 <= row["inside_1mm_pct"] <= row["inside_pct"] <= 100.0
        after = row["after"]
        assert 0.0 < after["p99_stretch"] <= after["p99_stretch_worst"] <= after["max_stretch_worst"]
    assert table["Newton"]["after"]["max_stretch_worst"] == table["Newton"]["max_stretch_worst"]
