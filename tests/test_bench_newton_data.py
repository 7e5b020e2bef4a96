"""bench/bench_newton_repeat.py on the tiny data set and a copy of it whose garments are moved by a known step,
and bench/testset_quality.py's sequences furthest from skinning on a copy with one vertex moved far off.

The data set is the factory's on the tiny config with the fake simulator of
``tests/nn/train_data.py``; the "repeat" is its copy with every simulated vertex 4 mm further
along x, so the gap between the runs is 4 mm exactly and the floor 2 mm.
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest

from script_module import ROOT, load_script

STEP_M = 0.004


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    from cloth_usd.core.shards import read_shard, write_shard

    train_data = load_script("train_data", ROOT / "tests" / "nn" / "train_data.py")
    data = train_data.tiny_dataset(tmp_path_factory)
    again = tmp_path_factory.mktemp("repeat") / "again"
    shutil.copytree(data, again)
    for path in again.glob("*.npz"):
        if path.name == "fit.npz":
            continue
        shard = read_shard(path)
        write_shard(path, dataclasses.replace(shard, positions=shard.positions + np.float32([STEP_M, 0.0, 0.0])))
    return data, again


def _bench():
    return load_script("bench_newton_repeat", ROOT / "bench" / "bench_newton_repeat.py")


def test_gap_and_floor_of_a_known_step(runs, tmp_path, capsys):
    data, again = runs
    assert _bench().main(["--data", str(data), "--repeat", str(again), "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "newton_repeat.json").read_text())
    total = report["total"]
    assert total["sequences"] >= 2  # the tiny set's unseen body, shirt and motion
    assert total["gap_mm"] == pytest.approx(1000 * STEP_M, rel=1e-3)
    assert total["floor_mm"] == pytest.approx(500 * STEP_M, rel=1e-3)
    assert total["floor_over_skinning"] == pytest.approx(total["floor_mm"] / total["skinning_mm"])
    for row in report["sequences"]:
        assert row["gap_first_quarter_mm"] == pytest.approx(1000 * STEP_M, rel=1e-3)
        assert row["gap_last_quarter_mm"] == pytest.approx(1000 * STEP_M, rel=1e-3)
    assert "Floor: no model averages less than" in (tmp_path / "newton_repeat.md").read_text()


def test_a_run_against_itself_has_no_floor(runs, tmp_path):
    data, _ = runs
    assert _bench().main(["--data", str(data), "--repeat", str(data), "--out", str(tmp_path)]) == 0
    total = json.loads((tmp_path / "newton_repeat.json").read_text())["total"]
    assert total["gap_mm"] == 0.0 and total["floor_mm"] == 0.0 and total["skinning_mm"] > 0


def test_other_motions_under_the_same_name_are_refused(runs, tmp_path):
    from cloth_usd.core.shards import read_shard, write_shard

    data, again = runs
    other = tmp_path / "other"
    shutil.copytree(again, other)
    path = next(p for p in sorted(other.glob("test_*.npz")))
    shard = read_shard(path)
    write_shard(path, dataclasses.replace(shard, poses=shard.poses + 0.1))
    with pytest.raises(SystemExit, match="different motions"):
        _bench().main(["--data", str(data), "--repeat", str(other), "--out", str(tmp_path / "out")])


def test_quality_report_lists_the_sequence_whose_cloth_left_the_skinned_garment_first(runs, tmp_path):
    """bench/testset_quality.py: one vertex of one frame moved 30 cm off puts its sequence first, at that frame."""
    from cloth_usd.core.shards import Manifest, read_shard, write_shard

    data, _ = runs
    broken = tmp_path / "broken"
    shutil.copytree(data, broken)
    manifest = Manifest.read(broken)
    name = sorted(n for n, e in manifest.sequences.items() if e.get("status") == "ok")[0]
    path = broken / manifest.sequences[name]["shard"]
    shard = read_shard(path)
    positions = shard.positions.copy()
    positions[2, 7] += np.float32([0.0, 0.3, 0.0])  # a procedural motion: no warm-up, frame 2 is evaluated frame 2
    write_shard(path, dataclasses.replace(shard, positions=positions))
    quality = load_script("testset_quality", ROOT / "bench" / "testset_quality.py")
    assert quality.main([str(broken), "--out", str(tmp_path / "q"), "--furthest", "3"]) == 0
    report = json.loads((tmp_path / "q" / "quality.json").read_text())
    furthest = report["furthest_from_skinning"]
    assert len(furthest) == sum(r["kept"] for r in report["splits"])
    assert furthest[0]["sequence"] == name and furthest[0]["frame"] == 2
    assert furthest[0]["max_mm"] > 250 and furthest[1]["max_mm"] < 50  # the stand-in's ripples: a few mm
    assert [f["max_mm"] for f in furthest] == sorted((f["max_mm"] for f in furthest), reverse=True)
    assert "look at these frames first" in (tmp_path / "q" / "quality.md").read_text()
    # one vertex 30 cm off bares no body; every stand-in garment stays on its body
    assert all(0.0 <= f["bare_max"] < 0.05 for f in furthest), [f["bare_max"] for f in furthest]
