"""Benchmark (not a test): detail generator and one GAT block, torch eager vs onnxruntime.

On a garment-sized grid (default 63 x 64 = 4032 vertices) at the paper's widths, prints
median ms per forward (batch 1) for:

- the detail generator (with parser), padded-table form: torch eager vs onnxruntime;
- one GAT block (width 256), padded-table form vs the scatter (index_add_) form, each in
  torch eager and exported to onnxruntime, with the scatter export's max error against
  torch (the issue's claim: ScatterND is slower and sums wrongly with several threads).

Run: python bench/bench_layers.py [--threads 2] [--repeats 7] [--nx 63 --ny 64]
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
from cloth_usd.nn.export import export_detail
from cloth_usd.nn.layers import GATBlock, gat_scatter_reference
from cloth_usd.nn.models import DetailConfig, DetailGenerator
from cloth_usd.runtime import DETAIL_INPUTS, ModelSession, detail_inputs


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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--nx", type=int, default=63)
    p.add_argument("--ny", type=int, default=64)
    a = p.parse_args()
    warnings.filterwarnings("ignore")
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    faces, pos = grid(a.nx, a.ny)
    graph = build_graph(faces, pos)
    n, k = graph.table.nbr.shape
    print(f"mesh: N={n} K={k} N2={graph.pooling.members.shape[0]} K2={graph.pooling.table.nbr.shape[1]}, "
          f"threads={a.threads}, batch 1, median of {a.repeats}")
    rng = np.random.default_rng(0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        model = DetailGenerator(DetailConfig()).eval()
        params = sum(p.numel() for p in model.parameters())
        inputs = detail_inputs(rng.normal(size=(1, n, 30)), rng.normal(size=(1, 85)), graph)
        targs = [torch.from_numpy(inputs[k]) for k in DETAIL_INPUTS]
        with torch.no_grad():
            t_torch = median_ms(lambda: model(*targs), a.repeats)
            ref = model(*targs).numpy()
        session = ModelSession(export_detail(model, Path(tmp) / "detail.onnx"), intra_op_threads=a.threads,
                               prefer_gpu=False)
        t_ort = median_ms(lambda: session.run(inputs), a.repeats)
        err = np.abs(session.run(inputs)["delta"] - ref).max()
        rows.append((f"detail+parser ({params / 1e6:.2f} M params), padded", t_torch, t_ort, err))

        block = GATBlock(128, 128, 4, 32).eval()
        x = torch.randn(1, n, 128)
        nbr, mask = torch.from_numpy(graph.table.nbr), torch.from_numpy(graph.table.mask)
        edges = torch.from_numpy(directed_edges(faces, n))
        with torch.no_grad():
            ref = block(x, nbr, mask).numpy()
            t_pad = median_ms(lambda: block(x, nbr, mask), a.repeats)
            t_sc = median_ms(lambda: gat_scatter_reference(block, x, edges), a.repeats)
        s_pad = ModelSession(export(PaddedBlock(block), (x, nbr, mask), ("x", "nbr", "mask"),
                                    Path(tmp) / "pad.onnx"), intra_op_threads=a.threads, prefer_gpu=False)
        feed = {"x": x.numpy(), "nbr": nbr.numpy(), "mask": mask.numpy()}
        rows.append(("GAT block 256, padded table", t_pad, median_ms(lambda: s_pad.run(feed), a.repeats),
                     np.abs(s_pad.run(feed)["y"] - ref).max()))
        try:
            s_sc = ModelSession(export(ScatterBlock(block), (x, edges), ("x", "edges"), Path(tmp) / "sc.onnx"),
                                intra_op_threads=a.threads, prefer_gpu=False)
            feed = {"x": x.numpy(), "edges": edges.numpy()}
            rows.append(("GAT block 256, scatter (index_add_)", t_sc, median_ms(lambda: s_sc.run(feed), a.repeats),
                         np.abs(s_sc.run(feed)["y"] - ref).max()))
        except Exception as exc:  # noqa: BLE001 - a benchmark reports and goes on
            rows.append((f"GAT block 256, scatter: export failed ({type(exc).__name__})", t_sc, float("nan"),
                         float("nan")))
    print(f"{'model':48s} {'torch ms':>9s} {'ort ms':>9s} {'torch/ort':>9s} {'ort max err':>12s}")
    for name, tt, to, e in rows:
        print(f"{name:48s} {tt:9.1f} {to:9.1f} {tt / to:9.2f} {e:12.2e}")


if __name__ == "__main__":
    main()
