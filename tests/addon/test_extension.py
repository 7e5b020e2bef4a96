"""The built extension archive: Blender validates it, installs it into a clean Blender
(only bpy and numpy, as Blender ships them, plus Blender's own pxr) and it bakes there
with nothing but its bundled wheels."""

from __future__ import annotations

import json
import os
import runpy
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy", reason="needs bpy (Blender as a Python module): bash scripts/test_addon.sh")

from tests.addon.helpers import ADDON_ID, ROOT, make_tube_shot  # noqa: E402

pytestmark = [pytest.mark.blender, pytest.mark.slow]

#: scripts/build_addon.py's exit status when a pinned wheel can be neither found nor downloaded.
WHEELS_UNAVAILABLE = runpy.run_path(str(ROOT / "scripts" / "build_addon.py"))["WHEELS_UNAVAILABLE"]

PLATFORM = {"linux": "linux-x64", "win32": "windows-x64"}.get(sys.platform, "macos-arm64")

# Run inside the clean Blender: install the archive, report where modules come from, bake.
_SCRIPT = textwrap.dedent("""
    import json, sys
    import bpy
    sys.path.append(sys.argv[3])  # Blender's own site-packages, on sys.path inside Blender
    result = bpy.ops.extensions.package_install_files(
        filepath=sys.argv[1], repo="user_default", enable_on_install=True)
    import cloth_usd, numpy, onnxruntime, pxr, scipy, threadpoolctl, tqdm
    scene = bpy.context.scene
    scene.cloth_usd.shot_path = sys.argv[2]
    baked = bpy.ops.cloth_usd.bake()
    scene.cloth_usd.tier = "detail"  # the shipped bundle, run by the bundled onnxruntime
    detail = bpy.ops.cloth_usd.bake()
    json.dump({
        "install": sorted(result), "bake": sorted(baked), "detail": sorted(detail),
        "files": {m.__name__: m.__file__ for m in (cloth_usd, numpy, onnxruntime, pxr, scipy, threadpoolctl, tqdm)},
        "objects": sorted((ob.name, ob.type, [md.type for md in ob.modifiers])
                          for ob in scene.cloth_usd.collection.objects),
    }, sys.stdout)
""")


def _clean_python_path(folder: Path) -> Path:
    """A folder holding only bpy and numpy, linked from this environment."""
    site = Path(bpy.utils.resource_path("LOCAL")).parents[1]  # LOCAL is <site-packages>/bpy/<version>
    folder.mkdir()
    for name in ("bpy", "numpy", "numpy.libs"):
        if (site / name).exists():
            (folder / name).symlink_to(site / name)
    return folder


def test_archive_validates_installs_and_bakes_in_a_clean_blender(tmp_path):
    built = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_addon.py"), "--platform", PLATFORM,
                            "--out", str(tmp_path / "dist")], capture_output=True, text=True)
    if built.returncode == WHEELS_UNAVAILABLE:  # offline and no wheels cache: nothing of ours failed
        pytest.skip(f"the pinned wheels cannot be had: {built.stderr[-500:]}")
    assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-3000:]
    (archive,) = (tmp_path / "dist").glob(f"{ADDON_ID}-*.zip")

    scripts = Path(bpy.utils.system_resource("SCRIPTS"))
    blender_ext = scripts / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"  # Blender's own tool
    checked = subprocess.run([sys.executable, str(blender_ext), "validate", str(archive)],
                             capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout + checked.stderr

    shot = make_tube_shot(tmp_path / "shot" / "shot.usda")
    user = tmp_path / "user"
    blender_site = (Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib"
                    / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages")
    env = {**os.environ, "BLENDER_USER_RESOURCES": str(user),
           "PYTHONPATH": str(_clean_python_path(tmp_path / "clean"))}
    ran = subprocess.run([sys.executable, "-S", "-c", _SCRIPT, str(archive), str(shot), str(blender_site)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert ran.returncode == 0, ran.stderr[-3000:]
    report = json.loads(ran.stdout[ran.stdout.index("{"):])

    assert report["install"] == ["FINISHED"] and report["bake"] == ["FINISHED"]
    assert report["detail"] == ["FINISHED"]
    files = {name: Path(f) for name, f in report["files"].items()}
    for bundled in ("cloth_usd", "scipy", "tqdm", "threadpoolctl", "onnxruntime"):  # from the archive's wheels
        assert user in files[bundled].parents, f"{bundled} came from {files[bundled]}"
    assert blender_site in files["pxr"].parents  # Blender's own USD, not usd-core
    assert ["Tube", "MESH", ["MESH_SEQUENCE_CACHE"]] in report["objects"]
