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
    "pad_table",
    "slot_softmax",
    "MASKED_LOGIT",
    "EXP_FLOOR",
    "gather_nodes",
    "pool_mean",
    "unpool",
    "gat_scatter_reference",
]


#: Exported blocks with fewer features per head than this spread the attention weights over
#: each head's features with a matrix product (onnxruntime broadcasts over a short inner axis
#: slowly); torch eager, and wider heads, broadcast (``bench/bench_layers.py`` measures both).
SPREAD_BELOW = 16
#: The source logit of the pad node every masked slot of a neighbour table points at
#: (:func:`pad_table`): far below any real attention logit, so a masked slot's weight is 0
#: beside a real neighbour, and far above float32's lowest value (so ``logit + MASKED_LOGIT``
#: never overflows to -inf).
MASKED_LOGIT = -1e30
#: Logit differences below ``-EXP_FLOOR`` are raised to it before ``exp`` (:func:`slot_softmax`):
#: onnxruntime's Exp runs about 10x slower on inputs whose result underflows (0.70-0.77 ms
#: against 0.08 ms for 646k values, 2 threads), and every masked slot's is such an input.
#: ``exp(-80)`` = 1.8e-35 beside the row's largest weight ``exp(0)`` = 1 changes no float32 sum.
EXP_FLOOR = 80.0


def gather_nodes(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Gather node rows by an index table, slot-major (one flat ONNX ``Gather`` on axis 1).

    The table is read column by column, so the result's slot axis comes before the node
    axis: every later elementwise op and every reduction over the slots then works on
    contiguous (R, F) planes, which onnxruntime runs several times faster than a
    reduction over a short inner axis (``bench/bench_layers.py``).

    Shapes:
        x: (B, N, F...); index: (R, C) int64 in [0, N) -> (B, C, R, F...).
    """
    flat = torch.index_select(x, 1, index.t().reshape(-1))
    return flat.reshape(x.shape[0], index.shape[1], index.shape[0], *x.shape[2:])


def pad_table(nbr: torch.Tensor, mask: torch.Tensor, num_nodes: int | torch.Tensor) -> torch.Tensor:
    """The neighbour table with every masked slot pointing at a pad node, index ``num_nodes``.

    A GAT block appends that node to its per-node tensors (source logit
    :data:`MASKED_LOGIT`, features zero), so a masked slot needs no mask arithmetic of its
    own: it gets no weight beside a real neighbour and adds zeros, and a node with no
    neighbour at all aggregates zeros.

    Shapes:
        nbr: (N, K) int64; mask: (N, K) bool -> (N, K) int64 in [0, N].
    """
    return torch.where(mask, nbr, num_nodes)


def slot_softmax(scores: torch.Tensor, dim: int) -> torch.Tensor:
    """Softmax over ``dim``, its logit differences floored at ``-EXP_FLOOR`` (:data:`EXP_FLOOR`).

    The row's largest entry gets ``exp(0)`` = 1, so the sum is >= 1 and the division is always
    safe, and ``exp`` never overflows, whatever the scores (no epsilon anywhere).

    Shapes:
        scores: (..., K, ...) -> same.
    """
    e = torch.exp((scores - scores.amax(dim=dim, keepdim=True)).clamp_min(-EXP_FLOOR))
    return e / e.sum(dim=dim, keepdim=True)


class GATBlock(nn.Module):
    """Graph attention (Velickovic et al. 2017) with a self-reinforced stream (docs/method.md).

    Output = concat(self stream ``W_s x_i`` (S), attention aggregation over the mesh
    neighbours j of i, per head h: ``sum_j softmax_j(LeakyReLU(a_dst.h_i + a_src.h_j)) h_j``
    (H x A)). The node itself is not among its attention neighbours: the self stream
    carries it. An isolated node aggregates nothing (zeros + bias).

    The forward runs one matrix product for the self stream, the head features and both
    attention logits (``a . W x`` is ``(a W) x``: the attention vectors are folded into
    the projection) and gathers slot-major (:func:`gather_nodes`) through :func:`pad_table`
    (masked slots read a pad node, so no mask enters the arithmetic); in an ONNX export with
    narrow heads it spreads the per-head weights over each head's features with a product
    by a 0/1 matrix instead of a broadcast (:data:`SPREAD_BELOW`). Same function and
    parameters as the textbook form (:func:`gat_scatter_reference` checks it in the tests).

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
        spread = torch.repeat_interleave(torch.eye(heads), head_features, dim=1)
        self.register_buffer("spread", spread, persistent=False)  # (H, H * A) 0/1

    @property
    def out_features(self) -> int:
        """S + H * A."""
        return self.self_features + self.heads * self.head_features

    def project(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per-node head features and the two attention logits (textbook form).

        Shapes:
            x: (B, N, F_in) -> h (B, N, H, A), src (B, N, H), dst (B, N, H).
        """
        h = self.lin(x).unflatten(-1, (self.heads, self.head_features))
        return h, (h * self.att_src).sum(-1), (h * self.att_dst).sum(-1)

    def forward(self, x: torch.Tensor, nbr: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        s, ha, heads = self.self_features, self.heads * self.head_features, self.heads
        w = self.lin.weight.unflatten(0, (heads, self.head_features))  # (H, A, F_in)
        weight = torch.cat([self.self_lin.weight, self.lin.weight,
                            (self.att_src.unsqueeze(-1) * w).sum(1), (self.att_dst.unsqueeze(-1) * w).sum(1)])
        bias = torch.cat([self.self_lin.bias, self.self_lin.bias.new_zeros(ha + 2 * heads)])
        y = fn.linear(x, weight, bias)  # (B, N, S + HA + 2H)
        own, h, src, dst = y.split([s, ha, heads, heads], dim=-1)
        table, b = pad_table(nbr, mask, x.shape[1]), x.shape[0]
        src = torch.cat([src, src.new_full((b, 1, heads), MASKED_LOGIT)], dim=1)  # the pad node (N + 1 rows)
        h = torch.cat([h, h.new_zeros((b, 1, ha))], dim=1)
        scores = fn.leaky_relu(dst.unsqueeze(1) + gather_nodes(src, table), self.negative_slope)  # (B,K,N,H)
        att = slot_softmax(scores, dim=1)
        if self.head_features < SPREAD_BELOW and torch.onnx.is_in_onnx_export():
            agg = (torch.matmul(att, self.spread) * gather_nodes(h, table)).sum(1)  # (B,N,HA)
        else:
            agg = (att.unsqueeze(-1) * gather_nodes(h.unflatten(-1, (heads, -1)), table)).sum(1).flatten(-2)
        return torch.cat([own, agg + self.bias], dim=-1)


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
    m = members_mask.t().to(x.dtype).unsqueeze(-1)  # (P, N2, 1)
    total = (gather_nodes(x, members) * m).sum(1)
    return total / m.sum(0).clamp_min(1.0)


def unpool(x: torch.Tensor, cluster: torch.Tensor) -> torch.Tensor:
    """Copy each cluster's features back to its members.

    Shapes:
        x: (B, N2, F); cluster: (N,) int64 in [0, N2) -> (B, N, F).
    """
    return torch.index_select(x, 1, cluster)
