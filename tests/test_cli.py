"""End to end: the cloth-usd command on the bundled samples, and every contract error."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.cli import main

SAMPLES = Path(__file__).resolve().parents[1] / "samples"
WALK = SAMPLES / "walk_tshirt" / "scene.usda"
ZUP = SAMPLES / "walk_tshirt_zup_cm" / "scene.usda"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _points(layer_path: Path, prim: str, t: float) -> np.ndarray:
    stage = Usd.Stage.Open(str(layer_path))
    return np.array(UsdGeom.Mesh(stage.GetPrimAtPath(prim)).GetPointsAttr().Get(t))


def _rest(scene: Path, prim: str) -> np.ndarray:
    stage = Usd.Stage.Open(str(scene))
    return np.array(UsdGeom.Mesh(stage.GetPrimAtPath(prim)).GetPointsAttr().Get())


def test_bake_writes_cache_and_shot_and_never_touches_the_source(tmp_path, capsys):
    before = _digest(WALK)
    cache, shot = tmp_path / "cache.usdc", tmp_path / "shot.usda"
    assert main(["bake", str(WALK), "-o", str(cache), "--shot", str(shot)]) == 0
    assert _digest(WALK) == before
    assert "wrote" in capsys.readouterr().out
    layer = Sdf.Layer.FindOrOpen(str(cache))
    assert (layer.startTimeCode, layer.endTimeCode) == (1001.0, 1096.0)
    times = layer.ListTimeSamplesForPath("/Character/Tshirt.points")
    assert list(times) == [1001.0 + i for i in range(96)]
    prov = layer.customLayerData["cloth_usd"]
    assert prov["garments"]["/Character/Tshirt"]["tier"] == "skinning"
    assert prov["source_layer"].endswith("scene.usda")
    assert len(prov["body_models"]["neutral"]["sha256"]) == 64
    # Composed through the shot layer: time-sampled, following the walk forward (+Z, Y-up metres).
    first, last = _points(shot, "/Character/Tshirt", 1001), _points(shot, "/Character/Tshirt", 1096)
    np.testing.assert_allclose(first, _rest(WALK, "/Character/Tshirt"), atol=1e-5)  # frame 0 is the rest pose
    advance = last.mean(axis=0) - first.mean(axis=0)
    assert 3.0 < advance[2] < 5.0 and abs(advance[0]) < 0.3
    stage = Usd.Stage.Open(str(shot))
    assert stage.GetPrimAtPath("/Character/Skeleton").IsA(UsdSkel.Skeleton)


def test_zup_centimetre_stage_round_trips_units_and_axis(tmp_path):
    cache = tmp_path / "cache.usdc"
    assert main(["bake", str(ZUP), "-o", str(cache), "--frames", "1001:1024:23"]) == 0
    layer = Sdf.Layer.FindOrOpen(str(cache))
    assert layer.pseudoRoot.GetInfo("upAxis") == "Z" and layer.pseudoRoot.GetInfo("metersPerUnit") == 0.01
    assert list(layer.ListTimeSamplesForPath("/Character/Tshirt.points")) == [1001.0, 1024.0]
    first = np.array(layer.QueryTimeSample("/Character/Tshirt.points", 1001.0))
    np.testing.assert_allclose(first, _rest(ZUP, "/Character/Tshirt"), atol=1e-3)  # centimetres
    assert 30.0 < np.ptp(first[:, 2]) < 90.0  # shirt height in cm, along Z
    last = np.array(layer.QueryTimeSample("/Character/Tshirt.points", 1024.0))
    assert (last.mean(axis=0) - first.mean(axis=0))[1] < -50.0  # the body walks to +Z_smpl = -Y_stage


def test_frames_step_and_garment_selection(tmp_path):
    cache = tmp_path / "cache.usda"
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", "1010:1020:5",
                 "--garment", "/Character/Tshirt", "--tier", "skinning"]) == 0
    layer = Sdf.Layer.FindOrOpen(str(cache))
    assert list(layer.ListTimeSamplesForPath("/Character/Tshirt.points")) == [1010.0, 1015.0, 1020.0]


def test_refuses_overwrite_without_force(tmp_path, capsys):
    cache = tmp_path / "cache.usdc"
    cache.write_bytes(b"keep me")
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", "1001:1002"]) == 2
    assert "--force" in capsys.readouterr().err
    assert cache.read_bytes() == b"keep me"
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", "1001:1002", "--force"]) == 0


def test_inspect_and_doctor(capsys):
    assert main(["inspect", str(WALK)]) == 0
    out = capsys.readouterr().out
    assert "/Character/Skeleton" in out and "/Character/Tshirt" in out and "tshirt" in out
    assert "1001..1096" in out and "problems    0" in out
    assert "models sample-tshirt-own (its own)" in out  # the bundle its learned tiers bake with
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    assert "FAIL" not in out and "body model" in out


def test_a_reshaped_garment_is_warned_about_by_its_own_bundle(tmp_path, caplog):
    """The sample shirt's own bundle was trained on the shirt as the sample holds it; the same
    triangles reshaped (here the shirt let out by 2 cm at the hem) bake with a warning naming
    how far, and the unchanged shirt bakes without one."""
    shirt = tmp_path / "scene.usda"
    shutil.copy(WALK, shirt)
    stage = Usd.Stage.Open(str(shirt))
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Tshirt")).GetPointsAttr()
    p = np.array(points.Get(), dtype=np.float64)
    low = p[:, 1] < np.percentile(p[:, 1], 20)
    p[low, 0] *= 1.0 + 0.02 / np.abs(p[low, 0]).max()
    points.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)))
    stage.GetRootLayer().Save()
    args = ["--tier", "coarse", "--frames", "1001:1002", "--no-progress"]
    with caplog.at_level("WARNING"):
        assert main(["bake", str(WALK), "-o", str(tmp_path / "a.usdc"), *args]) == 0
        assert "was trained on (the same triangles" not in caplog.text
        assert main(["bake", str(shirt), "-o", str(tmp_path / "b.usdc"), *args]) == 0
    said = [r.getMessage() for r in caplog.records if "the same triangles" in r.getMessage()]
    assert len(said) == 1 and "</Character/Tshirt>: its rest points lie up to 20 mm" in said[0]
    assert "'sample-tshirt-own'" in said[0]


def _broken(tmp_path: Path, edit) -> Path:
    """A copy of the walk sample with one contract violation."""
    path = tmp_path / "broken.usda"
    shutil.copy(WALK, path)
    stage = Usd.Stage.Open(str(path))
    edit(stage)
    stage.GetRootLayer().Save()
    return path


def _rename_joint(stage):
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Character/Skeleton"))
    joints = [j.replace("left_elbow", "left_elbo") for j in skel.GetJointsAttr().Get()]
    skel.GetJointsAttr().Set(joints)


def _reparent_joint(stage):
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Character/Skeleton"))
    joints = [str(j) for j in skel.GetJointsAttr().Get()]
    # left_knee hangs under right_hip instead of left_hip.
    joints = [j.replace("pelvis/left_hip/left_knee", "pelvis/right_hip/left_knee") for j in joints]
    skel.GetJointsAttr().Set(joints)


def _drop_body(stage):
    stage.GetPrimAtPath("/Character/Tshirt").RemoveProperty("cloth:body")


def _nan_points(stage):
    attr = UsdGeom.Mesh(stage.GetPrimAtPath("/Character/Tshirt")).GetPointsAttr()
    pts = np.array(attr.Get())
    pts[7, 1] = np.nan
    attr.Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))


@pytest.mark.parametrize("edit, expect", [
    (_rename_joint, r"/Character/Skeleton.*left_elbow"),
    (_reparent_joint, r"/Character/Skeleton.*left_knee"),
    (_drop_body, r"/Character/Tshirt.*cloth:body"),
    (_nan_points, r"/Character/Tshirt.*(NaN|non-finite)"),
])
def test_contract_errors_are_one_line_and_write_nothing(tmp_path, capsys, edit, expect):
    scene = _broken(tmp_path, edit)
    cache, shot = tmp_path / "cache.usdc", tmp_path / "shot.usda"
    assert main(["bake", str(scene), "-o", str(cache), "--shot", str(shot)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("cloth-usd: error: ")
    assert "broken.usda" in err
    import re
    assert re.search(expect, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.usda"]


@pytest.mark.parametrize("args, expect", [
    (["--frames", "1050:1001"], "--frames '1050:1001': empty range"),
    (["--frames", "abc"], "--frames 'abc'"),
    (["--tier", "ultra"], "--tier 'ultra': unknown tier (valid: skinning, coarse, detail)"),
    (["--tier", "detail", "--models", "/no/such/bundles"], "--models /no/such/bundles: no such folder"),
    (["--garment", "/Nope"], "--garment /Nope: no garment"),
    (["--body-model", "/no/such/body.npz"], "/no/such/body.npz: body model file not found"),
])
def test_argument_errors(tmp_path, capsys, args, expect):
    cache = tmp_path / "cache.usdc"
    assert main(["bake", str(WALK), "-o", str(cache), *args]) == 2
    err = capsys.readouterr().err
    assert expect in err and len(err.strip().splitlines()) == 1
    assert not cache.exists()


def test_empty_stage_range_and_unreadable_file(tmp_path, capsys):
    scene = _broken(tmp_path, lambda s: (s.SetStartTimeCode(1010), s.SetEndTimeCode(1001)))
    assert main(["bake", str(scene), "-o", str(tmp_path / "c.usdc")]) == 2
    assert "broken.usda: empty frame range" in capsys.readouterr().err
    junk = tmp_path / "junk.usda"
    junk.write_text("this is not usd")
    assert main(["bake", str(junk), "-o", str(tmp_path / "c.usdc")]) == 2
    assert "junk.usda" in capsys.readouterr().err
    assert main(["bake", str(tmp_path / "missing.usda"), "-o", str(tmp_path / "c.usdc")]) == 2
    assert "missing.usda" in capsys.readouterr().err


@pytest.mark.parametrize("where", ["before", "after", "none"])
def test_verbose_shows_the_traceback(tmp_path, capsys, where):
    args = ["bake", str(WALK), "-o", str(tmp_path / "c.usdc"), "--tier", "ultra"]
    args = {"before": ["-v", *args], "after": [*args, "--verbose"], "none": args}[where]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert ("Traceback" in err) is (where != "none")
    assert err.rstrip().splitlines()[-1].startswith("cloth-usd: error: --tier 'ultra'")


@pytest.mark.parametrize("argv", [["inspect", "s.usda"], ["bake", "s.usda", "-o", "c.usdc"], ["doctor"],
                                  ["datagen", "c.toml", "-o", "d"], ["batch", "jobs.toml"],
                                  ["render", "s.usda", "-o", "p.png", "--frames", "1"],
                                  ["train", "coarse", "--data", "d", "-o", "r"],
                                  ["export", "--coarse-run", "r", "--data", "d", "-o", "b", "--name", "n"],
                                  ["evaluate", "--data", "d", "--bundle", "b", "-o", "e"]])
def test_verbose_goes_before_or_after_every_command(argv):
    from cloth_usd.cli import _parser

    assert _parser().parse_args(argv).verbose is False
    assert _parser().parse_args(["-v", *argv]).verbose is True
    assert _parser().parse_args([*argv, "-v"]).verbose is True
    assert _parser().parse_args([argv[0], "--verbose", *argv[1:]]).verbose is True


def test_python_api(tmp_path):
    import cloth_usd

    result = cloth_usd.bake(WALK, tmp_path / "cache.usdc", frames="1001:1004")
    assert result.times.tolist() == [1001.0, 1002.0, 1003.0, 1004.0]
    assert result.garments[0].vertices == _rest(WALK, "/Character/Tshirt").shape[0]


def test_render_draws_a_stage_and_names_a_bad_view(tmp_path, capsys):
    png = tmp_path / "walk.png"
    assert main(["render", str(WALK), "-o", str(png), "--frames", "1001:1030:29"]) == 0  # as bake's: 1001, 1030
    assert png.stat().st_size > 1000
    assert main(["render", str(WALK), "-o", str(png), "--frames", "1001", "--view", "top"]) == 2
    assert "--view 'top': unknown" in capsys.readouterr().err


_SLOW_BAKE = """
import sys, time
import cloth_usd.baking.garment as garment
real = garment.skin_garment
def slow(*args, **kwargs):  # a long shot, without its memory
    time.sleep(0.5)
    return real(*args, **kwargs)
garment.skin_garment = slow
from cloth_usd.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_mid_bake_removes_the_temporary_files_and_says_so(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SAMPLES.parent), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_BAKE, "bake", str(WALK), "-o", str(tmp_path / "c.usdc"),
                             "--shot", str(tmp_path / "shot.usda"), "--frames", "1001:1096:0.25", "--no-progress"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob(".c.*.tmp.usdc")):  # the writer has begun
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.05)
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143, (out, err)
    assert err == ("cloth-usd: interrupted (SIGTERM); nothing partial was left "
                                       "(a cache and its shot are written whole, together, or not at all)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_full_stdout_keeps_the_cache_and_says_so_in_one_line(tmp_path, capsys, monkeypatch):
    import errno
    import sys

    class Full:
        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self):
            pass

    monkeypatch.setattr(sys, "stdout", Full())
    cache = tmp_path / "c.usdc"
    assert main(["bake", str(WALK), "-o", str(cache), "--frames", "1001:1003", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err == (f"cloth-usd: error: stdout: cannot write the summary (No space left on device); {cache} was "
                   "written and is complete\n")
    assert list(Sdf.Layer.FindOrOpen(str(cache)).ListTimeSamplesForPath("/Character/Tshirt.points")) == [
        1001.0, 1002.0, 1003.0]


def test_main_leaves_the_sigterm_handler_as_it_found_it():
    import signal

    before = signal.getsignal(signal.SIGTERM)
    assert main(["bake", "nothing.usda", "-o", "x.usdc"]) == 2
    assert signal.getsignal(signal.SIGTERM) is before


def test_train_refuses_physics_settings_for_a_supervised_run(tmp_path, capsys):
    """The "physics" table of a --config and --mocap are physics-run settings: a supervised run
    that is given them says so in one line instead of ignoring them."""
    pytest.importorskip("torch")
    config = tmp_path / "c.json"
    config.write_text('{"objective": "supervised", "physics": {"dynamic": true}}')
    assert main(["train", "coarse", "--data", str(tmp_path), "-o", str(tmp_path / "run"), "--config", str(config)]) == 2
    assert "physics\" table applies to --objective physics or hybrid only" in capsys.readouterr().err
    assert main(["train", "coarse", "--data", str(tmp_path), "-o", str(tmp_path / "run"), "--mocap", str(tmp_path)]) == 2
    assert "--mocap: only a physics run" in capsys.readouterr().err
    config.write_text('{"objective": "physics", "physics": {"dynamc": true}}')
    assert main(["train", "coarse", "--data", str(tmp_path), "-o", str(tmp_path / "run"), "--config", str(config)]) == 2
    assert "dynamc" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("flag, value", [("--batch", "0"), ("--workers", "0"), ("--penetration-frames", "0"),
                                         ("--max-minutes", "-1")])
def test_datagen_refuses_a_bad_count_in_one_line(tmp_path, capsys, flag, value):
    config = tmp_path / "c.json"
    config.write_text("{}")
    assert main(["datagen", str(config), "-o", str(tmp_path / "d"), flag, value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"cloth-usd: error: {flag} must be at least {0 if flag == '--max-minutes' else 1}, got {value}"]
    assert not (tmp_path / "d").exists()
