"""Generators and parser at small widths: shapes, ablation switches, numerical guards."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch", reason="cloth_usd.nn needs torch (pip install 'cloth-usd[train]')")

from meshes import grid  # noqa: E402

from cloth_usd.core.graph import build_graph  # noqa: E402
from cloth_usd.nn.models import (  # noqa: E402
    AttributeParser,
    CoarseConfig,
    CoarseGenerator,
    DetailConfig,
    DetailGenerator,
    ParserConfig,
)
from cloth_usd.runtime.io import DETAIL_INPUTS, detail_inputs  # noqa: E402

W = 0.125


@pytest.fixture(scope="module")
def graph():
    faces, pos = grid(7, 6)
    return build_graph(faces, pos)


def _coarse_args(graph, batch=2, scale=1.0):
    feats = scale * torch.randn(batch, graph.num_vertices, 7)
    return feats, torch.from_numpy(graph.table.nbr), torch.from_numpy(graph.table.mask)


def _detail_args(graph, batch=2, scale=1.0):
    inputs = detail_inputs(scale * torch.randn(batch, graph.num_vertices, 30).numpy(),
                           scale * torch.randn(batch, 85).numpy(), graph)
    return [torch.from_numpy(inputs[n]) for n in DETAIL_INPUTS]


@pytest.mark.parametrize("decompose", [True, False])
def test_coarse_shapes(graph, decompose):
    torch.manual_seed(0)
    model = CoarseGenerator(CoarseConfig(width=W, decompose=decompose))
    out = model(*_coarse_args(graph, batch=3))
    assert out.shape == (3, graph.num_vertices, 3)
    assert len(model.branches) == (2 if decompose else 1)


@pytest.mark.parametrize("use_parser", [True, False])
@pytest.mark.parametrize("decompose", [True, False])
def test_detail_shapes(graph, use_parser, decompose):
    torch.manual_seed(0)
    model = DetailGenerator(DetailConfig(width=W, use_parser=use_parser, decompose=decompose))
    out = model(*_detail_args(graph))
    assert out.shape == (2, graph.num_vertices, 3)
    assert (model.parser is not None) == use_parser


def test_parser_shape_and_default_widths():
    parser = AttributeParser(ParserConfig(width=W))
    assert parser(torch.randn(4, 85)).shape == (4, 128)
    assert [m.out_features for m in AttributeParser().mlp if hasattr(m, "out_features")] == [256, 512, 1024]


def test_paper_widths():
    coarse = CoarseGenerator()
    assert (coarse.first.self_features, coarse.first.heads, coarse.first.head_features) == (128, 4, 32)
    assert [b.out_features for b in coarse.branches[0]] == [512, 512, 256]
    detail = DetailGenerator()
    assert detail.first.out_features == 1024 == detail.parser.out_features
    assert [b.out_features for b in detail.branches[0]] == [256, 256, 128, 96]


def test_zero_direction_gives_zero_not_nan(graph):
    torch.manual_seed(0)
    model = CoarseGenerator(CoarseConfig(width=W))
    with torch.no_grad():
        model.head.direction[-1].weight.zero_()
        model.head.direction[-1].bias.zero_()
    out = model(*_coarse_args(graph))
    assert torch.isfinite(out).all() and (out == 0).all()


def test_direction_is_unit(graph):
    torch.manual_seed(0)
    model = CoarseGenerator(CoarseConfig(width=W))
    with torch.no_grad():  # magnitude fixed at 1: |delta| is then |d|
        model.head.magnitude[-1].weight.zero_()
        model.head.magnitude[-1].bias.fill_(1.0)
    norms = torch.linalg.vector_norm(model(*_coarse_args(graph)), dim=-1)
    torch.testing.assert_close(norms, torch.ones_like(norms))


@pytest.mark.parametrize("scale", [1e4, 1e-4])
def test_extreme_inputs_are_finite(graph, scale):
    torch.manual_seed(0)
    coarse = CoarseGenerator(CoarseConfig(width=W))
    detail = DetailGenerator(DetailConfig(width=W))
    assert torch.isfinite(coarse(*_coarse_args(graph, scale=scale))).all()
    assert torch.isfinite(detail(*_detail_args(graph, scale=scale))).all()


def test_statistics_are_saved_buffers(graph):
    model = CoarseGenerator(CoarseConfig(width=W))
    model.set_statistics(torch.arange(7.0), torch.zeros(7), torch.full((3,), 0.01))
    state = model.state_dict()
    assert {"input_mean", "input_std", "output_scale"} <= state.keys()
    assert torch.isfinite(model(*_coarse_args(graph))).all()  # zero std is guarded
    detail = DetailGenerator(DetailConfig(width=W))
    assert {"parser.input_mean", "parser.input_std"} <= detail.state_dict().keys()
