"""Writing the cache: long bakes in bounded memory, a full disk at the cache or shot write, and
SIGTERM between the cache's and the shot's commit. The sample stage, a few frames of it."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf

import cloth_usd.usd.write as write
from cloth_usd.baking import bake
from cloth_usd.cli import main

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "walk_tshirt" / "scene.usda"
PRIM = "/Character/Tshirt"


def _samples(path: Path) -> dict:
    """Every attribute's time samples, as raw bytes, and the layer's metadata."""
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    out = {}

    def visit(p):
        if p.IsPropertyPath():
            out[str(p)] = [(t, np.asarray(layer.QueryTimeSample(p, t)).tobytes())
                           for t in layer.ListTimeSamplesForPath(p)]

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    meta = (layer.timeCodesPerSecond, layer.framesPerSecond, layer.startTimeCode, layer.endTimeCode,
            layer.pseudoRoot.GetInfo("upAxis"), layer.pseudoRoot.GetInfo("metersPerUnit"))
    return {"samples": out, "meta": meta, "provenance": dict(layer.customLayerData)}


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_a_cache_flushed_every_chunk_reads_back_bit_identical(tmp_path, monkeypatch, suffix):
    whole = bake(SAMPLE, tmp_path / f"whole{suffix}", frames="1001:1020", tier="skinning", chunk=4).cache
    saves = []
    real = write._save
    monkeypatch.setattr(write, "_save", lambda *a: (saves.append(a[1]), real(*a)))
    monkeypatch.setattr(write, "FLUSH_BYTES", 1)  # save after every chunk of 4 frames
    streamed = bake(SAMPLE, tmp_path / f"streamed{suffix}", frames="1001:1020", tier="skinning", chunk=4).cache
    assert len(saves) == 5 + 1  # 5 chunks, then the commit's
    a, b = _samples(whole), _samples(streamed)
    assert a["samples"].keys() == {f"{PRIM}.points", f"{PRIM}.extent"}
    assert len(a["samples"][f"{PRIM}.points"]) == 20
    assert a == b
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([f"whole{suffix}", f"streamed{suffix}"])


_LONG = r"""
import sys, numpy as np
from cloth_usd.core.scene import StageInfo
from cloth_usd.usd.write import CacheLayerWriter
info = StageInfo(identifier="x", up_axis="Y", meters_per_unit=1.0, meters_per_unit_authored=True,
                 time_codes_per_second=24.0, frames_per_second=24.0, start_time_code=1.0, end_time_code=1.0,
                 stage_to_internal=np.eye(4))
n, frames, chunk = 20000, 1200, 40
base = np.random.default_rng(0).standard_normal((n, 3)).astype(np.float32)
with CacheLayerWriter(sys.argv[1], stage=info, start=1, end=frames, flush_bytes=int(sys.argv[2])) as w:
    for lo in range(0, frames, chunk):
        t = np.arange(lo + 1, lo + chunk + 1, dtype=np.float64)
        w.add_points("/G", t, base[None] + t[:, None, None].astype(np.float32))
    w.commit({})
# VmHWM, not ru_maxrss: that one keeps the peak of the process forked before exec
print(next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")) // 1024)
"""


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="reads the peak from /proc")
def test_a_long_cache_is_written_in_bounded_memory(tmp_path):
    """1200 frames of 20000 vertices (275 MiB of points): the peak stays far below the cache's size
    with flushes of 16 MiB, and does not when everything is held until the commit."""
    def peak_mib(flush: int) -> int:
        run = subprocess.run([sys.executable, "-c", _LONG, str(tmp_path / f"c{flush}.usdc"), str(flush)],
                             capture_output=True, text=True, check=True)
        return int(run.stdout.split()[-1])

    streamed, held = peak_mib(16 * 2 ** 20), peak_mib(2 ** 40)
    assert held - streamed > 200 and streamed < 230, (held, streamed)
    print(f"peak RSS {streamed} MiB streamed, {held} MiB held")
    layer = Sdf.Layer.OpenAsAnonymous(str(tmp_path / f"c{16 * 2 ** 20}.usdc"))
    assert layer.GetNumTimeSamplesForPath("/G.points") == 1200
    assert np.array_equal(np.asarray(layer.QueryTimeSample("/G.points", 1200.0))[0],
                          np.asarray(Sdf.Layer.OpenAsAnonymous(str(tmp_path / f"c{2 ** 40}.usdc"))
                                     .QueryTimeSample("/G.points", 1200.0))[0])


def _bake_cli(tmp_path, *extra) -> list[str]:
    return ["bake", str(SAMPLE), "-o", str(tmp_path / "cache.usdc"), "--shot", str(tmp_path / "shot.usda"),
            "--frames", "1001:1003", "--tier", "skinning", *extra]


def _full_disk(which: str):
    real = Sdf.Layer.Save

    def save(layer, *args):
        if Path(layer.realPath).suffix == which:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(layer, *args)

    return save


@pytest.mark.parametrize("which, named", [(".usdc", "cache.usdc"), (".usda", "shot.usda")])
def test_a_full_disk_at_the_cache_or_the_shot_write_leaves_neither(tmp_path, monkeypatch, capsys, which, named):
    """The shot is saved before either is renamed: a full disk at its write leaves no cache."""
    monkeypatch.setattr(Sdf.Layer, "Save", _full_disk(which))
    assert main(_bake_cli(tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{named}: no space left on device" in err and "nothing was written" in err
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_at_a_rename_leaves_the_target_as_it_was(tmp_path, monkeypatch, capsys):
    (tmp_path / "cache.usdc").write_bytes(b"the old cache")

    def replace(src, dst):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(write.os, "replace", replace)
    assert main(_bake_cli(tmp_path, "--force")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cache.usdc: no space left on device" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.usdc"]
    assert (tmp_path / "cache.usdc").read_bytes() == b"the old cache"


def test_a_shot_that_cannot_be_renamed_takes_its_cache_back(tmp_path, monkeypatch, capsys):
    real, calls = os.replace, []

    def replace(src, dst):
        calls.append(dst)
        if str(dst).endswith(".usda"):
            raise OSError(errno.EACCES, os.strerror(errno.EACCES))
        real(src, dst)

    monkeypatch.setattr(write.os, "replace", replace)
    assert main(_bake_cli(tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "shot.usda: could not be written" in err and "cache.usdc removed again" in err
    assert [Path(c).name for c in calls] == ["cache.usdc", "shot.usda"]
    assert list(tmp_path.iterdir()) == []


def test_sigterm_between_the_cache_and_the_shot_rename_commits_both(tmp_path, monkeypatch, capsys):
    """SIGTERM waits for the renames: the pair is committed together, then the bake exits 143."""
    real = os.replace

    def replace(src, dst):
        real(src, dst)
        if str(dst).endswith("cache.usdc"):
            os.kill(os.getpid(), signal.SIGTERM)  # the cache is in place, the shot is not yet

    monkeypatch.setattr(write.os, "replace", replace)
    assert main(_bake_cli(tmp_path)) == 128 + signal.SIGTERM
    assert "interrupted (SIGTERM)" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.usdc", "shot.usda"]
    shot = Sdf.Layer.OpenAsAnonymous(str(tmp_path / "shot.usda"))
    assert shot.subLayerPaths[0] == "cache.usdc"
    assert Sdf.Layer.OpenAsAnonymous(str(tmp_path / "cache.usdc")).GetNumTimeSamplesForPath(f"{PRIM}.points") == 3


def test_sigterm_before_the_renames_commits_neither(tmp_path, monkeypatch, capsys):
    import cloth_usd.baking.run as run

    real = run.stage_shot_layer

    def stage_then_term(*args, **kwargs):
        staged = real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)  # both layers saved under temporary names
        return staged

    monkeypatch.setattr(run, "stage_shot_layer", stage_then_term)
    assert main(_bake_cli(tmp_path)) == 128 + signal.SIGTERM
    assert capsys.readouterr().err == ("cloth-usd: interrupted (SIGTERM); nothing partial was left "
                                       "(a cache and its shot are written whole, together, or not at all)\n")
    assert list(tmp_path.iterdir()) == []
