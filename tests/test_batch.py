"""``cloth-usd batch``: job files, a 24-job batch with workers killed mid-job (local processes
and Ray), skipping what is up to date, frame chunks stitched into one cache, failures alone."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd

from cloth_usd.baking import bake
from cloth_usd.batch import KILL_HOOK_ENV, Job, JobStatus, load_jobs, run_batch
from cloth_usd.cli import main
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.frame_range import FrameRange
from cloth_usd.core.scene import Tier
from cloth_usd.datagen import walk_cycle
from cloth_usd.errors import ArgumentError
from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

FRAMES = 12
#: (file name, up axis, metres per unit, betas, garments)
STAGES = [("shot_a.usda", "Y", 1.0, [0.5, -0.3], 1), ("shot_b.usda", "Z", 0.01, [-1.0, 1.0], 1),
          ("shot_c.usdc", "Y", 0.001, [0.0], 1), ("shot_d.usda", "Y", 1.0, [1.5, 0.5], 2)]
RANGES = ["1:3", "4:6", "7:9", "10:12", "1:12", "1:11:2"]
CHUNK = 5  # frames per chunk: the 1:12 and 1:11:2 jobs are stitched from chunks


def tube(joints: np.ndarray, around: int = 16, rows: int = 12, shift=(0.0, 0.0, 0.0)):
    """A ~200-vertex tube around the torso, from below the pelvis to the chest: (N, 3) m, (M, 3)."""
    angles = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    heights = np.linspace(joints[0, 1] - 0.08, joints[9, 1], rows)
    ring = np.stack([0.19 * np.cos(angles), np.zeros(around), 0.14 * np.sin(angles)], axis=1)
    points = np.concatenate([ring + [joints[0, 0], h, joints[0, 2]] for h in heights]) + shift
    faces = []
    for r in range(rows - 1):
        for a in range(around):
            p, q = r * around + a, r * around + (a + 1) % around
            faces += [[p, q, q + around], [p, q + around, p + around]]
    return points, np.array(faces)


def author(path: Path, up: str, mpu: float, betas, garments: int) -> Path:
    body = load_body_model()
    betas = np.pad(np.asarray(betas, dtype=np.float64), (0, 10 - len(betas)))
    _, joints = shape_body(body, betas)
    poses, root = walk_cycle(FRAMES)
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu, start=1, end=FRAMES)
    skel = author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=betas, poses=poses,
                           root_positions=joints[0] + root, times=np.arange(1.0, FRAMES + 1))
    for g in range(garments):
        points, faces = tube(joints, shift=(0.0, 0.0, 0.01 * g))
        author_garment(stage, f"/Char/Tube{g}", points=points, faces=faces, body_path=skel)
    stage.GetRootLayer().Save()
    return path


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> Path:
    """Four tiny stages and a TOML job file of 24 jobs (4 stages x 6 frame ranges)."""
    root = tmp_path_factory.mktemp("shots")
    lines = ['out_dir = "out"', "[defaults]", 'tier = "skinning"', ""]
    for name, up, mpu, betas, garments in STAGES:
        author(root / name, up, mpu, betas, garments)
        for frames in RANGES:
            lines += ["[[jobs]]", f'stage = "{name}"', f'frames = "{frames}"', ""]
    (root / "jobs.toml").write_text("\n".join(lines))
    return root


def _names(jobs) -> dict[str, Job]:
    return {(j.stage.name, j.frames.spec()): j for j in jobs}


def _check_outputs(jobs, out: Path) -> None:
    """Every output opens, holds points for exactly its frames, finite; nothing else is left."""
    for job in jobs:
        layer = Sdf.Layer.OpenAsAnonymous(str(job.output))
        garments = 2 if job.stage.name == "shot_d.usda" else 1
        lo, hi, *step = map(int, job.frames.spec().split(":"))
        want = list(range(lo, hi + 1, step[0] if step else 1))
        for g in range(garments):
            attr = f"/Char/Tube{g}.points"
            assert layer.ListTimeSamplesForPath(attr) == want, (job.name, attr)
            pts = np.stack([np.array(layer.QueryTimeSample(attr, t)) for t in want])
            assert pts.shape == (len(want), 192, 3) and np.isfinite(pts).all()
        prov = layer.customLayerData["cloth_usd"]
        assert len(prov["inputs_sha256"]) == 64 and prov["frame_range"].startswith(f"{lo}:{hi}")
        assert Usd.Stage.Open(str(job.output)) is not None
    left = sorted(p.name for p in out.iterdir())
    assert left == sorted(j.output.name for j in jobs), "temporary files or chunk folders were left"


def _kill_plan(folder: Path, jobs, *, few: bool = False) -> dict[str, str]:
    """Marker files that kill workers mid-job: at task start and mid-write, in every task kind
    (``few``: one kill each of a bake, a chunk and a stitch; a new Ray worker is slow to start)."""
    by = _names(jobs)
    plan = {
        by["shot_a.usda", "1:3"].name + ".plan": "start",
        by["shot_a.usda", "4:6"].name + ".bake": "write",   # 3 frames <= CHUNK: a plain bake after the plan
        by["shot_b.usda", "7:9"].name + ".bake": "start",
        by["shot_c.usdc", "10:12"].name + ".bake": "write",
        by["shot_b.usda", "1:12"].name + ".chunk": "write",  # one of its chunks, mid-write
        by["shot_d.usda", "1:12"].name + ".stitch": "start",
        by["shot_c.usdc", "1:11:2"].name + ".chunk": "start",
    }
    if few:
        plan = {k: v for k, v in plan.items() if k.startswith(by["shot_a.usda", "4:6"].name)
                or k.endswith((".chunk", ".stitch")) and "shot_c" not in k}
    folder.mkdir(exist_ok=True)
    for name, mode in plan.items():
        (folder / f"{name}.kill").write_text(mode)
    return plan


def _run_killed_batch(shots: Path, tmp_path: Path, monkeypatch, executor: str):
    jobs = load_jobs(shots / "jobs.toml")
    jobs = [Job(**{**j.__dict__, "output": tmp_path / j.output.name}) for j in jobs]
    assert len(jobs) == 24 and len({j.output for j in jobs}) == 24
    kills = _kill_plan(tmp_path / "kill", jobs, few=executor == "ray")
    monkeypatch.setenv(KILL_HOOK_ENV, str(tmp_path / "kill"))
    began = time.perf_counter()
    report = run_batch(jobs, executor=executor, workers=2, retries=2, chunk_frames=CHUNK)
    seconds = time.perf_counter() - began
    assert [j.error for j in report.failed] == []
    assert report.count(JobStatus.DONE) == 24
    assert list((tmp_path / "kill").iterdir()) == [], "every kill marker was taken"
    return jobs, report, kills, seconds


def test_batch_survives_killed_workers_and_reruns_skip(shots, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    jobs, report, kills, seconds = _run_killed_batch(shots, out, monkeypatch, "local")
    (out / "kill").rmdir()
    _check_outputs(jobs, out)
    by = {j.name: j for j in report.jobs}
    for marker in kills:  # each killed task ran again
        job = by[marker.rsplit(".", 1)[0]]
        tasks = 1 + (job.chunks + 1 if job.chunks else 1)  # plan + (chunks and stitch, or one bake)
        assert job.attempts == tasks + 1, (marker, job.attempts, tasks)
    assert by[_names(jobs)["shot_b.usda", "1:12"].name].chunks == 3
    # A chunked job's cache is the one a whole bake writes.
    whole = _names(jobs)["shot_d.usda", "1:12"]
    bake(whole.stage, tmp_path / "whole.usdc", frames="1:12")
    a, b = Sdf.Layer.OpenAsAnonymous(str(whole.output)), Sdf.Layer.OpenAsAnonymous(str(tmp_path / "whole.usdc"))
    assert a.customLayerData == b.customLayerData
    for t in range(1, 13):
        assert np.array_equal(np.array(a.QueryTimeSample("/Char/Tube1.points", t)),
                              np.array(b.QueryTimeSample("/Char/Tube1.points", t)))

    # Run again: everything is up to date, except a truncated output and a changed job.
    monkeypatch.delenv(KILL_HOOK_ENV)
    broken = _names(jobs)["shot_a.usda", "7:9"]
    broken.output.write_bytes(broken.output.read_bytes()[:200])
    changed = _names(jobs)["shot_b.usda", "4:6"]
    mtimes = {j.output: j.output.stat().st_mtime_ns for j in jobs}
    again = run_batch(jobs, workers=2, chunk_frames=CHUNK)
    status = {j.name: j.status for j in again.jobs}
    assert status.pop(broken.name) is JobStatus.DONE
    assert set(status.values()) == {JobStatus.SKIPPED}
    assert all(j.output.stat().st_mtime_ns == mtimes[j.output] for j in jobs if j is not broken)
    forced = run_batch([Job(**{**changed.__dict__, "tier": Tier.SKINNING, "frames": FrameRange(4, 7)})], workers=1)
    assert forced.jobs[0].status is JobStatus.DONE  # same output path, other frames: not up to date
    print(f"24 jobs, 2 local workers, {len(kills)} workers killed: {seconds:.1f} s; re-run {again.seconds:.1f} s")


def test_ray_runs_the_same_batch_with_killed_workers(shots, tmp_path, monkeypatch):
    pytest.importorskip("ray", reason="the Ray executor needs ray (pip install 'cloth-usd[ray]')")
    out = tmp_path / "out"
    out.mkdir()
    jobs, report, kills, seconds = _run_killed_batch(shots, out, monkeypatch, "ray")
    (out / "kill").rmdir()
    _check_outputs(jobs, out)
    print(f"24 jobs on a local Ray (2 CPUs), {len(kills)} workers killed: {seconds:.1f} s")


def test_a_task_killed_on_every_attempt_fails_its_job_alone_and_leaves_no_layer(shots, tmp_path, monkeypatch):
    jobs = [Job(name=f"j{i}", stage=shots / "shot_a.usda", output=tmp_path / f"j{i}.usdc", frames=FrameRange(i, i + 1))
            for i in (1, 2, 3)]
    (tmp_path / "kill").mkdir()
    (tmp_path / "kill" / "j2.bake.kill").write_text("write")
    monkeypatch.setenv(KILL_HOOK_ENV, str(tmp_path / "kill"))
    report = run_batch(jobs, workers=2, retries=0)
    status = {j.name: (j.status, j.error) for j in report.jobs}
    assert status["j1"] == (JobStatus.DONE, None) and status["j3"] == (JobStatus.DONE, None)
    assert status["j2"][0] is JobStatus.FAILED
    assert status["j2"][1] == "bake task: worker killed by SIGKILL (1 attempts)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["j1.usdc", "j3.usdc", "kill"]


def test_cli_batch_reports_a_broken_job_and_exits_1(shots, tmp_path, capsys):
    (tmp_path / "broken.usda").write_text("#usda 1.0\n(\n")
    jobs = {"out_dir": "out", "defaults": {"frames": "1:2"},
            "jobs": [{"stage": str(shots / "shot_a.usda"), "name": "good"},
                     {"stage": "broken.usda", "name": "bad"},
                     {"stage": str(shots / "shot_b.usda"), "garments": ["/Char/Nope"], "name": "nogarment"}]}
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    (tmp_path / "out").mkdir()
    rc = main(["batch", str(tmp_path / "jobs.json"), "--workers", "2", "--report", str(tmp_path / "r.json")])
    out = capsys.readouterr().out
    assert rc == 1
    assert "3 jobs: 1 done, 0 skipped (up to date), 2 failed" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["counts"] == {"done": 1, "skipped": 0, "failed": 2}
    by = {j["name"]: j for j in report["jobs"]}
    assert "broken.usda" in by["bad"]["error"] and "\n" not in by["bad"]["error"]
    assert by["nogarment"]["error"].startswith("--garment /Char/Nope: no garment at this prim path")
    assert by["good"]["frames"] == 2 and by["good"]["garments"][0]["vertices"] == 192
    assert [p.name for p in (tmp_path / "out").iterdir()] == [Path(by["good"]["output"]).name]


def test_load_jobs_from_a_txt_a_glob_and_a_toml(shots, tmp_path):
    (tmp_path / "list.txt").write_text(f"# shots\n{shots / 'shot_a.usda'}\n\n{shots / 'shot_b.usda'}  # b\n")
    jobs = load_jobs(tmp_path / "list.txt", out_dir=tmp_path, frames="1:4")
    assert [j.output.name for j in jobs] == ["shot_a.skinning.1-4.usdc", "shot_b.skinning.1-4.usdc"]
    jobs = load_jobs(str(shots / "shot_*.usd*"), tier="skinning", garments=["/Char/Tube0"])
    assert [j.stage.name for j in jobs] == ["shot_a.usda", "shot_b.usda", "shot_c.usdc", "shot_d.usda"]
    assert all(j.output.parent == shots and j.frames is None for j in jobs)
    assert jobs[0].output.name.startswith("shot_a.skinning.all.g")  # garments named: a hash part
    # Same stem in two folders, one output folder: the folder name tells them apart.
    for sub in ("x", "y"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "scene.usda").write_text("#usda 1.0\n")
    jobs = load_jobs(str(tmp_path / "*" / "scene.usda"), out_dir=tmp_path / "o")
    assert [j.output.name for j in jobs] == ["x_scene.skinning.all.usdc", "y_scene.skinning.all.usdc"]
    assert jobs[0].bake_command()[:5] == ["cloth-usd", "bake", str(tmp_path / "x" / "scene.usda"), "-o",
                                          str(tmp_path / "o" / "x_scene.skinning.all.usdc")]
    toml = load_jobs(shots / "jobs.toml")
    assert len(toml) == 24 and toml[5].frames == FrameRange(1, 11, 2)
    assert toml[5].output.name == "shot_a.skinning.1-11x2.usdc"
    assert toml[0].output.parent == shots / "out" and toml[0].tier is Tier.SKINNING


@pytest.mark.parametrize("text, message", [
    ('[[jobs]]\nstage = "a.usda"\nframe = "1:2"\n', "unknown key(s) frame"),
    ('[[jobs]]\nstage = "a.usda"\nframes = "2:1"\n', "empty range"),
    ('[[jobs]]\nstage = "a.usda"\ntier = "fancy"\n', "unknown tier"),
    ('[[jobs]]\nstage = "a.usda"\n[[jobs]]\nstage = "a.usda"\n', "give each job its own output"),
    ('[[jobs]]\nframes = "1:2"\n', "needs 'stage'"),
    ('jobs = 3\n', "'jobs' must be a list"),
    ('[[jobs\n', "not valid TOML"),
])
def test_bad_job_files_are_one_clear_error(tmp_path, text, message):
    (tmp_path / "jobs.toml").write_text(text)
    with pytest.raises(ArgumentError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_jobs(tmp_path / "jobs.toml")


def test_cli_dry_run_lists_bake_commands(shots, capsys):
    assert main(["batch", str(shots / "shot_a.usda"), "--frames", "1:4", "--dry-run"]) == 0
    out = capsys.readouterr().out.strip()
    assert out == (f"shot_a.skinning.1-4: cloth-usd bake {shots / 'shot_a.usda'} -o "
                   f"{shots / 'shot_a.skinning.1-4.usdc'} --force --frames 1:4")
    assert main(["batch", str(shots / "nothing*.usda")]) == 2
    assert not os.path.exists(shots / "shot_a.skinning.1-4.usdc")


def test_a_worker_cache_loads_each_model_once_and_binds_each_garment_once(shots, tmp_path, monkeypatch):
    """Three frame chunks of one job in one worker: one body model load, one bundle load
    (and sha256 check), one binding per garment."""
    from test_extremes import fake_bundle

    import cloth_usd.baking.cache as baking_cache
    import cloth_usd.baking.garment as baking_garment
    import cloth_usd.runtime.bundle as bundles
    from cloth_usd.baking import ModelCache

    calls = {"body": 0, "bundle": 0, "bind": 0}

    def counting(name, fn):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return fn(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(baking_cache, "load_body_model", counting("body", baking_cache.load_body_model))
    monkeypatch.setattr(bundles, "load_bundle", counting("bundle", bundles.load_bundle))
    monkeypatch.setattr(baking_garment, "bind_worn", counting("bind", baking_garment.bind_worn))
    models = fake_bundle(tmp_path / "fake", 0.005)
    cache = ModelCache()
    for i, frames in enumerate(["1:4", "5:8", "9:12"]):
        bake(shots / "shot_d.usda", tmp_path / f"{i}.usdc", frames=frames, tier="coarse", models=models, cache=cache)
    assert calls == {"body": 1, "bundle": 1, "bind": 2}  # shot_d wears two garments


def test_ray_executor_without_ray_says_what_to_install(shots, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    jobs = load_jobs(shots / "shot_a.usda", frames="1:2")
    with pytest.raises(ArgumentError, match=r"pip install 'cloth-usd\[ray\]'"):
        run_batch(jobs, executor="ray")


@pytest.mark.parametrize("error, retry, message", [
    ("write", True, "out.usdc: USD could not save the layer"),  # a full disk, a share gone: worth another try
    ("argument", False, "out.usdc: </Shirt> has non-finite points"),
    ("bug", False, "ValueError: a bug"),
])
def test_a_task_says_whether_its_error_is_worth_a_retry(tmp_path, monkeypatch, error, retry, message):
    import cloth_usd.batch.tasks
    from cloth_usd.batch.tasks import Kind, Outcome, Task, run_task
    from cloth_usd.errors import OutputWriteError

    raised = {"write": OutputWriteError("out.usdc: USD could not save the layer"),
              "argument": ArgumentError("out.usdc: </Shirt> has non-finite points at time code 2"),
              "bug": ValueError("a bug")}[error]

    def failing_bake(*args, **kwargs):
        raise raised

    monkeypatch.setattr(cloth_usd.batch.tasks, "bake", failing_bake)
    job = Job(name="j", stage=tmp_path / "s.usda", output=tmp_path / "out.usdc")
    out = run_task(Task(Kind.BAKE, job, job.output))
    assert (out.status, out.retry) == (Outcome.ERROR, retry)
    assert out.error.startswith(message)


def test_jobs_carry_a_joint_map_and_strict_to_their_bakes(shots, tmp_path, capsys):
    from test_extremes import fake_bundle

    (tmp_path / "map.json").write_text(json.dumps({"Hips": "pelvis"}))
    jobs = {"defaults": {"frames": "1:2", "tier": "coarse"},
            "jobs": [{"stage": str(shots / "shot_a.usda"), "name": "lenient", "output": "a.usdc"},
                     {"stage": str(shots / "shot_a.usda"), "name": "strict", "output": "b.usdc", "strict": True,
                      "joint_map": "map.json"}]}
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    loaded = {j.name: j for j in load_jobs(tmp_path / "jobs.json")}
    assert (loaded["lenient"].strict, loaded["lenient"].joint_map) == (False, None)
    assert loaded["strict"].strict and loaded["strict"].joint_map == str(tmp_path / "map.json")
    assert loaded["strict"].bake_command()[-3:] == ["--joint-map", str(tmp_path / "map.json"), "--strict"]
    # --strict on the command line is the default for the jobs that do not say
    assert {j.name: j.strict for j in load_jobs(tmp_path / "jobs.json", strict=True)} == {"lenient": True,
                                                                                          "strict": True}
    wild = fake_bundle(tmp_path / "wild", 5.0)  # every learned frame is thrown 5 m off: not a garment
    rc = main(["batch", str(tmp_path / "jobs.json"), "--models", str(wild), "--workers", "1",
               "--report", str(tmp_path / "r.json")])
    assert rc == 1
    by = {j["name"]: j for j in json.loads((tmp_path / "r.json").read_text())["jobs"]}
    assert by["lenient"]["status"] == "done" and by["strict"]["status"] == "failed"
    assert "is not a garment" in by["strict"]["error"] and "--strict" in by["strict"]["error"]
    assert not (tmp_path / "b.usdc").exists()
    (tmp_path / "bad.toml").write_text('[[jobs]]\nstage = "a.usda"\nstrict = "yes"\n')
    with pytest.raises(ArgumentError, match="strict must be true or false"):
        load_jobs(tmp_path / "bad.toml")


def test_a_chunked_batch_makes_its_missing_out_dir(shots, tmp_path):
    """Chunk folders (and plain bakes) in an out_dir that does not exist yet: the batch makes it."""
    out = tmp_path / "new" / "deeper"
    jobs = [Job(name="long", stage=shots / "shot_a.usda", output=out / "long.usdc", frames=FrameRange(1, 12)),
            Job(name="short", stage=shots / "shot_a.usda", output=out / "short.usdc", frames=FrameRange(1, 3))]
    report = run_batch(jobs, workers=2, chunk_frames=CHUNK)
    assert [(j.status, j.error) for j in report.jobs] == [(JobStatus.DONE, None)] * 2
    assert sorted(p.name for p in out.iterdir()) == ["long.usdc", "short.usdc"]
    assert Sdf.Layer.OpenAsAnonymous(str(out / "long.usdc")).GetNumTimeSamplesForPath("/Char/Tube0.points") == 12


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.add(child)
            todo.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="finds the workers in /proc")
def test_workers_of_a_killed_batch_exit_quietly_and_leave_no_temporary_file(tmp_path):
    import signal
    import subprocess

    sample = Path(__file__).resolve().parents[1] / "samples" / "walk_tshirt" / "scene.usda"
    out = tmp_path / "out"
    out.mkdir()
    jobs = {"jobs": [{"stage": str(sample), "output": str(out / f"{i}.usdc"), "frames": "1001:9000",
                      "tier": "skinning"} for i in range(2)]}
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    with open(tmp_path / "stderr", "wb") as err:
        parent = subprocess.Popen([sys.executable, "-c", "import sys; from cloth_usd.cli import main; "
                                   "sys.exit(main(sys.argv[1:]))", "batch", str(tmp_path / "jobs.json"),
                                   "--workers", "2"], stderr=err, stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while len(list(out.glob(".*.tmp.usdc"))) < 2:  # both workers are writing their caches
            assert parent.poll() is None and time.monotonic() < deadline, (tmp_path / "stderr").read_text()
            time.sleep(0.05)
        below = _descendants(parent.pid)
        assert len(below) >= 3  # the forkserver and two workers
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 30
        while any(_alive(p) for p in below) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in below), "workers outlived their batch"
    finally:
        if parent.poll() is None:
            parent.kill()
    text = (tmp_path / "stderr").read_text()
    assert "Traceback" not in text and "Error" not in text, text
    assert list(out.iterdir()) == []  # each worker removed its temporary file on the way out
