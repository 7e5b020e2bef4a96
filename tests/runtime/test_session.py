"""The onnxruntime session wrapper, on a model built with the onnx helper (no torch)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cloth_usd.errors import ClothUsdError

ort = pytest.importorskip("onnxruntime", reason="needs onnxruntime (pip install 'cloth-usd[runtime]')")
onnx = pytest.importorskip("onnx", reason="builds its test model with the onnx package")

from onnx import TensorProto, helper  # noqa: E402

from cloth_usd.runtime import ModelSession, coarse_inputs, pick_providers  # noqa: E402
from cloth_usd.core.graph import NeighbourTable  # noqa: E402


@pytest.fixture
def tiny_model(tmp_path):
    """delta = features[..., :3] taken at each node's first neighbour (a tiny stand-in model)."""
    nodes = [
        helper.make_node("Slice", ["features", "zero", "three", "two"], ["xyz"]),
        helper.make_node("Gather", ["nbr", "scalar_zero"], ["first"], axis=1),
        helper.make_node("Gather", ["xyz", "first"], ["delta"], axis=1),
    ]
    graph = helper.make_graph(
        nodes, "tiny",
        [helper.make_tensor_value_info("features", TensorProto.FLOAT, ["B", "N", 7]),
         helper.make_tensor_value_info("nbr", TensorProto.INT64, ["N", "K"]),
         helper.make_tensor_value_info("nbr_mask", TensorProto.BOOL, ["N", "K"])],
        [helper.make_tensor_value_info("delta", TensorProto.FLOAT, None)],
        initializer=[helper.make_tensor("zero", TensorProto.INT64, [1], [0]),
                     helper.make_tensor("scalar_zero", TensorProto.INT64, [], [0]),
                     helper.make_tensor("three", TensorProto.INT64, [1], [3]),
                     helper.make_tensor("two", TensorProto.INT64, [1], [2])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    model.ir_version = 8
    path = tmp_path / "tiny.onnx"
    onnx.save(model, str(path))
    return path


def test_runs_a_batch(tiny_model):
    table = NeighbourTable(nbr=np.array([[1, 2], [0, 1], [1, 2]]), mask=np.ones((3, 2), bool), truncated=0)
    feats = np.arange(2 * 3 * 7, dtype=np.float32).reshape(2, 3, 7)
    session = ModelSession(tiny_model, intra_op_threads=2)
    assert session.input_names == ("features", "nbr", "nbr_mask")
    assert session.providers[-1] == "CPUExecutionProvider"
    out = session.run(coarse_inputs(feats, table))["delta"]
    np.testing.assert_array_equal(out, feats[:, [1, 0, 1], :3])


def test_sessions_spin_after_a_run_unless_told_not_to_and_the_same_either_way(tiny_model):
    """``spin`` reaches onnxruntime's session options; a bundle's coarse session spins, its detail session
    does not (SPINNING_TIERS: the detail tier's post-process follows its run on the CPU)."""
    from cloth_usd.runtime.bundle import SPINNING_TIERS, find_bundle
    from cloth_usd.core.scene import Tier

    table = NeighbourTable(nbr=np.array([[1, 2], [0, 1], [1, 2]]), mask=np.ones((3, 2), bool), truncated=0)
    feats = np.arange(2 * 3 * 7, dtype=np.float32).reshape(2, 3, 7)
    key = "session.intra_op.allow_spinning"
    runs = []
    for spin, want in ((True, "1"), (False, "0")):
        session = ModelSession(tiny_model, intra_op_threads=2, spin=spin)
        assert session._session.get_session_options().get_session_config_entry(key) == want
        runs.append(session.run(coarse_inputs(feats, table))["delta"])
    np.testing.assert_array_equal(runs[0], runs[1])
    assert SPINNING_TIERS == (Tier.COARSE,)
    bundle = find_bundle("tshirt")
    for tier in bundle.tiers:
        entry = bundle.session(tier, prefer_gpu=False)._session.get_session_options().get_session_config_entry(key)
        assert entry == ("1" if tier is Tier.COARSE else "0")


def test_missing_input_names_the_options(tiny_model):
    with pytest.raises(ClothUsdError, match="nbr_mask"):
        ModelSession(tiny_model).run({"features": np.zeros((1, 1, 7), np.float32)})


def test_missing_file(tmp_path):
    with pytest.raises(ClothUsdError, match="not found"):
        ModelSession(tmp_path / "nope.onnx")


def test_providers_prefer_cuda_only_when_available():
    providers = pick_providers()
    assert providers[-1] == "CPUExecutionProvider"
    assert ("CUDAExecutionProvider" in providers) == ("CUDAExecutionProvider" in ort.get_available_providers())
    assert pick_providers(prefer_gpu=False) == ["CPUExecutionProvider"]


def test_runtime_never_imports_torch():
    code = "import sys, cloth_usd.runtime; print('torch' in sys.modules, 'onnxruntime' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]  # onnxruntime too loads only on first session
