"""The body model as ``smplx.SMPL`` (torch): for training, and to hold the numpy LBS honest.

smplx cannot read SMPL from ``.npz``, so the arrays go in through ``data_struct``; a
body that is not SMPL's 6890-vertex mesh passes its own landmark ``vertex_ids``.
Requires the ``train`` extra (torch, smplx).
"""

from __future__ import annotations

import contextlib
import io
from types import SimpleNamespace
from typing import Any

import numpy as np

from .core.body import BodyModel
from .errors import ClothUsdError

__all__ = ["to_smplx"]


def to_smplx(body: BodyModel, *, batch_size: int = 1) -> Any:
    """Build an ``smplx.SMPL`` module over the arrays of ``body``."""
    try:
        import smplx
    except ImportError as exc:
        raise ClothUsdError("smplx is not installed: pip install 'cloth-usd[train]'") from exc
    num_v = body.num_vertices
    if body.vertex_ids is None and num_v != 6890:
        raise ClothUsdError(f"{body.source}: a {num_v}-vertex body needs 'vertex_ids' landmarks for "
                            "smplx (SMPL's own ids index its 6890-vertex mesh)")
    posedirs = body.posedirs if body.posedirs is not None else np.zeros((num_v, 3, 207))
    kintree = np.stack([body.parents, np.arange(body.parents.shape[0])])
    data = SimpleNamespace(
        v_template=body.v_template, shapedirs=body.shapedirs, posedirs=posedirs,
        J_regressor=body.J_regressor, weights=body.weights, kintree_table=kintree,
        f=body.faces,
    )
    with contextlib.redirect_stdout(io.StringIO()):  # smplx prints a warning for 10 betas
        return smplx.SMPL(model_path="", data_struct=data, vertex_ids=body.vertex_ids,
                          num_betas=body.num_betas, batch_size=batch_size)
