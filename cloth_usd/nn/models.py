"""The learned tiers' networks: coarse generator, attribute parser, detail generator.

Widths default to the paper's (docs/method.md); ``width`` scales every hidden width for
faster tiers. Normalisation statistics (input mean/std, output scale) are buffers, so
they ship inside the saved and exported model.

Our choices where the paper is silent (documented here, change with a measured reason):

- every GAT block uses 4 heads and splits its width half self stream, half heads;
- hidden activations: ELU between GAT blocks, ReLU between FC layers; the first GAT
  block of both generators is followed by tanh (the paper says so for the coarse one);
- the parser's last layer is linear (ReLU on its hidden layers only), so the encoding
  can scale detail features by either sign;
- the detail branch pools after its first GAT block and unpools before its last, and
  concatenates the first block's output with the unpooled features (``pool_skip``) so
  the last block sees full-resolution features.

Shape letters: B batch (frames), N nodes, K neighbours, N2 pooled clusters, P members
per cluster, K2 pooled neighbours, F features.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from ..core.features import ATTRIBUTE_FEATURES, COARSE_FEATURES, DETAIL_FEATURES
from .layers import GATBlock, pool_mean, unpool

__all__ = [
    "CoarseConfig",
    "ParserConfig",
    "DetailConfig",
    "CoarseGenerator",
    "AttributeParser",
    "DetailGenerator",
    "DisplacementHead",
]

#: The guard of the direction normalisation d / max(|d|, EPS) (docs/method.md).
DIRECTION_EPS = 1e-6
#: Heads of every GAT block.
HEADS = 4


def _scaled(width: int, factor: float, multiple: int = 2 * HEADS) -> int:
    """``width * factor`` rounded to a positive multiple of ``multiple``."""
    return max(multiple, int(round(width * factor / multiple)) * multiple)


def _gat(in_features: int, width: int) -> GATBlock:
    """A GAT block of total width ``width``: half self stream, half over :data:`HEADS` heads."""
    half = width // 2
    return GATBlock(in_features, half, HEADS, half // HEADS)


def _mlp(in_features: int, widths: tuple[int, ...]) -> nn.Sequential:
    """Linear layers to ``widths`` with ReLU between them (none after the last)."""
    layers: list[nn.Module] = []
    for k, w in enumerate(widths):
        layers.append(nn.Linear(in_features, w))
        if k < len(widths) - 1:
            layers.append(nn.ReLU())
        in_features = w
    return nn.Sequential(*layers)


@dataclass(frozen=True)
class CoarseConfig:
    """Widths and switches of :class:`CoarseGenerator` (defaults: the paper's)."""

    in_features: int = COARSE_FEATURES
    """Node features F."""
    first_width: int = 256
    """Width of the first GAT block (self 128 + 4 heads x 32)."""
    branch_widths: tuple[int, ...] = (512, 512, 256)
    """GAT block widths of each branch."""
    fc_widths: tuple[int, ...] = (256, 128)
    """Hidden FC widths before each branch's output (1 magnitude or 3 direction)."""
    width: float = 1.0
    """Multiplier on every hidden width (faster tiers, tests)."""
    decompose: bool = True
    """Predict magnitude x direction (the paper); False: one direct 3-vector head (ablation)."""


@dataclass(frozen=True)
class ParserConfig:
    """Widths of :class:`AttributeParser` (defaults: the paper's)."""

    in_features: int = ATTRIBUTE_FEATURES
    """Attribute features: alpha (3) + beta (10) + theta (72)."""
    widths: tuple[int, ...] = (256, 512, 1024)
    """FC widths; the last is the encoding width (must equal the detail first width)."""
    width: float = 1.0
    """Multiplier on every width."""


@dataclass(frozen=True)
class DetailConfig:
    """Widths and switches of :class:`DetailGenerator` (defaults: the paper's)."""

    in_features: int = DETAIL_FEATURES
    """Node features F."""
    first_width: int = 1024
    """Width of the first GAT block, multiplied by the parser encoding."""
    branch_widths: tuple[int, int, int, int] = (256, 256, 128, 96)
    """GAT block widths of each branch: block 1 at N, pool, blocks 2-3 at N2, unpool, block 4 at N."""
    fc_widths: tuple[int, ...] = (128, 64)
    """Hidden FC widths before each branch's output."""
    width: float = 1.0
    """Multiplier on every hidden width (parser included)."""
    decompose: bool = True
    """Magnitude x direction heads (the paper); False: one direct 3-vector head (ablation)."""
    use_parser: bool = True
    """Multiply by the parser encoding (the paper); False: append attributes to every node."""
    pool_skip: bool = True
    """Concatenate the first block's output with the unpooled features before the last block."""
    parser: ParserConfig = ParserConfig()
    """The parser's config; its ``width`` is overridden by this config's ``width``."""


class DisplacementHead(nn.Module):
    """Output reconstruction: Delta = m * d, m = ReLU(FC), d = tanh(FC) / max(|tanh(FC)|, 1e-6).

    With ``decompose=False``: Delta = FC directly (the ablation baseline).

    Shapes:
        m_features: (B, N, F); d_features: (B, N, F) -> (B, N, 3).
    """

    def __init__(self, in_features: int, fc_widths: tuple[int, ...], *, decompose: bool) -> None:
        super().__init__()
        self.decompose = decompose
        self.direction = _mlp(in_features, (*fc_widths, 3))
        self.magnitude = _mlp(in_features, (*fc_widths, 1)) if decompose else None

    def forward(self, m_features: torch.Tensor, d_features: torch.Tensor) -> torch.Tensor:
        if self.magnitude is None:
            return self.direction(d_features)
        m = torch.relu(self.magnitude(m_features))
        d = torch.tanh(self.direction(d_features))
        # clamp_min, not "+ eps": the dynamo ONNX exporter was seen to drop x + eps for tiny eps.
        d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True).clamp_min(DIRECTION_EPS)
        return m * d


class _Normalised(nn.Module):
    """Input mean/std and output scale buffers shared by both generators."""

    def _init_stats(self, in_features: int) -> None:
        self.register_buffer("input_mean", torch.zeros(in_features))
        self.register_buffer("input_std", torch.ones(in_features))
        self.register_buffer("output_scale", torch.ones(3))

    def set_statistics(self, input_mean: torch.Tensor, input_std: torch.Tensor,
                       output_scale: torch.Tensor) -> None:
        """Store normalisation statistics: (F,) input mean and std, (3,) output scale [m]."""
        self.input_mean.copy_(torch.as_tensor(input_mean, dtype=torch.float32))
        self.input_std.copy_(torch.as_tensor(input_std, dtype=torch.float32))
        self.output_scale.copy_(torch.as_tensor(output_scale, dtype=torch.float32))

    def _normalise(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.input_mean) / self.input_std.clamp_min(DIRECTION_EPS)


class CoarseGenerator(_Normalised):
    """W_coarse: per-vertex displacement from the associated posed body vertex.

    Shapes:
        features: (B, N, 7); nbr: (N, K) int64; mask: (N, K) bool -> delta (B, N, 3) [m].
    """

    def __init__(self, config: CoarseConfig = CoarseConfig()) -> None:
        super().__init__()
        self.config = config
        c = config
        self._init_stats(c.in_features)
        self.first = _gat(c.in_features, _scaled(c.first_width, c.width))
        fc = tuple(_scaled(w, c.width) for w in c.fc_widths)
        self.branches = nn.ModuleList()
        for _ in range(2 if c.decompose else 1):
            blocks, f = nn.ModuleList(), self.first.out_features
            for w in c.branch_widths:
                blocks.append(_gat(f, _scaled(w, c.width)))
                f = blocks[-1].out_features
            self.branches.append(blocks)
        self.head = DisplacementHead(f, fc, decompose=c.decompose)

    def forward(self, features: torch.Tensor, nbr: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        x = torch.tanh(self.first(self._normalise(features), nbr, mask))
        outs = []
        for blocks in self.branches:
            y = x
            for k, block in enumerate(blocks):
                y = block(y, nbr, mask)
                if k < len(blocks) - 1:
                    y = nn.functional.elu(y)
            outs.append(y)
        return self.head(outs[-1] if len(outs) == 1 else outs[0], outs[-1]) * self.output_scale


class AttributeParser(nn.Module):
    """W_parser: (alpha, beta, theta) -> the detail-aware encoding.

    Shapes:
        attributes: (B, 85) -> (B, F_enc), F_enc the last of ``widths`` (scaled).
    """

    def __init__(self, config: ParserConfig = ParserConfig()) -> None:
        super().__init__()
        self.config = config
        self.register_buffer("input_mean", torch.zeros(config.in_features))
        self.register_buffer("input_std", torch.ones(config.in_features))
        self.mlp = _mlp(config.in_features, tuple(_scaled(w, config.width) for w in config.widths))

    @property
    def out_features(self) -> int:
        """F_enc."""
        return self.mlp[-1].out_features

    def forward(self, attributes: torch.Tensor) -> torch.Tensor:
        return self.mlp((attributes - self.input_mean) / self.input_std.clamp_min(DIRECTION_EPS))


class DetailGenerator(_Normalised):
    """W_detail (with its parser): per-vertex detail displacement on the coarse garment.

    Each branch: GAT block 1 at N -> pool_mean to N2 -> GAT blocks 2, 3 at N2 -> unpool
    to N (concatenated with block 1's output if ``pool_skip``) -> GAT block 4 at N.

    Shapes:
        features: (B, N, 30); attributes: (B, 85); nbr, mask: (N, K); cluster: (N,) int64;
        members, members_mask: (N2, P); pooled_nbr, pooled_mask: (N2, K2)
        -> delta (B, N, 3) [m].
    """

    def __init__(self, config: DetailConfig = DetailConfig()) -> None:
        super().__init__()
        self.config = config
        c = config
        self._init_stats(c.in_features)
        first = _scaled(c.first_width, c.width)
        if c.use_parser:
            self.parser = AttributeParser(
                ParserConfig(c.parser.in_features, (*c.parser.widths[:-1], c.first_width), c.width))
            node_in = c.in_features
        else:
            self.parser = None
            self.register_buffer("attribute_mean", torch.zeros(c.parser.in_features))
            self.register_buffer("attribute_std", torch.ones(c.parser.in_features))
            node_in = c.in_features + c.parser.in_features
        self.first = _gat(node_in, first)
        widths = [_scaled(w, c.width) for w in c.branch_widths]
        self.branches = nn.ModuleList()
        for _ in range(2 if c.decompose else 1):
            b1 = _gat(self.first.out_features, widths[0])
            b2 = _gat(b1.out_features, widths[1])
            b3 = _gat(b2.out_features, widths[2])
            b4 = _gat(b3.out_features + (b1.out_features if c.pool_skip else 0), widths[3])
            self.branches.append(nn.ModuleList([b1, b2, b3, b4]))
        fc = tuple(_scaled(w, c.width) for w in c.fc_widths)
        self.head = DisplacementHead(widths[3], fc, decompose=c.decompose)

    def set_attribute_statistics(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Store the (85,) attribute mean and std: the parser's input normalisation, or that of
        the attributes appended to every node when there is no parser."""
        if self.parser is not None:
            dst_mean, dst_std = self.parser.input_mean, self.parser.input_std
        else:
            dst_mean, dst_std = self.attribute_mean, self.attribute_std
        dst_mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        dst_std.copy_(torch.as_tensor(std, dtype=torch.float32))

    def forward(self, features: torch.Tensor, attributes: torch.Tensor, nbr: torch.Tensor,
                mask: torch.Tensor, cluster: torch.Tensor, members: torch.Tensor,
                members_mask: torch.Tensor, pooled_nbr: torch.Tensor,
                pooled_mask: torch.Tensor) -> torch.Tensor:
        x = self._normalise(features)
        if self.parser is None:
            a = (attributes - self.attribute_mean) / self.attribute_std.clamp_min(DIRECTION_EPS)
            x = torch.cat([x, a.unsqueeze(1).expand(-1, x.shape[1], -1)], dim=-1)
        x = torch.tanh(self.first(x, nbr, mask))
        if self.parser is not None:
            x = x * self.parser(attributes).unsqueeze(1)
        elu = nn.functional.elu
        outs = []
        for b1, b2, b3, b4 in self.branches:
            y1 = elu(b1(x, nbr, mask))
            y = pool_mean(y1, members, members_mask)
            y = elu(b2(y, pooled_nbr, pooled_mask))
            y = elu(b3(y, pooled_nbr, pooled_mask))
            y = unpool(y, cluster)
            if self.config.pool_skip:
                y = torch.cat([y, y1], dim=-1)
            outs.append(b4(y, nbr, mask))
        return self.head(outs[0], outs[-1]) * self.output_scale
