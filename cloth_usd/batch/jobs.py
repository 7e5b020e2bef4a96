"""Batch jobs: the :class:`Job` record and :func:`load_jobs`, which reads job files, stage
lists and globs and parses every frame range and tier once, here."""

from __future__ import annotations

import glob
import hashlib
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

from ..baking.plan import parse_tier
from ..core.files import read_config
from ..core.frame_range import FrameRange, parse_frames
from ..core.scene import Tier
from ..errors import ArgumentError

__all__ = ["Job", "load_jobs", "describe_jobs"]

_STAGE_SUFFIXES = {".usd", ".usda", ".usdc", ".usdz"}
_JOB_KEYS = ("name", "stage", "output", "frames", "garments", "tier", "models", "body_model", "joint_map", "strict")
_DEFAULT_KEYS = ("frames", "garments", "tier", "models", "body_model", "joint_map", "strict")
_FILE_KEYS = ("out_dir", "defaults", "jobs")


@dataclass(frozen=True)
class Job:
    """One bake of a batch."""

    name: str
    """Unique within the batch; names the job in the summary and report."""
    stage: Path
    """The USD stage to read."""
    output: Path
    """The cache layer to write."""
    frames: FrameRange | None = None
    """None for the stage's range."""
    garments: tuple[str, ...] | None = None
    """Garment prim paths, None for every enabled garment."""
    tier: Tier | None = None
    """Default tier for garments without ``cloth:tier`` (None: skinning)."""
    models: tuple[str, ...] | None = None
    """Model bundle search folders, None for the shipped ones."""
    body_model: str | None = None
    """SMPL-format file or folder, None for the embedded model."""
    joint_map: str | None = None
    """Joint map file for skeletons named in no known convention (``bake --joint-map``)."""
    strict: bool = False
    """A learned frame that is not a garment fails the job (``bake --strict``) instead of
    being replaced by a safer tier."""

    def bake_command(self) -> list[str]:
        """The ``cloth-usd bake`` command line that bakes this job by itself."""
        cmd = ["cloth-usd", "bake", str(self.stage), "-o", str(self.output), "--force"]
        if self.frames is not None:
            cmd += ["--frames", self.frames.spec()]
        for g in self.garments or ():
            cmd += ["--garment", g]
        if self.tier is not None:
            cmd += ["--tier", self.tier.value]
        if self.models:
            if len(self.models) > 1:  # `bake --models` takes one folder
                raise ArgumentError(f"job {self.name}: several model folders; `cloth-usd bake` takes one")
            cmd += ["--models", self.models[0]]
        if self.body_model:
            cmd += ["--body-model", self.body_model]
        if self.joint_map:
            cmd += ["--joint-map", self.joint_map]
        if self.strict:
            cmd += ["--strict"]
        return cmd


def describe_jobs(jobs: Iterable[Job]) -> list[str]:
    """One line per job for ``--dry-run``: its name and the ``cloth-usd bake`` command that runs it."""
    return [f"{job.name}: {shlex.join(job.bake_command())}" for job in jobs]


def _frames_token(frames: FrameRange | None) -> str:
    if frames is None:
        return "all"
    return f"{frames.start:.10g}-{frames.end:.10g}" + ("" if frames.step == 1.0 else f"x{frames.step:.10g}")


def _default_outputs(entries: list[dict]) -> None:
    """Give every entry without an output ``<out dir>/<base>.<tier>.<frames>[.g<hash>].usdc``.

    ``base`` is the stage's stem, prefixed with its parent folders' names only where
    two stages of the same stem would share an output folder.
    """
    todo = [e for e in entries if e.get("output") is None]
    depth = {id(e): 0 for e in todo}

    def base(e: dict) -> str:
        stage: Path = e["stage"]
        parents = stage.resolve().parent.parts[len(stage.resolve().parent.parts) - depth[id(e)]:]
        return "_".join([*parents, stage.stem]) if depth[id(e)] else stage.stem

    def name(e: dict) -> Path:
        folder = Path(e["out_dir"]) if e.get("out_dir") else e["stage"].parent
        token = f"{base(e)}.{(e.get('tier') or Tier.SKINNING).value}.{_frames_token(e.get('frames'))}"
        if e.get("garments"):
            token += ".g" + hashlib.sha256("\n".join(sorted(e["garments"])).encode()).hexdigest()[:8]
        return folder / f"{token}.usdc"

    for _ in range(64):
        seen: dict[Path, list[dict]] = {}
        for e in todo:
            seen.setdefault(name(e).resolve(), []).append(e)
        clashes = [group for group in seen.values() if len({g["stage"].resolve() for g in group}) > 1]
        if not clashes:
            break
        for group in clashes:
            for e in group:
                depth[id(e)] += 1
    for e in todo:
        e["output"] = name(e)


def _as_tuple(value: Any, key: str, where: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    if isinstance(value, str):
        return (value,)
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return tuple(value)
    raise ArgumentError(f"{where}: '{key}' must be a string or a list of strings, got {value!r}")


def _check_keys(table: dict, valid: Sequence[str], where: str) -> None:
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise ArgumentError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(valid)})")


def _entries_from_file(path: Path) -> tuple[list[dict], dict, str | None]:
    """Raw job tables, file defaults and out_dir of a .toml/.json/.txt job file."""
    where = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ArgumentError(f"{path}: cannot read the job file ({exc.strerror})") from None
    if path.suffix == ".txt":
        lines = (line.split("#", 1)[0].strip() for line in text.splitlines())
        return [{"stage": line} for line in lines if line], {}, None
    data = read_config(path, "the job file", text=text)
    if isinstance(data, list):
        data = {"jobs": data}
    if not isinstance(data, dict):
        raise ArgumentError(f"{path}: expected a table with 'jobs' (a list of tables) or a list of jobs")
    _check_keys(data, _FILE_KEYS, where)
    jobs = data.get("jobs")
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise ArgumentError(f"{path}: 'jobs' must be a list of tables, each with at least a 'stage'")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise ArgumentError(f"{path}: 'defaults' must be a table")
    _check_keys(defaults, _DEFAULT_KEYS, f"{where} [defaults]")
    for i, job in enumerate(jobs):
        _check_keys(job, _JOB_KEYS, f"{where} job {i + 1}")
    out_dir = data.get("out_dir")
    if out_dir is not None and not isinstance(out_dir, str):
        raise ArgumentError(f"{path}: 'out_dir' must be a string")
    return [dict(j) for j in jobs], dict(defaults), out_dir


def _expand(spec: str) -> list[Path]:
    """A stage path, or the stages a glob matches (sorted)."""
    path = Path(spec)
    if path.exists():
        if path.suffix not in _STAGE_SUFFIXES:
            raise ArgumentError(f"{spec}: not a job file (.toml, .json, .txt) or a USD stage "
                                f"({', '.join(sorted(_STAGE_SUFFIXES))})")
        return [path]
    if glob.has_magic(spec):
        found = sorted(Path(p) for p in glob.glob(spec, recursive=True) if Path(p).suffix in _STAGE_SUFFIXES)
        if not found:
            raise ArgumentError(f"{spec}: the pattern matches no USD stage")
        return found
    raise ArgumentError(f"{spec}: no such file; pass a job file (.toml, .json, .txt), stages or a glob")


def _typed(value: Any, key: str, label: str) -> Any:
    """A job table's ``frames`` or ``tier`` parsed (an error names the job); the others as they are."""
    try:
        if key == "frames" and value is not None and not isinstance(value, FrameRange):
            return parse_frames(str(value))
        if key == "tier":
            return parse_tier(value)
    except ArgumentError as exc:
        raise ArgumentError(f"{label}: {exc}") from None
    return value


def load_jobs(sources: str | Path | Sequence[str | Path], *, out_dir: str | Path | None = None,
              frames: FrameRange | str | None = None, garments: Sequence[str] | None = None,
              tier: Tier | str | None = None, models: str | Sequence[str] | None = None,
              body_model: str | None = None, joint_map: str | None = None, strict: bool | None = None) -> list[Job]:
    """Read jobs from job files, stage paths and globs.

    A TOML or JSON job file holds ``jobs`` (a list of tables with ``stage`` and
    optionally ``name``, ``output``, ``frames``, ``garments``, ``tier``, ``models``,
    ``body_model``, ``joint_map``, ``strict``), optional ``defaults`` (the same keys but ``name``, ``stage``,
    ``output``) and ``out_dir``; relative paths are relative to the file. A ``.txt``
    lists stage paths, one a line (``#`` comments). Anything else is a stage or a glob.

    Keyword arguments are the defaults of jobs that give none (a job file's own
    ``defaults`` and ``out_dir`` come first). A job without ``output`` gets
    ``<out_dir>/<stage stem>.<tier>.<frames>.usdc`` (the stage's folder without an
    out_dir; a ``.g<hash>`` part when it names garments).

    Raises:
        ArgumentError: an unreadable or malformed job file, a bad frame range or tier,
            a pattern that matches nothing, two jobs with one output or one name.
    """
    if isinstance(sources, (str, Path)):
        sources = [sources]
    cli = {"frames": parse_frames(frames) if isinstance(frames, str) else frames,
           "garments": _as_tuple(garments, "garments", "--garment"), "tier": parse_tier(tier),
           "models": _as_tuple(models, "models", "--models"), "body_model": body_model, "joint_map": joint_map,
           "strict": strict}
    entries: list[dict] = []
    for spec in sources:
        path = Path(spec)
        if path.suffix in (".toml", ".json", ".txt") and path.is_file():
            raw, defaults, file_out = _entries_from_file(path)
            base = path.parent
            where = str(path)
        else:
            raw, defaults, file_out, base, where = ([{"stage": str(p)} for p in _expand(str(spec))], {},
                                                    None, Path("."), str(spec))
        for i, job in enumerate(raw):
            label = f"{where} job {i + 1}" if len(raw) > 1 else where
            if not isinstance(job.get("stage"), str):
                raise ArgumentError(f"{label}: needs 'stage', the path of a USD stage")
            e: dict[str, Any] = {"label": label}
            for key in _DEFAULT_KEYS:
                value = job.get(key, defaults.get(key))
                if key in ("garments", "models"):
                    value = _as_tuple(value, key, label)
                    if key == "models" and value is not None:
                        value = tuple(str(base / m) for m in value)
                elif key in ("body_model", "joint_map") and value is not None:
                    value = str(base / value)
                elif key == "strict" and value is not None and not isinstance(value, bool):
                    raise ArgumentError(f"{label}: strict must be true or false, got {value!r}")
                e[key] = _typed(value, key, label) if value is not None else cli[key]
            e["stage"] = base / job["stage"]
            e["output"] = base / job["output"] if job.get("output") else None
            e["name"] = job.get("name")
            e["out_dir"] = str(base / file_out) if file_out else (str(out_dir) if out_dir else None)
            entries.append(e)
    if not entries:
        raise ArgumentError(f"{', '.join(map(str, sources)) or 'no sources'}: no jobs")
    _default_outputs(entries)
    jobs, outputs, names = [], {}, set()
    for e in entries:
        key = Path(e["output"]).resolve()
        if key in outputs:
            raise ArgumentError(f"{e['label']}: writes {e['output']}, as {outputs[key]} does; give each job "
                                "its own output")
        name = e["name"] or Path(e["output"]).name.removesuffix(Path(e["output"]).suffix)
        if name in names:
            raise ArgumentError(f"{e['label']}: job name '{name}' is used twice; give each job its own name")
        names.add(name)
        outputs[key] = e["label"]
        jobs.append(Job(name=name, stage=Path(e["stage"]), output=Path(e["output"]), frames=e["frames"],
                        garments=e["garments"], tier=e["tier"], models=e["models"], body_model=e["body_model"],
                        joint_map=e["joint_map"], strict=bool(e["strict"])))
    return jobs
