"""Fixtures of the export tests (helpers in tests/export/helpers.py)."""

from __future__ import annotations

import pytest

from cloth_usd.core.animation import MeshAnimation
from tests.export.helpers import grid_animation


@pytest.fixture
def patch() -> MeshAnimation:
    return grid_animation()
