"""The sample stage mutated at random: every bake either writes a sound cache (exit 0) or
refuses in one ``cloth-usd: error:`` line (exit 2), and leaves nothing else behind.

Each example applies one to three mutations, drawn by hypothesis, to a fresh copy of
``samples/walk_tshirt/scene.usda`` through the USD API (the way a DCC or a script would
author a broken stage), then bakes it in-process through ``cloth_usd.cli.main``. What is
asserted holds for every mutation: exit code 0 or 2; on 2, exactly one stderr line with
the error prefix, no traceback, and no file written; on 0, a cache whose every time
sample is finite and has the garment's vertex count; the source's bytes never change.
"""

from __future__ import annotations

import hashlib
import math
import shutil
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.cli import main

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"
SKEL, ANIM, SHIRT = "/Character/Skeleton", "/Character/Skeleton/Motion", "/Character/Tshirt"
PREFIX = "cloth-usd: error: "

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                    st.sampled_from([0.0, -1.0, 1e-9, 1e9, -1e30, 24.0, 30.0]))


def _betas(stage, values):
    UsdSkel.Skeleton(stage.GetPrimAtPath(SKEL)).GetPrim().CreateAttribute(
        "smpl:betas", Sdf.ValueTypeNames.FloatArray).Set(Vt.FloatArray(list(values)))


def _rates(stage, values):
    tcps, fps = values
    layer = stage.GetRootLayer()
    layer.timeCodesPerSecond, layer.framesPerSecond = tcps, fps


def _range(stage, values):
    start, end = values
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)


def _drop_joint(stage, index):
    attr = UsdSkel.Skeleton(stage.GetPrimAtPath(SKEL)).GetJointsAttr()
    joints = list(attr.Get())
    del joints[index % len(joints)]
    attr.Set(joints)


def _points(stage, values):
    index, value, scale = values
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(SHIRT)).GetPointsAttr()
    pts = np.array(attr.Get(), dtype=np.float64) * scale
    pts[index % len(pts)] = value
    attr.Set(Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))


def _rotations(stage, values):
    time_index, value = values
    attr = UsdSkel.Animation(stage.GetPrimAtPath(ANIM)).GetRotationsAttr()
    times = attr.GetTimeSamples()
    t = times[time_index % len(times)]
    rot = np.array(attr.Get(t), dtype=np.float64)
    rot[:, 0] = value
    attr.Set(Vt.QuatfArray.FromNumpy(rot.astype(np.float32)), t)


def _unbind(stage, which):
    prim = stage.GetPrimAtPath(SHIRT)
    if which == "body":
        prim.GetRelationship("cloth:body").SetTargets([Sdf.Path("/Character/Nowhere")])
    elif which == "category":
        prim.GetAttribute("cloth:category").Set("cape")
    elif which == "tier":
        prim.CreateAttribute("cloth:tier", Sdf.ValueTypeNames.Token).Set("wrinkly")
    else:
        stage.RemovePrim(ANIM)


MUTATIONS = st.one_of(
    st.tuples(st.just(_betas), st.lists(numbers, max_size=12)),
    st.tuples(st.just(_rates), st.tuples(numbers, numbers)),
    st.tuples(st.just(_range), st.tuples(numbers, numbers)),
    st.tuples(st.just(_drop_joint), st.integers(0, 60)),
    st.tuples(st.just(_points), st.tuples(st.integers(0, 10_000), numbers, st.sampled_from([1.0, 1e-4, 100.0]))),
    st.tuples(st.just(_rotations), st.tuples(st.integers(0, 200), numbers)),
    st.tuples(st.just(_unbind), st.sampled_from(["body", "category", "tier", "animation"])),
)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(mutations=st.lists(MUTATIONS, min_size=1, max_size=3))
def test_a_mutated_stage_bakes_soundly_or_fails_in_one_line(tmp_path_factory, capfd, mutations):
    folder = tmp_path_factory.mktemp("mutant")
    scene = Path(shutil.copy(SAMPLE, folder / "scene.usda"))
    stage = Usd.Stage.Open(str(scene))
    for mutate, value in mutations:
        try:
            mutate(stage, value)
        except Exception:  # USD itself refused to author it: that mutation is not made
            pass
    stage.GetRootLayer().Save()
    before, listing = _sha(scene), sorted(p.name for p in folder.iterdir())
    capfd.readouterr()
    code = main(["bake", str(scene), "-o", str(folder / "cache.usdc"), "--frames", "1001:1006",
                 "--no-progress"])
    out, err = capfd.readouterr()
    assert _sha(scene) == before
    names = [m.__name__ for m, _ in mutations]
    if code == 2:
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith(PREFIX) and "Traceback" not in err, (names, err)
        assert sorted(p.name for p in folder.iterdir()) == listing, names
        return
    assert code == 0, (names, code, err)
    assert sorted(p.name for p in folder.iterdir()) == sorted([*listing, "cache.usdc"]), names  # no temp left
    layer = Sdf.Layer.FindOrOpen(str(folder / "cache.usdc"))
    attr = f"{SHIRT}.points"
    times = layer.ListTimeSamplesForPath(attr)
    assert list(times) == [1001.0 + k for k in range(6)], names
    source = Usd.Stage.Open(str(scene))  # held: a prim of a freed stage is invalid
    count = len(UsdGeom.Mesh(source.GetPrimAtPath(SHIRT)).GetPointsAttr().Get())
    for t in times:
        pts = np.array(layer.QueryTimeSample(attr, t))
        assert pts.shape == (count, 3) and np.isfinite(pts).all() and math.isfinite(float(np.abs(pts).max())), names


def test_the_mutations_do_what_they_say(tmp_path):
    """Each mutation changes the stage (so the property above is not run on the sample alone)."""
    scene = Path(shutil.copy(SAMPLE, tmp_path / "scene.usda"))
    for mutate, value in [(_betas, [1e30]), (_rates, (0.0, 0.0)), (_range, (10.0, 1.0)), (_drop_joint, 3),
                          (_points, (5, float("nan"), 1.0)), (_rotations, (2, float("nan"))), (_unbind, "body"),
                          (_unbind, "animation")]:
        stage = Usd.Stage.Open(str(scene))
        text = stage.GetRootLayer().ExportToString()
        mutate(stage, value)
        assert stage.GetRootLayer().ExportToString() != text, mutate.__name__
        stage.GetRootLayer().Reload(force=True)  # unsaved: the next mutation starts from the sample again
