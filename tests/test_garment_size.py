"""inspect warns about and bake refuses a garment in the wrong units (the decimetre top)."""

from __future__ import annotations

import shutil
from pathlib import Path

from pxr import Usd, UsdGeom

from cloth_usd.cli import main

WALK = Path(__file__).resolve().parents[1] / "samples" / "walk_tshirt" / "scene.usda"


def _scaled(tmp_path: Path, factor: float) -> Path:
    path = tmp_path / "scaled.usda"
    shutil.copy(WALK, path)
    stage = Usd.Stage.Open(str(path))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Tshirt")).GetPointsAttr()
    points.Set(points.Get() * factor)  # the mesh left in decimetres in a metre stage
    stage.GetRootLayer().Save()
    return path


def test_inspect_warns_and_bake_refuses_a_ten_times_garment(tmp_path, capsys):
    scene = _scaled(tmp_path, 10.0)
    assert main(["inspect", str(scene)]) == 0  # a warning, not a contract violation
    out = capsys.readouterr().out
    assert "warnings    3" in out and "times the body's height" in out and "/Character/Tshirt" in out
    assert "from the body </Character/Skeleton> on average at rest" in out  # as the bake says it
    cache = tmp_path / "cache.usdc"
    assert main(["bake", str(scene), "-o", str(cache), "--frames", "1001:1002"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "</Character/Tshirt>" in err and "--allow-any-size" in err
    assert not cache.exists()
    assert main(["bake", str(scene), "-o", str(cache), "--frames", "1001:1002", "--allow-any-size"]) == 0


def test_the_sample_shirt_has_no_warnings(capsys):
    assert main(["inspect", str(WALK)]) == 0
    assert "warnings    0" in capsys.readouterr().out
