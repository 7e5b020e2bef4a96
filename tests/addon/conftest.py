"""Fixtures for the Blender add-on tests: bpy (Blender as a Python module, in its own
venv: ``bash scripts/test_addon.sh``), the add-on enabled as an extension straight
from ``addon/``, and small USD shots built with cloth_usd."""

from __future__ import annotations

import atexit
import importlib.util
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

from tests.addon.helpers import ADDON_ID, MODULE, REPO, ROOT

if importlib.util.find_spec("bpy") is None:
    bpy = None  # the tests skip themselves, saying why
else:
    # Keep Blender's user folders (preferences, extension repositories) out of $HOME.
    if "BLENDER_USER_RESOURCES" not in os.environ:
        _user = tempfile.mkdtemp(prefix="cloth_usd_blender_user_")
        atexit.register(shutil.rmtree, _user, ignore_errors=True)
        os.environ["BLENDER_USER_RESOURCES"] = _user
    import bpy

    # Inside Blender, Blender's own site-packages (which holds pxr, its USD build) is on
    # sys.path; bpy as a module ships it but does not add it.
    _site = (Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib"
             / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages")
    if _site.is_dir() and str(_site) not in sys.path:
        sys.path.append(str(_site))


@pytest.fixture(scope="session")
def extension_repo(tmp_path_factory) -> Path:
    """A local extension repository holding a copy of ``addon/``."""
    repo = tmp_path_factory.mktemp("extensions")
    shutil.copytree(ROOT / "addon", repo / ADDON_ID, ignore=shutil.ignore_patterns("__pycache__", "docs"))
    return repo


def _raise(exc: BaseException) -> None:
    raise exc


@pytest.fixture
def blender(extension_repo):
    """Factory-fresh Blender with the add-on enabled; yields ``bpy``."""
    import addon_utils

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.preferences.extensions.repos.new(
        name="cloth_usd dev", module=REPO, custom_directory=str(extension_repo), source="USER")
    addon_utils.enable(MODULE, default_set=True, handle_error=_raise)
    yield bpy
    addon_utils.disable(MODULE, default_set=True, handle_error=_raise)


@pytest.fixture
def prefs(blender):
    """The add-on's preferences."""
    return blender.context.preferences.addons[MODULE].preferences
