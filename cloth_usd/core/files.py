"""Where shipped model files live, and file hashes for manifests and provenance."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["models_dir", "file_sha256"]


def models_dir() -> Path:
    """The shipped ``models/`` folder: ``cloth_usd/models`` when installed from a wheel,
    else the repository's ``models/`` (an editable install or a checkout)."""
    installed = Path(__file__).resolve().parents[1] / "models"
    return installed if installed.exists() else Path(__file__).resolve().parents[2] / "models"


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
