"""The wheel's package list covers every package in the tree, and ships the body model."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_is_listed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "cloth_usd").rglob("__init__.py")}
    assert found <= listed, f"add to pyproject.toml [tool.setuptools] packages: {sorted(found - listed)}"
    assert config["package-dir"]["cloth_usd.models"] == "models"
    data = config["package-data"]["cloth_usd.models"]
    assert "body/*.npz" in data and (ROOT / "models" / "body" / "cloth_usd_neutral.npz").exists()
