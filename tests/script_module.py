"""A script of the repository (``bench/``, ``tests/nn/train_data.py``) loaded as a module by its path, once
per session, for the tests that call its functions."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_script(name: str, path: Path):
    """The module ``name`` made from the file ``path`` (the one already loaded under that name, if any)."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # before exec: dataclasses look their module up
        spec.loader.exec_module(module)
    return sys.modules[name]
