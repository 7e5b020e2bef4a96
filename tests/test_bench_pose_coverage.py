"""bench/bench_pose_coverage.py on the two CMU fixtures: the bake's own pose test, counted per bundle."""

from __future__ import annotations

import json
import shutil

import numpy as np

from script_module import ROOT, load_script

MOCAP = ROOT / "tests" / "data" / "mocap"


def test_it_counts_the_frames_a_bake_would_warn_on(tmp_path, capsys):
    """A bundle whose recorded training poses keep the knees nearly straight: the bench counts the
    frames the bake's test (pose_outliers) flags, clip by clip."""
    bench = load_script("bench_pose_coverage", ROOT / "bench" / "bench_pose_coverage.py")
    from cloth_usd.core.limits import pose_outliers
    from cloth_usd.runtime.bundle import load_bundle

    narrow = tmp_path / "narrow"
    shutil.copytree(ROOT / "models" / "bundles" / "sample-tshirt-own", narrow)
    manifest = json.loads((narrow / "manifest.json").read_text())
    table = manifest["training_data"]["poses"]["euler_deg"]
    for knee in ("left_knee", "right_knee"):  # bent 5 degrees at most (+10 of margin): a walk's swing leg is past it
        table[knee][0] = [-5.0, 5.0]
    (narrow / "manifest.json").write_text(json.dumps(manifest))
    clips = sorted(MOCAP.glob("*.bvh"))
    poses = [bench.clip_poses(p) for p in clips]
    frames = sum(len(p) for p in poses)
    limits = load_bundle(narrow).pose_limits
    flagged = [0 if (o := pose_outliers(p, limits=limits)) is None else o.frames.size for p in poses]
    assert 0 < sum(flagged) < frames

    assert bench.main(["--mocap", str(MOCAP), "--bundle", str(narrow)]) == 0
    out = capsys.readouterr().out
    assert f"2 clips, {frames} frames" in out
    row = next(line for line in out.splitlines() if line.startswith(f"| {narrow} |")).split("|")
    assert row[2].strip() == f"{sum(flagged) / frames:.1%}"
    assert row[3].strip() == f"{sum(f > len(p) / 2 for f, p in zip(flagged, poses))} of 2"
    # the clip's captured frames only: the converter's synthetic T-pose is left out
    assert all(np.abs(p[:, 3:]).max(axis=1).min() > 0.05 for p in poses)
    assert bench.main(["--mocap", str(MOCAP), "--bundle", str(narrow), "--exclude", clips[0].name]) == 0
    assert f"1 clips, {len(poses[1])} frames" in capsys.readouterr().out


def test_a_folder_without_clips_is_refused(tmp_path, capsys):
    bench = load_script("bench_pose_coverage", ROOT / "bench" / "bench_pose_coverage.py")
    bundle = str(ROOT / "models" / "bundles" / "sample-tshirt-own")
    assert bench.main(["--mocap", str(tmp_path), "--bundle", bundle]) == 2
    assert f"--mocap {tmp_path}: no .bvh file under it" in capsys.readouterr().err
    (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT")
    assert bench.main(["--mocap", str(tmp_path), "--bundle", bundle]) == 2
    assert "none of its 1 .bvh files could be read: broken.bvh" in capsys.readouterr().err
