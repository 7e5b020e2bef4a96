"""Graph layers over padded neighbour tables: GAT block, mean pooling, unpooling.

Every forward here is gather-based (``x[:, nbr]``): no scatter / ``index_put`` /
``index_add_``, because those export to ONNX ScatterND, which onnxruntime sums wrongly
when multithreaded. The scatter form lives on only in :func:`gat_scatter_reference`,
which tests use to prove the padded form computes the same thing.

Shape letters: B batch (frames), N nodes, K neighbours per node (table width),
N2 pooled clusters, P members per cluster, E directed edges, F features,
H heads, A features per head, S self-stream features.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as fn

__all__ = [
    "GATBlock",
    "masked_softmax",
    "gather_nodes",
    "pool_mean",
    "unpool",
    "gat_scatter_reference",
]


def gather_nodes(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Gather node rows by an index table (one flat ONNX ``Gather`` on axis 1, then reshape).

    Shapes:
        x: (B, N, F...); index: (R, C) int64 in [0, N) -> (B, R, C, F...).
    """
    flat = torch.index_select(x, 1, index.reshape(-1))
    return flat.reshape(x.shape[0], index.shape[0], index.shape[1], *x.shape[2:])


def masked_softmax(scores: torch.Tensor, mask: torch.Tensor, dim: int) -> torch.Tensor:
    """Softmax over ``dim`` restricted to ``mask``; an all-masked row gives zeros, never NaN.

    The max is taken over valid entries only (invalid ones are set to the dtype's lowest
    value first), so ``exp`` never overflows; every valid row's sum is then >= 1 (its max
    entry contributes exp(0)), so dividing by ``sum.clamp_min(1)`` is exact for valid rows
    and turns an empty row into 0 / 1 without an epsilon.

    Shapes:
        scores: (..., K, ...); mask: broadcastable to scores, bool -> same as scores.
    """
    low = torch.finfo(scores.dtype).min
    s = torch.where(mask, scores, torch.full_like(scores, low))
    peak = s.amax(dim=dim, keepdim=True)
    e = torch.exp(s - peak) * mask.to(scores.dtype)
    return e / e.sum(dim=dim, keepdim=True).clamp_min(1.0)


class GATBlock(nn.Module):
    """Graph attention (Velickovic et al. 2017) with a self-reinforced stream (METHOD.md).

    Output = concat(self stream ``W_s x_i`` (S), attention aggregation over the mesh
    neighbours j of i, per head h: ``sum_j softmax_j(LeakyReLU(a_dst.h_i + a_src.h_j)) h_j``
    (H x A)). The node itself is not among its attention neighbours: the self stream
    carries it. An isolated node aggregates nothing (zeros + bias).

    Shapes:
        x: (B, N, F_in); nbr: (N, K) int64; mask: (N, K) bool -> (B, N, S + H * A).
    """

    def __init__(self, in_features: int, self_features: int, heads: int, head_features: int,
                 *, negative_slope: float = 0.2) -> None:
        super().__init__()
        self.in_features = in_features
        self.self_features = self_features
        self.heads = heads
        self.head_features = head_features
        self.negative_slope = negative_slope
        self.self_lin = nn.Linear(in_features, self_features)
        self.lin = nn.Linear(in_features, heads * head_features, bias=False)
        self.att_src = nn.Parameter(torch.empty(heads, head_features))
        self.att_dst = nn.Parameter(torch.empty(heads, head_features))
        self.bias = nn.Parameter(torch.zeros(heads * head_features))
        nn.init.xavier_uniform_(self.att_src)
        nn.init.xavier_uniform_(self.att_dst)

    @property
    def out_features(self) -> int:
        """S + H * A."""
        return self.self_features + self.heads * self.head_features

    def project(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per-node head features and the two attention logits.

        Shapes:
            x: (B, N, F_in) -> h (B, N, H, A), src (B, N, H), dst (B, N, H).
        """
        h = self.lin(x).unflatten(-1, (self.heads, self.head_features))
        return h, (h * self.att_src).sum(-1), (h * self.att_dst).sum(-1)

    def forward(self, x: torch.Tensor, nbr: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        h, src, dst = self.project(x)
        scores = fn.leaky_relu(dst.unsqueeze(2) + gather_nodes(src, nbr), self.negative_slope)  # (B,N,K,H)
        w = masked_softmax(scores, mask.unsqueeze(-1), dim=2)
        agg = (w.unsqueeze(-1) * gather_nodes(h, nbr)).sum(2)  # (B,N,H,A)
        return torch.cat([self.self_lin(x), agg.flatten(-2) + self.bias], dim=-1)


def gat_scatter_reference(block: GATBlock, x: torch.Tensor, edges: torch.Tensor) -> torch.Tensor:
    """The same GAT block computed over an edge list with ``index_add_`` (tests only).

    Not for export: it is the scatter form the padded table replaces.

    Shapes:
        x: (B, N, F_in); edges: (E, 2) int64 ``(i, j)``, j a neighbour of i -> (B, N, S + H * A).
    """
    h, src, dst = block.project(x)
    i, j = edges[:, 0], edges[:, 1]
    score = fn.leaky_relu(dst[:, i] + src[:, j], block.negative_slope)  # (B,E,H)
    b, n = x.shape[0], x.shape[1]
    peak = torch.full((b, n, block.heads), float("-inf"), dtype=x.dtype)
    peak = peak.scatter_reduce(1, i[None, :, None].expand_as(score), score, reduce="amax")
    e = torch.exp(score - peak[:, i])
    denom = torch.zeros(b, n, block.heads, dtype=x.dtype).index_add_(1, i, e)
    w = e / denom[:, i]
    agg = torch.zeros_like(h).index_add_(1, i, w.unsqueeze(-1) * h[:, j])
    return torch.cat([block.self_lin(x), agg.flatten(-2) + block.bias], dim=-1)


def pool_mean(x: torch.Tensor, members: torch.Tensor, members_mask: torch.Tensor) -> torch.Tensor:
    """Mean of each cluster's member features (gather + masked sum).

    Shapes:
        x: (B, N, F); members: (N2, P) int64; members_mask: (N2, P) bool -> (B, N2, F).
    """
    m = members_mask.to(x.dtype)
    total = (gather_nodes(x, members) * m.unsqueeze(-1)).sum(2)
    return total / m.sum(1).clamp_min(1.0).unsqueeze(-1)


def unpool(x: torch.Tensor, cluster: torch.Tensor) -> torch.Tensor:
    """Copy each cluster's features back to its members.

    Shapes:
        x: (B, N2, F); cluster: (N,) int64 in [0, N2) -> (B, N, F).
    """
    return torch.index_select(x, 1, cluster)
