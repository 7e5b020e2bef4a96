"""The data factory's shard and manifest files (numpy ``.npz`` and JSON, no simulator).

Read by training (:mod:`cloth_usd.nn.data`) and rendering, written by the factory
(:mod:`cloth_usd.datagen.dataset`, which re-exports these names). Never pickle: every
array is plain and :func:`read_shard` loads with ``allow_pickle=False``. Shape letters:
T frames, N garment vertices.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import ClothUsdError

__all__ = ["DatasetError", "SHARD_FORMAT", "MANIFEST_NAME", "Shard", "Manifest", "atomic_write",
           "write_shard", "read_shard"]

#: Version of the shard layout; bump when keys change meaning.
SHARD_FORMAT = 1
MANIFEST_NAME = "manifest.json"


class DatasetError(ClothUsdError):
    """A shard or manifest is unreadable, or a job is malformed."""


@dataclass(frozen=True)
class Shard:
    """One sequence as stored on disk."""

    garment_vertices: np.ndarray
    """(N, 3) float32 rest garment [m]."""
    garment_faces: np.ndarray
    """(M, 3) int64 triangles."""
    positions: np.ndarray
    """(T, N, 3) float32 simulated garment [m], world frame."""
    coarse: np.ndarray
    """(T, N, 3) float32 coarse target [m]: Laplacian smoothing of ``positions``."""
    betas: np.ndarray
    """(B',) float64."""
    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad]."""
    transl: np.ndarray
    """(T, 3) float64 [m]."""
    assoc_vertex: np.ndarray
    """(N,) int64 associated body vertex (nearest vertex of the unposed body, docs/method.md's I)."""
    fit_distance: np.ndarray
    """(N,) float32 distance [m] from each rest garment vertex to its associated body vertex."""
    surface_distance: np.ndarray
    """(N,) float32 distance [m] from each rest garment vertex to the unposed body surface."""
    penetration: np.ndarray
    """(T,) float32 fraction of garment vertices inside the posed body."""
    max_stretch: np.ndarray
    """(T,) float32 largest edge length ratio."""
    digest: str
    """The job digest the shard was made from."""
    meta: dict
    """JSON provenance: name, seed, config, engine versions, quality, job meta."""


def atomic_write(path: Path, write: Callable[[object], None], suffix: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


_ARRAY_KEYS = ("garment_vertices", "garment_faces", "positions", "coarse", "betas", "poses", "transl",
               "assoc_vertex", "fit_distance", "surface_distance", "penetration", "max_stretch")


def write_shard(path: str | Path, shard: Shard) -> Path:
    """Write a shard atomically (temp file in the same folder, then rename)."""
    path = Path(path)
    arrays = {k: getattr(shard, k) for k in _ARRAY_KEYS}
    arrays["digest"] = np.array(shard.digest)
    arrays["meta_json"] = np.array(json.dumps(shard.meta, sort_keys=True))
    arrays["format"] = np.array(SHARD_FORMAT)
    atomic_write(path, lambda fh: np.savez_compressed(fh, **arrays), ".npz.tmp")
    return path


def read_shard(path: str | Path) -> Shard:
    """Read a shard; raises :class:`DatasetError` naming the file and the fault."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in _ARRAY_KEYS + ("digest", "meta_json", "format") if k not in data.files]
            if missing:
                raise DatasetError(f"{path}: not a cloth_usd shard, missing {', '.join(missing)}")
            if int(data["format"]) != SHARD_FORMAT:
                raise DatasetError(f"{path}: shard format {int(data['format'])}, this code reads {SHARD_FORMAT}")
            arrays = {k: data[k] for k in _ARRAY_KEYS}
            digest, meta = str(data["digest"]), json.loads(str(data["meta_json"]))
    except DatasetError:
        raise
    except Exception as exc:  # OSError, zipfile.BadZipFile, ValueError from a truncated file
        raise DatasetError(f"{path}: unreadable shard ({exc})") from exc
    t, n = arrays["positions"].shape[:2]
    if arrays["coarse"].shape != (t, n, 3) or arrays["garment_vertices"].shape != (n, 3) \
            or arrays["poses"].shape != (t, 72):
        raise DatasetError(f"{path}: inconsistent shapes (positions {arrays['positions'].shape}, "
                           f"coarse {arrays['coarse'].shape}, poses {arrays['poses'].shape})")
    return Shard(**arrays, digest=digest, meta=meta)


@dataclass
class Manifest:
    """The JSON record of a data set folder."""

    config: dict
    """The SimConfig, as JSON."""
    dataset: dict
    """The DatasetConfig, as JSON."""
    engine: dict
    """Engine versions: newton, warp."""
    sequences: dict = field(default_factory=dict)
    """name -> {status: 'ok'|'rejected', seed, digest, shard, quality, meta}."""

    @property
    def rejected(self) -> list[str]:
        return sorted(k for k, v in self.sequences.items() if v["status"] == "rejected")

    @property
    def partial(self) -> list[str]:
        """The accepted sequences that went unstable and keep only their first frames
        (``SimConfig.keep_partial``)."""
        return sorted(k for k, v in self.sequences.items() if v["status"] == "ok" and v.get("partial"))

    @property
    def accepted(self) -> list[str]:
        return sorted(k for k, v in self.sequences.items() if v["status"] == "ok")

    def to_json(self) -> dict:
        return {"format": SHARD_FORMAT, "config": self.config, "dataset": self.dataset,
                "engine": self.engine, "sequences": self.sequences, "rejected": self.rejected}

    def write(self, folder: str | Path, name: str = MANIFEST_NAME) -> Path:
        """Write ``manifest.json`` (or ``name``: a worker's own) atomically."""
        path = Path(folder) / name
        text = json.dumps(self.to_json(), indent=2, sort_keys=True).encode()
        atomic_write(path, lambda fh: fh.write(text), ".json.tmp")
        return path

    @classmethod
    def read(cls, folder: str | Path, name: str = MANIFEST_NAME) -> "Manifest":
        path = Path(folder) / name
        try:
            raw = json.loads(path.read_text())
            return cls(config=raw["config"], dataset=raw["dataset"], engine=raw["engine"],
                       sequences=raw["sequences"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DatasetError(f"{path}: unreadable manifest ({exc})") from exc

