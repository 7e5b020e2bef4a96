"""Benchmark (not a test): the generators and one GAT block, torch eager vs onnxruntime.

On a garment-sized grid (default 63 x 64 = 4032 vertices), prints median ms per forward
(batch 1) for:

- the coarse and detail generators at the paper's widths and at ``--width`` (default the
  shipped detail model's): torch eager vs onnxruntime (the issue's target: onnxruntime never slower);
- one GAT block at widths 256 and 64 (32 and 8 features per head) in three forms, each in
  torch eager and exported to onnxruntime, with the export's max error against torch:
  the layer as shipped (slot-major padded table, :class:`cloth_usd.nn.layers.GATBlock`),
  the node-major padded table it replaced (:class:`NodeMajorBlock`, the (N, K) table
  gathered as (B, N, K, F) and reduced over K), and the scatter form (``index_add_``;
  the issue's claim: ScatterND is slower and sums wrongly with several threads).

Run: python bench/bench_layers.py [--threads 2] [--repeats 7] [--nx 63 --ny 64] [--width 0.125]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from cloth_usd.core.graph import build_graph, directed_edges
from cloth_usd.nn.export import export_coarse, export_detail
from cloth_usd.nn.layers import GATBlock, gat_scatter_reference
from cloth_usd.nn.models import CoarseConfig, CoarseGenerator, DetailConfig, DetailGenerator
from cloth_usd.runtime import COARSE_INPUTS, DETAIL_INPUTS, ModelSession, coarse_inputs, detail_inputs


def grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    pos = np.stack([xs.ravel(), ys.ravel(), 0.2 * np.sin(xs.ravel() / 3)], 1) * 0.01
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]), pos


def median_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


class PaddedBlock(torch.nn.Module):
    def __init__(self, block: GATBlock) -> None:
        super().__init__()
        self.block = block

    def forward(self, x, nbr, mask):
        return self.block(x, nbr, mask)


class NodeMajorBlock(torch.nn.Module):
    """The previous padded-table form (same parameters): gather (B, N, K, F), reduce over K,
    attention logits by broadcast products, softmax by ``where``."""

    def __init__(self, block: GATBlock) -> None:
        super().__init__()
        self.block = block

    def forward(self, x, nbr, mask):
        b = self.block
        h, src, dst = b.project(x)

        def gather(t):
            return torch.index_select(t, 1, nbr.reshape(-1)).reshape(t.shape[0], *nbr.shape, *t.shape[2:])

        scores = torch.nn.functional.leaky_relu(dst.unsqueeze(2) + gather(src), b.negative_slope)  # (B,N,K,H)
        m = mask.unsqueeze(-1)
        s = torch.where(m, scores, torch.full_like(scores, torch.finfo(scores.dtype).min))
        e = torch.exp(s - s.amax(dim=2, keepdim=True)) * m.to(scores.dtype)
        w = e / e.sum(dim=2, keepdim=True).clamp_min(1.0)
        agg = (w.unsqueeze(-1) * gather(h)).sum(2)
        return torch.cat([b.self_lin(x), agg.flatten(-2) + b.bias], dim=-1)


class ScatterBlock(torch.nn.Module):
    def __init__(self, block: GATBlock) -> None:
        super().__init__()
        self.block = block

    def forward(self, x, edges):
        return gat_scatter_reference(self.block, x, edges)


def export(module, args, names, path) -> Path:
    dyn = tuple({a: torch.export.Dim.DYNAMIC for a in range(t.ndim - (1 if n == "x" else 0))}
                for n, t in zip(names, args))
    with torch.no_grad():
        torch.onnx.export(module, args, input_names=list(names), output_names=["y"], dynamic_shapes=dyn,
                          opset_version=18, dynamo=True, verbose=False).save(str(path))
    return path


def _session(path: Path, threads: int) -> ModelSession:
    return ModelSession(path, intra_op_threads=threads, prefer_gpu=False)


def model_rows(graph, width: float, threads: int, repeats: int, tmp: Path) -> list[tuple]:
    """Coarse and detail generators at ``width``: torch eager vs onnxruntime, batch 1."""
    rng = np.random.default_rng(0)
    n = graph.num_vertices
    rows = []
    coarse = CoarseGenerator(CoarseConfig(width=width)).eval()
    feed = coarse_inputs(rng.normal(size=(1, n, 7)), graph.table)
    detail = DetailGenerator(DetailConfig(width=width)).eval()
    dfeed = detail_inputs(rng.normal(size=(1, n, 30)), rng.normal(size=(1, 85)), graph)
    for name, model, inputs, names, export_fn in (("coarse", coarse, feed, COARSE_INPUTS, export_coarse),
                                                  ("detail+parser", detail, dfeed, DETAIL_INPUTS, export_detail)):
        params = sum(p.numel() for p in model.parameters())
        args = [torch.from_numpy(inputs[k]) for k in names]
        with torch.no_grad():
            t_torch = median_ms(lambda: model(*args), repeats)
            ref = model(*args).numpy()
        session = _session(export_fn(model, tmp / f"{name}-{width}.onnx"), threads)
        t_ort = median_ms(lambda: session.run(inputs), repeats)
        err = np.abs(session.run(inputs)["delta"] - ref).max()
        rows.append((f"{name} width {width:g} ({params / 1e6:.2f} M params)", t_torch, t_ort, err))
    return rows


def block_rows(graph, faces, width: int, threads: int, repeats: int, tmp: Path) -> list[tuple]:
    """One GAT block of ``width`` (half self stream, 4 heads) in the three forms."""
    n = graph.num_vertices
    block = GATBlock(width, width // 2, 4, width // 8).eval()
    x = torch.randn(1, n, width)
    nbr, mask = torch.from_numpy(graph.table.nbr), torch.from_numpy(graph.table.mask)
    edges = torch.from_numpy(directed_edges(faces, n))
    feed = {"x": x.numpy(), "nbr": nbr.numpy(), "mask": mask.numpy()}
    with torch.no_grad():
        ref = block(x, nbr, mask).numpy()
    rows = []
    for name, module in (("slot-major (shipped)", PaddedBlock(block)), ("node-major (previous)", NodeMajorBlock(block))):
        with torch.no_grad():
            t_torch = median_ms(lambda: module(x, nbr, mask), repeats)
        s = _session(export(module, (x, nbr, mask), ("x", "nbr", "mask"), tmp / f"{name[:4]}{width}.onnx"), threads)
        rows.append((f"GAT block {width} (A={width // 8}), {name}", t_torch, median_ms(lambda: s.run(feed), repeats),
                     np.abs(s.run(feed)["y"] - ref).max()))
    with torch.no_grad():
        t_sc = median_ms(lambda: gat_scatter_reference(block, x, edges), repeats)
    try:
        s = _session(export(ScatterBlock(block), (x, edges), ("x", "edges"), tmp / f"sc{width}.onnx"), threads)
        sfeed = {"x": x.numpy(), "edges": edges.numpy()}
        rows.append((f"GAT block {width} (A={width // 8}), scatter", t_sc, median_ms(lambda: s.run(sfeed), repeats),
                     np.abs(s.run(sfeed)["y"] - ref).max()))
    except Exception as exc:  # noqa: BLE001 - a benchmark reports and goes on
        rows.append((f"GAT block {width}, scatter: export failed ({type(exc).__name__})", t_sc, float("nan"),
                     float("nan")))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--nx", type=int, default=63)
    p.add_argument("--ny", type=int, default=64)
    p.add_argument("--width", type=float, default=0.125, help="a reduced width to compare (default: the shipped detail model's)")
    a = p.parse_args()
    warnings.filterwarnings("ignore")
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    faces, pos = grid(a.nx, a.ny)
    graph = build_graph(faces, pos)
    n, k = graph.table.nbr.shape
    print(f"mesh: N={n} K={k} N2={graph.pooling.members.shape[0]} K2={graph.pooling.table.nbr.shape[1]}, "
          f"threads={a.threads}, batch 1, median of {a.repeats}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for width in sorted({1.0, a.width}):
            rows += model_rows(graph, width, a.threads, a.repeats, Path(tmp))
        for width in (256, 64):
            rows += block_rows(graph, faces, width, a.threads, a.repeats, Path(tmp))
    print(f"{'model':52s} {'torch ms':>9s} {'ort ms':>9s} {'torch/ort':>9s} {'ort max err':>12s}")
    for name, tt, to, e in rows:
        print(f"{name:52s} {tt:9.1f} {to:9.1f} {tt / to:9.2f} {e:12.2e}")


if __name__ == "__main__":
    main()
