"""scripts/mocap_windows.py: the training windows it cuts from each clip (pure parts; no retargeting)."""

from __future__ import annotations

import pytest
from script_module import ROOT, load_script


@pytest.fixture(scope="module")
def script():
    return load_script("mocap_windows", ROOT / "scripts" / "mocap_windows.py")


def test_windows_follow_one_another_and_short_clips_get_one(script):
    long = script.windows("a/long.bvh", 20.0, length=3.0, short=2.0, per_clip=4)
    assert [w["start_seconds"] for w in long] == [0.5, 3.5, 6.5, 9.5] and all(w["seconds"] == 3.0 for w in long)
    assert script.windows("a/b.bvh", 7.0, length=3.0, short=2.0, per_clip=4) == [
        {"bvh": "a/b.bvh", "start_seconds": 0.5, "seconds": 3.0}, {"bvh": "a/b.bvh", "start_seconds": 3.5,
                                                                    "seconds": 3.0}]
    assert script.windows("c.bvh", 2.6, length=3.0, short=2.0, per_clip=4) == [
        {"bvh": "c.bvh", "start_seconds": 0.2, "seconds": 2.0}]
    assert script.windows("run.bvh", 1.2, length=3.0, short=2.0, per_clip=4) == [
        {"bvh": "run.bvh", "start_seconds": 0.0, "seconds": 1.1, "ramp_seconds": 0.25}]
    assert script.windows("tiny.bvh", 1.09, length=3.0, short=2.0, per_clip=4) == []  # past its end


def test_clip_seconds_reads_the_motion_header(script, tmp_path):
    clip = tmp_path / "c.bvh"
    clip.write_text("HIERARCHY\nROOT Hips\n{\n}\nMOTION\nFrames: 240\nFrame Time: 0.0083333\n0 0 0\n")
    assert script.clip_seconds(clip) == pytest.approx(2.0, abs=1e-3)
    clip.write_text("not a clip\n")
    with pytest.raises(SystemExit, match="no 'Frames:'"):
        script.clip_seconds(clip)
