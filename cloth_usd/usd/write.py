"""Writing the point-cache layer and the shot layer (docs/scene_contract.md, "The output").

The cache layer holds only ``over`` specs at garment prim paths with time-sampled
``points`` and ``extent``. Layers are written to a temporary file beside the target and
renamed into place, so a crash never leaves a partial file (a process killed mid-write
leaves only its temporary file, which :func:`remove_stale_temps` clears, as every bake does
for its own targets; the CLI turns SIGTERM into an exception, so the writer removes its
temporary file itself); an existing
file is only replaced with ``force``; a layer the source stage uses is never a target.
Frame-chunk caches of one bake are joined into one layer by :func:`stitch_layers`.

Long caches are written in bounded memory: :class:`CacheLayerWriter` saves its temporary
``.usdc`` whenever :data:`FLUSH_BYTES` of new samples are held (a crate file saved again
appends to itself and then reads the saved samples from disk), so a bake holds one flush of
points at a time, whatever its length. A ``.usda`` target is staged the same way in a
temporary ``.usdc`` and exported to text at the end. A cache and its shot layer are both saved
under temporary names before either is renamed (:func:`commit_layers`), and SIGTERM and SIGINT
wait for the renames, so the pair is committed together or not at all.
"""

from __future__ import annotations

import errno
import logging
import os
import re
import signal
import tempfile
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np
from pxr import Sdf, Tf, Vt

from ..core.scene import StageInfo
from ..errors import ArgumentError, OutputExistsError, OutputWriteError

__all__ = ["FLUSH_BYTES", "CacheLayerWriter", "CacheInfo", "StagedLayer", "commit_layers", "stage_shot_layer",
           "write_shot_layer", "check_output_path", "cache_layer_info", "stitch_layers", "remove_stale_temps"]

log = logging.getLogger(__name__)

_FORMATS = {".usdc", ".usda", ".usd"}

#: New time-sample bytes a :class:`CacheLayerWriter` holds before it saves them to its
#: temporary file (and :func:`stitch_layers` before it saves what it copied). A cache under
#: this size is saved once, at its commit.
FLUSH_BYTES = 64 * 2 ** 20


def check_output_path(path: str | Path, *, force: bool, protected: Iterable[str] = ()) -> Path:
    """Validate an output path before any work is done.

    Args:
        protected: real paths of the source stage's layers; never writable.
    Raises:
        ArgumentError: unknown extension, missing folder, or a source layer as target.
        OutputExistsError: the file exists and ``force`` is false.
    """
    path = Path(path)
    if path.suffix not in _FORMATS:
        raise ArgumentError(f"{path}: output must end in .usdc, .usda or .usd")
    if not path.parent.is_dir():
        what = "is not a folder" if path.parent.exists() else "does not exist"
        raise ArgumentError(f"{path}: folder '{path.parent}' {what}")
    if path.is_dir():
        raise ArgumentError(f"{path}: is a folder; name a layer file to write")
    real = os.path.realpath(path)
    if any(real == os.path.realpath(p) for p in protected if p):
        raise ArgumentError(f"{path}: is a layer of the source stage; cloth_usd never writes into "
                            "source layers, choose another output path")
    if path.exists() and not force:
        raise OutputExistsError(f"{path}: already exists; pass --force to replace it")
    return path


def _temp_path(path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    os.unlink(tmp)  # Sdf creates the file itself
    return Path(tmp)


def remove_stale_temps(path: str | Path) -> list[Path]:
    """Remove the temporary files that writes of ``path`` left behind when killed.

    Only call this while no other process is writing ``path``: a live write's
    temporary file looks the same.

    Returns:
        The files removed.
    """
    path = Path(path)
    # tempfile.mkstemp puts 8 random characters between prefix and suffix; a .usda target
    # is staged in the same name plus .usdc.
    pattern = re.compile(rf"^\.{re.escape(path.stem)}\.[A-Za-z0-9_]{{8}}\.tmp{re.escape(path.suffix)}(\.usdc)?$")
    removed = []
    if path.parent.is_dir():
        for entry in path.parent.iterdir():
            if pattern.match(entry.name) and entry.is_file():
                entry.unlink(missing_ok=True)
                removed.append(entry)
    if removed:
        log.info("removed %d stale temporary file(s) of %s", len(removed), path)
    return removed


def _no_space(text: str, exc: BaseException | None = None) -> bool:
    return getattr(exc, "errno", None) == errno.ENOSPC or "No space left on device" in text


def _write_error(path: Path, exc: BaseException, tmp: Path | None = None) -> OutputWriteError:
    """The one-line :class:`OutputWriteError` of a failed save or rename of ``path``."""
    text = str(exc)
    where = f" (writing {tmp.name})" if tmp is not None else ""
    if _no_space(text, exc):
        return OutputWriteError(f"{path}: no space left on device{where}; free some space in '{path.parent}' "
                                "and run again; nothing was written")
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    reason = getattr(exc, "strerror", None) or (lines[-1].rsplit(" : ", 1)[-1].strip("'") if lines else "")
    return OutputWriteError(f"{path}: could not be written{where}: {reason or type(exc).__name__}; check the "
                            "folder's permissions and free space; nothing was written")


def _save(layer: Sdf.Layer, tmp: Path, path: Path) -> None:
    """Save ``layer`` (at ``tmp``), or OutputWriteError naming ``path``."""
    try:
        saved = layer.Save()
    except (Tf.ErrorException, OSError) as exc:
        raise _write_error(path, exc, tmp) from None
    if not saved:
        raise OutputWriteError(f"{path}: USD could not save the layer (to {tmp}); check the folder's "
                               "permissions and free space; nothing was written")


@dataclass(frozen=True)
class StagedLayer:
    """A layer saved under a temporary name beside its target, waiting for :func:`commit_layers`."""

    tmp: Path
    path: Path
    force: bool

    def discard(self) -> None:
        self.tmp.unlink(missing_ok=True)


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """SIGTERM and SIGINT wait until the block is left, then are delivered (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum))
                for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in caught:
            signal.raise_signal(s)  # now to the handler that was there


def commit_layers(staged: Sequence[StagedLayer]) -> None:
    """Rename saved temporary layers into place, all or none.

    Every target is checked first (one that appeared meanwhile without ``force`` is an
    OutputExistsError and nothing is renamed); SIGTERM and SIGINT wait for the renames.
    A rename that fails removes the targets renamed before it, so a cache is never left
    without its shot layer. On any error every temporary file is removed.
    """
    try:
        for s in staged:
            if s.path.exists() and not s.force:
                raise OutputExistsError(f"{s.path}: appeared while baking; pass --force to replace it")
        done: list[StagedLayer] = []
        with _signals_deferred():
            try:
                for s in staged:
                    os.replace(s.tmp, s.path)
                    done.append(s)
            except OSError as exc:
                for d in done:
                    d.path.unlink(missing_ok=True)
                failed = staged[len(done)]
                undone = (f"; {', '.join(str(d.path) for d in done)} removed again (written with it)"
                          if done else "")
                raise OutputWriteError(f"{_write_error(failed.path, exc, failed.tmp)}{undone}") from None
    finally:
        for s in staged:
            s.discard()


def _commit(layer: Sdf.Layer, tmp: Path, path: Path, force: bool) -> None:
    try:
        _save(layer, tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    commit_layers([StagedLayer(tmp, path, force)])


def _copy_stage_metadata(layer: Sdf.Layer, stage: StageInfo, start: float, end: float) -> None:
    layer.timeCodesPerSecond = stage.time_codes_per_second
    layer.framesPerSecond = stage.frames_per_second
    layer.startTimeCode = float(start)
    layer.endTimeCode = float(end)
    layer.pseudoRoot.SetInfo("upAxis", stage.up_axis)
    layer.pseudoRoot.SetInfo("metersPerUnit", float(stage.meters_per_unit))


class CacheLayerWriter:
    """Writes a point-cache layer frame chunk by frame chunk, then commits it atomically.

    Use as a context manager: leaving the block by an exception removes the temporary
    file and leaves any existing output untouched::

        with CacheLayerWriter(path, stage=info, start=1, end=48, force=False) as w:
            w.add_points("/Char/Shirt", times, points)
            w.commit(provenance)
    """

    def __init__(self, path: str | Path, *, stage: StageInfo, start: float, end: float,
                 force: bool = False, protected: Iterable[str] = (), flush_bytes: int | None = None) -> None:
        self.path = check_output_path(path, force=force, protected=protected)
        self.force = force
        self.flush_bytes = FLUSH_BYTES if flush_bytes is None else int(flush_bytes)
        self._tmp = _temp_path(self.path)
        # A text layer cannot be saved incrementally: stage it in a crate file, export at the end.
        self._staging = self._tmp.with_name(self._tmp.name + ".usdc") if self.path.suffix == ".usda" else self._tmp
        self._committed = False
        try:
            self._layer = Sdf.Layer.CreateNew(str(self._staging))
        except Tf.ErrorException as exc:
            self._remove_temps()
            raise _write_error(self.path, exc, self._staging) from None
        if self._layer is None:
            self._remove_temps()
            raise OutputWriteError(f"{self.path}: USD could not create a layer (at {self._staging}); check "
                                   "the folder's permissions and free space")
        _copy_stage_metadata(self._layer, stage, start, end)
        self._attrs: dict[str, tuple[Sdf.Path, Sdf.Path]] = {}
        self._pending = 0  # bytes of samples set since the last save

    def __enter__(self) -> "CacheLayerWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self._committed:
            self.abort()

    def _specs(self, prim_path: str) -> tuple[Sdf.Path, Sdf.Path]:
        if prim_path not in self._attrs:
            spec = Sdf.CreatePrimInLayer(self._layer, Sdf.Path(prim_path))  # 'over' specs
            points = Sdf.AttributeSpec(spec, "points", Sdf.ValueTypeNames.Point3fArray)
            extent = Sdf.AttributeSpec(spec, "extent", Sdf.ValueTypeNames.Float3Array)
            self._attrs[prim_path] = (points.path, extent.path)
        return self._attrs[prim_path]

    def add_points(self, prim_path: str, times: np.ndarray, points: np.ndarray) -> None:
        """Author time samples of ``points`` and ``extent`` for one garment.

        Args:
            times: (T,) float64 time codes.
            points: (T, N, 3) float points in the garment prim's own space and units.
        Raises:
            ArgumentError: a non-finite point, naming the prim and the time code.
        """
        points = np.ascontiguousarray(points, dtype=np.float32)
        if not np.all(np.isfinite(points)):
            bad = int(np.nonzero(~np.isfinite(points).all(axis=(1, 2)))[0][0])
            raise ArgumentError(f"{self.path}: <{prim_path}> has non-finite points at time code {times[bad]:g}; "
                                "nothing was written")
        pts_path, ext_path = self._specs(prim_path)
        lo, hi = points.min(axis=1), points.max(axis=1)
        for i, t in enumerate(np.asarray(times, dtype=np.float64)):
            self._layer.SetTimeSample(pts_path, float(t), Vt.Vec3fArray.FromNumpy(points[i]))
            self._layer.SetTimeSample(ext_path, float(t), Vt.Vec3fArray.FromNumpy(
                np.stack([lo[i], hi[i]])))
        self._pending += points.nbytes + 24 * points.shape[0]
        if self._pending >= self.flush_bytes:
            self.flush()

    def flush(self) -> None:
        """Save the samples added so far to the temporary file; the layer then reads them from
        there, so the memory they held is freed."""
        _save(self._layer, self._staging, self.path)
        self._pending = 0

    def commit(self, provenance: Mapping[str, Any], *, together: Sequence[StagedLayer] = ()) -> Path:
        """Record provenance in ``customLayerData``, save, and rename into place.

        Args:
            together: layers already saved (:func:`stage_shot_layer`) that are renamed into
                place with the cache, all or none (:func:`commit_layers`); they are
                discarded when the cache cannot be saved.
        """
        try:
            self._layer.customLayerData = dict(provenance)
            self.flush()
            if self._staging != self._tmp:
                try:
                    exported = self._layer.Export(str(self._tmp))
                except Tf.ErrorException as exc:
                    raise _write_error(self.path, exc, self._tmp) from None
                if not exported:
                    raise OutputWriteError(f"{self.path}: USD could not save the layer (to {self._tmp}); check "
                                           "the folder's permissions and free space; nothing was written")
                self._staging.unlink(missing_ok=True)
            commit_layers([StagedLayer(self._tmp, self.path, self.force), *together])
        except BaseException:
            for s in together:
                s.discard()
            self.abort()
            raise
        self._committed = True
        log.info("wrote %s", self.path)
        return self.path

    def _remove_temps(self) -> None:
        self._tmp.unlink(missing_ok=True)
        self._staging.unlink(missing_ok=True)

    def abort(self) -> None:
        """Drop the temporary files; the target is left as it was."""
        self._remove_temps()
        self._committed = True


def _relative(target: Path, start: Path) -> str:
    try:
        return os.path.relpath(target.resolve(), start.resolve().parent)
    except ValueError:  # another drive
        return str(target.resolve())


def stage_shot_layer(path: str | Path, *, cache: str | Path, scene: str | Path, stage: StageInfo,
                     start: float, end: float, force: bool = False,
                     protected: Iterable[str] = ()) -> StagedLayer:
    """Save a layer that sublayers ``[cache, scene]``, strongest first, under a temporary
    name; :func:`commit_layers` renames it into place (with its cache).

    The cache must sit above the scene: a default value in a stronger layer would hide
    its time samples. Paths are stored relative to the shot layer when possible.
    """
    path = check_output_path(path, force=force, protected=protected)
    tmp = _temp_path(path)
    try:
        layer = Sdf.Layer.CreateNew(str(tmp))
        if layer is None:
            raise OutputWriteError(f"{path}: USD could not create a layer (at {tmp}); check the folder's "
                                   "permissions and free space")
        _copy_stage_metadata(layer, stage, start, end)
        layer.subLayerPaths = [_relative(Path(cache), path), _relative(Path(scene), path)]
        _save(layer, tmp, path)
    except Tf.ErrorException as exc:
        tmp.unlink(missing_ok=True)
        raise _write_error(path, exc, tmp) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return StagedLayer(tmp, path, force)


def write_shot_layer(path: str | Path, *, cache: str | Path, scene: str | Path, stage: StageInfo,
                     start: float, end: float, force: bool = False,
                     protected: Iterable[str] = ()) -> Path:
    """:func:`stage_shot_layer` and rename it into place (for a cache already written)."""
    staged = stage_shot_layer(path, cache=cache, scene=scene, stage=stage, start=start, end=end, force=force,
                              protected=protected)
    commit_layers([staged])
    return staged.path


@dataclass(frozen=True)
class CacheInfo:
    """What a cache layer on disk says about itself (:func:`cache_layer_info`)."""

    provenance: dict
    """Its ``customLayerData``."""
    start: float
    """``startTimeCode``."""
    end: float
    """``endTimeCode``."""
    samples: dict[str, int]
    """Number of time samples per attribute path (``/Char/Shirt.points``)."""


def cache_layer_info(path: str | Path) -> CacheInfo | None:
    """Read a cache layer's metadata and time-sample counts; None when it is missing or
    not a readable USD layer (a truncated or foreign file)."""
    if not Path(path).is_file():
        return None
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))  # never the registry's cached copy
    except Tf.ErrorException:
        return None
    if layer is None:
        return None
    samples: dict[str, int] = {}

    def visit(spec_path: Sdf.Path) -> None:
        if spec_path.IsPropertyPath():
            samples[str(spec_path)] = layer.GetNumTimeSamplesForPath(spec_path)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return CacheInfo(provenance=dict(layer.customLayerData), start=float(layer.startTimeCode),
                     end=float(layer.endTimeCode), samples=samples)


def stitch_layers(path: str | Path, sources: Sequence[str | Path], *, provenance: Mapping[str, Any],
                  force: bool = False, protected: Iterable[str] = ()) -> Path:
    """Join cache layers that hold different time codes of the same prims into one layer.

    Specs become ``over``s at the same paths, every time sample is copied as it is (no
    resampling), layer metadata comes from the first source, and the time range spans
    all of them. Written to a temporary file and renamed into place.

    Args:
        sources: cache layers in time order (frame chunks of one bake).
        provenance: the joined layer's ``customLayerData``.
    Raises:
        ArgumentError: no sources, or a source that is not a readable layer.
    """
    path = check_output_path(path, force=force, protected=protected)
    if not sources:
        raise ArgumentError(f"{path}: no chunk layers to stitch")
    layers = []
    for src in sources:
        try:
            layer = Sdf.Layer.OpenAsAnonymous(str(src))
        except Tf.ErrorException:
            layer = None
        if layer is None:
            raise ArgumentError(f"{src}: not a readable USD layer; cannot stitch it into {path}")
        layers.append(layer)
    tmp = _temp_path(path)
    out = Sdf.Layer.CreateNew(str(tmp))
    try:
        first = layers[0]
        out.timeCodesPerSecond = first.timeCodesPerSecond
        out.framesPerSecond = first.framesPerSecond
        out.startTimeCode = min(layer.startTimeCode for layer in layers)
        out.endTimeCode = max(layer.endTimeCode for layer in layers)
        for key in ("upAxis", "metersPerUnit"):
            if first.pseudoRoot.HasInfo(key):
                out.pseudoRoot.SetInfo(key, first.pseudoRoot.GetInfo(key))
        held = 0
        for src, layer in zip(sources, layers):
            _copy_time_samples(layer, out)
            held += os.path.getsize(src)
            if held >= FLUSH_BYTES and path.suffix != ".usda":  # bounded memory, as CacheLayerWriter
                _save(out, tmp, path)
                held = 0
        out.customLayerData = dict(provenance)
        _commit(out, tmp, path, force)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    log.info("stitched %d layers into %s", len(layers), path)
    return path


def _copy_time_samples(src: Sdf.Layer, dst: Sdf.Layer) -> None:
    """Every attribute's time samples of ``src`` into ``dst``, creating ``over`` specs.

    Values from a ``.usdc`` source are memory-mapped arrays: the copy shares them until
    ``dst`` is saved.
    """
    attrs: list[Sdf.Path] = []
    src.Traverse(Sdf.Path.absoluteRootPath, lambda p: attrs.append(p) if p.IsPropertyPath() else None)
    for attr in attrs:
        spec = src.GetAttributeAtPath(attr)
        if spec is None:  # a relationship
            continue
        if dst.GetAttributeAtPath(attr) is None:
            prim = Sdf.CreatePrimInLayer(dst, attr.GetPrimPath())
            Sdf.AttributeSpec(prim, attr.name, spec.typeName)
        for t in src.ListTimeSamplesForPath(attr):
            dst.SetTimeSample(attr, t, src.QueryTimeSample(attr, t))
