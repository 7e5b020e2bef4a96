"""Torch vs onnxruntime parity of the exported generators on two topologies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="export needs torch (pip install 'cloth-usd[train]')")
pytest.importorskip("onnxruntime", reason="parity needs onnxruntime (pip install 'cloth-usd[runtime]')")
onnx = pytest.importorskip("onnx", reason="the torch.onnx exporter needs onnx and onnxscript")
pytest.importorskip("onnxscript", reason="the torch.onnx exporter needs onnx and onnxscript")

from meshes import grid, icosphere  # noqa: E402

from cloth_usd.core.graph import build_graph  # noqa: E402
import cloth_usd  # noqa: E402
from cloth_usd.nn.export import OPSET, STACK_TRACE, export_coarse, export_detail  # noqa: E402
from cloth_usd.nn.models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator  # noqa: E402
from cloth_usd.runtime import (  # noqa: E402
    COARSE_INPUTS,
    DETAIL_INPUTS,
    ModelSession,
    coarse_inputs,
    detail_inputs,
)

pytestmark = pytest.mark.slow
W = 0.125
ATOL = 1e-4

TOPOLOGIES = {"icosphere642": icosphere(3), "grid500": grid(25, 20)}


@pytest.fixture(scope="module")
def graphs():
    return {name: build_graph(f, p) for name, (f, p) in TOPOLOGIES.items()}


def _prepare(model, in_features):
    """Non-trivial statistics, and a magnitude bias so ReLU does not zero a fresh model."""
    g = torch.Generator().manual_seed(5)
    model.set_statistics(torch.randn(in_features, generator=g), torch.rand(in_features, generator=g) + 0.5,
                         torch.tensor([0.01, 0.02, 0.03]))
    with torch.no_grad():
        model.head.magnitude[-1].bias.fill_(1.0)


@pytest.fixture(scope="module")
def coarse(tmp_path_factory):
    torch.manual_seed(0)
    model = CoarseGenerator(CoarseConfig(width=W)).eval()
    _prepare(model, 7)
    return model, export_coarse(model, tmp_path_factory.mktemp("onnx") / "coarse.onnx")


@pytest.fixture(scope="module")
def detail(tmp_path_factory):
    torch.manual_seed(0)
    model = DetailGenerator(DetailConfig(width=W)).eval()
    _prepare(model, 30)
    return model, export_detail(model, tmp_path_factory.mktemp("onnx") / "detail.onnx")


def _torch_run(model, inputs, names):
    with torch.no_grad():
        return model(*[torch.from_numpy(inputs[n]) for n in names]).numpy()


@pytest.mark.parametrize("name", list(TOPOLOGIES))
def test_coarse_parity(coarse, graphs, name):
    model, path = coarse
    g = graphs[name]
    rng = np.random.default_rng(1)
    inputs = coarse_inputs(rng.normal(size=(3, g.num_vertices, 7)), g.table)
    session = ModelSession(path, intra_op_threads=2, prefer_gpu=False)
    got = session.run(inputs)["delta"]
    want = _torch_run(model, inputs, COARSE_INPUTS)
    assert got.shape == (3, g.num_vertices, 3)
    assert np.abs(want).max() > 1e-3  # not a trivially zero model
    np.testing.assert_allclose(got, want, atol=ATOL, rtol=0)
    np.testing.assert_array_equal(session.run(inputs)["delta"], got)  # 2 threads, same bits twice


@pytest.mark.parametrize("name", list(TOPOLOGIES))
def test_detail_parity(detail, graphs, name):
    model, path = detail
    g = graphs[name]
    rng = np.random.default_rng(2)
    inputs = detail_inputs(rng.normal(size=(2, g.num_vertices, 30)), rng.normal(size=(2, 85)), g)
    session = ModelSession(path, intra_op_threads=2, prefer_gpu=False)
    got = session.run(inputs)["delta"]
    want = _torch_run(model, inputs, DETAIL_INPUTS)
    assert got.shape == (2, g.num_vertices, 3)
    assert np.abs(want).max() > 1e-3
    np.testing.assert_allclose(got, want, atol=ATOL, rtol=0)
    np.testing.assert_array_equal(session.run(inputs)["delta"], got)


def test_exported_graphs_have_no_scatter_and_keep_the_guard(coarse, detail):
    for _, path in (coarse, detail):
        m = onnx.load(str(path))
        ops = {n.op_type for n in m.graph.node}
        assert not {op for op in ops if "Scatter" in op}, ops
        assert "Clip" in ops or "Max" in ops  # the clamp_min of the direction normalisation
        assert m.opset_import[0].version >= OPSET
        assert [i.name for i in m.graph.input] == list(COARSE_INPUTS if path.stem == "coarse" else DETAIL_INPUTS)


def test_exported_files_carry_no_source_paths(coarse, tmp_path):
    model, path = coarse
    data = path.read_bytes()
    assert STACK_TRACE.encode() not in data
    assert str(Path(cloth_usd.__file__).parent).encode() not in data
    again = export_coarse(model, tmp_path / "again.onnx")
    assert again.read_bytes() == data  # the same model, the same bytes


def test_exported_attention_never_takes_an_underflowing_exp(coarse):
    """Every Exp of the attention softmax reads a Max/Clip (the EXP_FLOOR floor)."""
    m = onnx.load(str(coarse[1]))
    producer = {o: n for n in m.graph.node for o in n.output}
    exps = [n for n in m.graph.node if n.op_type == "Exp"]
    assert exps
    assert all(producer[n.input[0]].op_type in ("Max", "Clip") for n in exps), \
        [producer[n.input[0]].op_type for n in exps]


def _zero_layer(model: "onnx.ModelProto", bias_name: str) -> None:
    """Zero one exported linear layer: its bias initializer and the weight of its MatMul/Gemm."""
    init = {t.name: t for t in model.graph.initializer}
    producer = {o: n for n in model.graph.node for o in n.output}
    names = [bias_name]
    for node in model.graph.node:
        if bias_name in node.input:
            if node.op_type == "Gemm":
                names.append(node.input[1])
            else:
                other = [i for i in node.input if i != bias_name][0]
                names += [i for i in producer[other].input if i in init]
    for name in names:
        arr = onnx.numpy_helper.to_array(init[name])
        init[name].CopyFrom(onnx.numpy_helper.from_array(np.zeros_like(arr), name))


def test_exported_zero_direction_is_finite(coarse, graphs, tmp_path):
    """The direction guard survives export: an all-zero direction gives 0, not NaN."""
    _, path = coarse
    m = onnx.load(str(path))
    _zero_layer(m, "head.direction.4.bias")
    zeroed = tmp_path / "zero.onnx"
    onnx.save(m, str(zeroed))
    g = graphs["grid500"]
    inputs = coarse_inputs(np.random.default_rng(3).normal(size=(1, g.num_vertices, 7)), g.table)
    got = ModelSession(zeroed, intra_op_threads=2, prefer_gpu=False).run(inputs)["delta"]
    assert np.isfinite(got).all() and (got == 0).all()
