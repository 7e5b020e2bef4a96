"""The exported models' input/output contract (numpy only; shared by export and runtime).

Coarse model inputs, in order (B frames, N vertices, K neighbours):

- ``features`` (B, N, F) float32: body normal, body position minus root translation [m], fit a1
  (F = 7); a bundle whose ``models.coarse.features`` is ``contact`` then adds the nearest body
  normal and the signed distance to it [m] (F = 11, :class:`cloth_usd.core.pipeline.CoarseFeatures`);
- ``nbr`` (N, K) int64 neighbour table; ``nbr_mask`` (N, K) bool.

Detail model inputs, in order (N2 pooled clusters, P members, K2 pooled neighbours):

- ``features`` (B, N, 30) float32: normal, position minus root translation [m], 24 joint
  distances [m];
- ``attributes`` (B, 85) float32: fit alpha (3), SMPL beta (10), pose theta (72);
- ``nbr``, ``nbr_mask`` (N, K); ``cluster`` (N,) int64; ``members`` (N2, P) int64,
  ``members_mask`` (N2, P) bool; ``pooled_nbr`` (N2, K2) int64, ``pooled_nbr_mask``
  (N2, K2) bool.

Both output ``delta`` (B, N, 3) float32 displacement [m]. Every dimension is dynamic.

A garment's own model (a bundle with a ``garment`` entry, :mod:`cloth_usd.nn.garment_model`)
takes instead ``pose`` (B, 216) float32, the 24 joints' rotation matrices minus the identity
with the heading taken out of the root, and ``betas`` (B, 10) float32; its ``delta`` (B, N, 3)
is the displacement of that garment's N vertices in its unposed frame, before skinning.
"""

from __future__ import annotations

import numpy as np

from ..core.graph import MeshGraph, NeighbourTable

__all__ = ["COARSE_INPUTS", "DETAIL_INPUTS", "GARMENT_INPUTS", "OUTPUT", "coarse_inputs", "detail_inputs"]

COARSE_INPUTS = ("features", "nbr", "nbr_mask")
DETAIL_INPUTS = ("features", "attributes", "nbr", "nbr_mask", "cluster", "members",
                 "members_mask", "pooled_nbr", "pooled_nbr_mask")
GARMENT_INPUTS = ("pose", "betas")
OUTPUT = "delta"


def coarse_inputs(features: np.ndarray, table: NeighbourTable) -> dict[str, np.ndarray]:
    """Named coarse-model inputs.

    Args:
        features: (B, N, F) float node features (F: 7, or 11 with contact features).
        table: the garment's (N, K) neighbour table.
    """
    return {
        "features": np.ascontiguousarray(features, dtype=np.float32),
        "nbr": np.ascontiguousarray(table.nbr, dtype=np.int64),
        "nbr_mask": np.ascontiguousarray(table.mask, dtype=bool),
    }


def detail_inputs(features: np.ndarray, attributes: np.ndarray, graph: MeshGraph) -> dict[str, np.ndarray]:
    """Named detail-model inputs.

    Args:
        features: (B, N, 30) float node features.
        attributes: (B, 85) float (alpha, beta, theta) per frame.
        graph: the garment's graph bundle.
    """
    p = graph.pooling
    return {
        **coarse_inputs(features, graph.table),
        "attributes": np.ascontiguousarray(attributes, dtype=np.float32),
        "cluster": np.ascontiguousarray(p.cluster, dtype=np.int64),
        "members": np.ascontiguousarray(p.members, dtype=np.int64),
        "members_mask": np.ascontiguousarray(p.members_mask, dtype=bool),
        "pooled_nbr": np.ascontiguousarray(p.table.nbr, dtype=np.int64),
        "pooled_nbr_mask": np.ascontiguousarray(p.table.mask, dtype=bool),
    }
