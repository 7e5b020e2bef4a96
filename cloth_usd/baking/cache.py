"""Body models, model bundles and bound garments kept across bakes (one per batch worker)."""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..core.body import BodyModel, load_body_model
from ..core.scene import Garment, Tier
from ..runtime.bundle import ModelBundle

__all__ = ["ModelCache", "garment_key"]


class ModelCache:
    """Body models, model bundles and bound garments kept across bakes.

    A batch worker keeps one for all its jobs, so each body model and bundle is loaded
    (and verified) once per process and each garment is bound to its body once, even
    when its frames come in several chunks. Files are assumed not to change while a
    cache lives.

    Args:
        max_garments: bound garments kept (least recently used dropped first).
    """

    def __init__(self, max_garments: int = 8) -> None:
        self._bodies: dict[tuple[str, str], BodyModel] = {}
        self._bundles: dict[tuple[str, ...] | None, dict] = {}
        self._garments: OrderedDict[str, Any] = OrderedDict()
        self.max_garments = max_garments

    def body(self, path: str | Path | None, gender: str) -> BodyModel:
        """The body model of :func:`~cloth_usd.core.body.load_body_model`, loaded once."""
        key = ("" if path is None else os.path.abspath(path), gender)
        if key not in self._bodies:
            self._bodies[key] = load_body_model(path, gender=gender)
        return self._bodies[key]

    def bundles(self, models: Sequence[str | Path] | None) -> dict:
        """The bundles found so far in these search folders, by category."""
        key = None if models is None else tuple(os.path.abspath(m) for m in models)
        return self._bundles.setdefault(key, {})

    def garment(self, key: str, make: Callable[[], Any]) -> Any:
        """``make()`` once per ``key``."""
        if key in self._garments:
            self._garments.move_to_end(key)
            return self._garments[key]
        value = make()
        self._garments[key] = value
        while len(self._garments) > self.max_garments:
            self._garments.popitem(last=False)
        return value


def garment_key(garment: Garment, body: BodyModel, betas: np.ndarray, rest: np.ndarray,
                tier: Tier, bundle: ModelBundle | None) -> str:
    """The :meth:`ModelCache.garment` key of a garment bound to a body for a tier.

    Args:
        betas: (10,) float64; rest: (N, 3) float64 canonical rest points [m].
    """
    h = hashlib.sha256()
    for part in (body.sha256.encode(), tier.value.encode(), (bundle.sha256 if bundle else "").encode(),
                 np.ascontiguousarray(betas, dtype=np.float64).tobytes(),
                 np.ascontiguousarray(rest, dtype=np.float64).tobytes(),
                 np.ascontiguousarray(garment.triangles, dtype=np.int64).tobytes()):
        h.update(part)
        h.update(b"|")
    return h.hexdigest()
