"""Training data: data-factory shards -> model inputs and targets, normalisation statistics.

Every model input is built through :mod:`cloth_usd.core.pipeline`, the functions the
runtime uses at inference, so training and inference features are the same numbers.
Targets follow docs/method.md: the coarse model learns ``Delta_coarse = M_coarse^GT - I M_b``
(``M_coarse^GT`` the shard's Laplacian-smoothed simulation); configurable are the target
(a Taubin-smoothed simulation: :class:`CoarseTarget`) and the base (the skinned garment
instead of ``I M_b``: :class:`cloth_usd.core.pipeline.CoarseBase`). The detail model learns
``Delta_detail = M_sim - M_coarse`` on a given coarse garment (see
:class:`cloth_usd.nn.train.TrainConfig.coarse_input`).

numpy only (no torch). Shape letters: T frames, B frames of a batch, N garment vertices,
F features.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Sequence

import numpy as np

from ..core.body import BodyModel, load_body_model
from ..core.features import ATTRIBUTE_FEATURES
from ..core.files import file_sha256
from ..core.fit import FitModel
from ..core.heading import Heading, heading_frame
from ..core.mesh import TAUBIN_LAMBDA, TAUBIN_MU, laplacian_smooth
from ..core.pipeline import (
    CoarseBase,
    CoarseFeatures,
    GarmentPair,
    PosedBody,
    coarse_base_points,
    coarse_model_features,
    detail_model_inputs,
    pose_body,
    prepare_pair,
)
from ..core.scene import Category
from ..errors import ArgumentError

if TYPE_CHECKING:
    from ..core.shards import Shard

__all__ = ["Split", "TEST_SPLITS", "Clip", "DataSet", "load_dataset", "CoarseTarget", "with_coarse_target", "with_heading",
           "plan_batches", "CoarseExample", "DetailExample", "coarse_example", "detail_example", "Moments", "Statistics", "even_frames",
           "warmup_frames"]

log = logging.getLogger(__name__)

#: The data set's manifest and fit model, as the factory writes them.
MANIFEST = "manifest.json"
FIT = "fit.npz"
#: Standard deviations below this are replaced by 1 (a constant input carries no scale).
MIN_STD = 1e-6
#: Output scales below this [m] are raised to it.
MIN_SCALE = 1e-4


class Split(str, enum.Enum):
    """The factory's splits (:func:`cloth_usd.datagen.factory.plan_jobs`)."""

    TRAIN = "train"
    VAL = "val"
    TEST_BODY = "test_body"
    """Training shirts on unseen bodies."""
    TEST_GARMENT = "test_garment"
    """Unseen shirts on training bodies."""
    TEST_MOTION = "test_motion"
    """Training pairs with unseen motions."""


TEST_SPLITS = (Split.TEST_BODY, Split.TEST_GARMENT, Split.TEST_MOTION)


@dataclass(frozen=True, eq=False)
class Clip:
    """One simulated sequence with its garment-body pair prepared."""

    name: str
    """The manifest's sequence name."""
    split: Split
    meta: dict
    """The job's provenance from the manifest: shirt, shirt_params, body, motion, ..."""
    pair: GarmentPair
    """Association, graph and fit attribute, as the runtime computes them."""
    rest_points: np.ndarray
    """(N, 3) float64 rest garment [m], canonical body frame."""
    positions: np.ndarray
    """(T, N, 3) float32 simulated garment [m], world frame."""
    coarse: np.ndarray
    """(T, N, 3) float32 coarse target [m] (Laplacian-smoothed simulation)."""
    poses: np.ndarray
    """(T, 72) float64 axis-angle [rad]."""
    transl: np.ndarray
    """(T, 3) float64 root translation [m]."""
    authored_points: np.ndarray | None = None
    """(N, 3) float64 the garment as it was handed to the simulator, before its drape (the
    data set's ``drape/`` cache), canonical body frame; :attr:`rest_points` is the draped
    garment. What a bake of the authored garment reads (a garment's own bundle reads the one
    of the two it was trained on: :func:`cloth_usd.evaluate.garment_reads`). None when the
    folder keeps no drape of this pair."""
    penetration: np.ndarray | None = None
    """(T,) the fraction of the garment's vertices inside the body in each frame, as the
    simulator measured it (the shard's); None when made elsewhere."""

    @property
    def num_frames(self) -> int:
        """T."""
        return int(self.positions.shape[0])


@dataclass(frozen=True)
class DataSet:
    """The shards of a factory folder, loaded."""

    root: Path
    """The data folder."""
    manifest_sha256: str
    """sha256 of its ``manifest.json`` (recorded with every model trained on it)."""
    fit: FitModel
    """The fit attribute's model (``fit.npz``), fitted on the training pairs."""
    body: BodyModel
    """The body model the shards were simulated with."""
    clips: tuple[Clip, ...]

    def split(self, split: Split | str) -> list[Clip]:
        """The clips of one split, in name order."""
        split = Split(split)
        return [c for c in self.clips if c.split is split]


def _pair_key(rest: np.ndarray, faces: np.ndarray, betas: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in (rest, faces, betas):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def load_dataset(root: str | Path, splits: Iterable[Split | str] | None = None, *,
                 body: BodyModel | None = None, max_frames: int | None = None,
                 sequences: Iterable[str] | None = None) -> DataSet:
    """Load the accepted shards of some splits of a factory folder, each without its warm-up
    frames (:func:`warmup_frames`).

    Args:
        root: the folder ``cloth-usd datagen`` wrote (``manifest.json``, ``fit.npz``, shards).
        splits: the splits to load (all when None).
        body: the body model the data was simulated with (default: the embedded one).
        max_frames: keep only the first frames of every sequence after its warm-up (quick runs).
        sequences: load only the sequences of these manifest names (all when None; a name the
            folder does not hold, or not among its accepted sequences, loads nothing).
    Raises:
        ArgumentError: naming the folder, when it is not a data set or a shard is unreadable.
    """
    from ..core.shards import DatasetError, Manifest, read_shard

    root = Path(root)
    if not (root / MANIFEST).is_file() or not (root / FIT).is_file():
        raise ArgumentError(f"--data {root}: not a data set folder (needs {MANIFEST} and {FIT}; "
                            "make one with cloth-usd datagen)")
    try:
        manifest = Manifest.read(root)
    except DatasetError as exc:
        raise ArgumentError(str(exc)) from exc
    wanted = {Split(s) for s in splits} if splits is not None else set(Split)
    named = set(sequences) if sequences is not None else None
    body = body if body is not None else load_body_model()
    fit = FitModel.load(root / FIT)
    pairs: dict[str, GarmentPair] = {}
    chosen = []
    for name in manifest.accepted:
        if named is not None and name not in named:
            continue
        entry = manifest.sequences[name]
        split_name = entry.get("split") or entry.get("meta", {}).get("split")
        if entry.get("meta", {}).get("floor_of"):
            continue  # a held pose of another sequence (cloth_usd.datagen.floor), never trained or evaluated on
        try:
            split = Split(split_name)
        except ValueError:
            log.warning("%s: sequence %s has unknown split %r, skipped", root, name, split_name)
            continue
        if split in wanted:
            chosen.append((name, entry, split))

    def read(item: tuple) -> Shard:
        try:
            return read_shard(root / item[1]["shard"])
        except DatasetError as exc:
            raise ArgumentError(str(exc)) from exc

    # Shards are read (and unzipped, which frees the GIL) a few at a time; pairs are prepared in order.
    authored = _authored(root)
    clips = [_clip(body, fit, pairs, root, name, entry, split, shard, max_frames, authored)
             for (name, entry, split), shard in zip(chosen, _in_threads(read, chosen))]
    clips = [c for c in clips if c is not None]
    log.info("%s: %d sequences, %d garment-body pairs", root, len(clips), len(pairs))
    return DataSet(root=root, manifest_sha256=file_sha256(root / MANIFEST), fit=fit, body=body,
                   clips=tuple(clips))


def _draped_key(draped: np.ndarray) -> str:
    """A draped garment's key in :func:`_authored` (its float32 points, as the shards keep them)."""
    return hashlib.sha256(np.ascontiguousarray(draped, dtype=np.float32).tobytes()).hexdigest()


def _authored(root: Path) -> dict[str, np.ndarray]:
    """By :func:`_draped_key` of each draped garment in ``root/drape``: the garment before its drape."""
    found = {}
    for path in sorted((root / "drape").glob("*.npz")):
        try:
            with np.load(path) as drape:
                found[_draped_key(drape["vertices"])] = np.asarray(drape["source"], dtype=np.float64)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("%s: unreadable drape (%s); its sequences keep no authored garment", path, exc)
    return found


def _clip(body: BodyModel, fit: FitModel, pairs: dict, root: Path, name: str, entry: dict, split: Split,
          shard: Shard, max_frames: int | None, authored: dict[str, np.ndarray] | None = None) -> Clip | None:
    """One sequence of :func:`load_dataset` (its pair prepared once, in ``pairs``), None when
    nothing is left after its warm-up."""
    rest = shard.garment_vertices.astype(np.float64)
    key = _pair_key(rest, shard.garment_faces, shard.betas)
    meta = dict(entry.get("meta", {}))
    if key not in pairs:
        pairs[key] = prepare_pair(body, shard.betas, rest, shard.garment_faces, fit,
                                  category=meta.get("category", Category.TSHIRT.value))
    w = warmup_frames(meta)  # the ease-in of a real clip: the garment still catching up
    t = shard.positions.shape[0] if max_frames is None else min(w + max_frames, shard.positions.shape[0])
    if w >= t:
        log.warning("%s: sequence %s has no frames after its %d warm-up frames, skipped", root, name, w)
        return None
    return Clip(name=name, split=split, meta=meta, pair=pairs[key],
                rest_points=rest, positions=shard.positions[w:t], coarse=shard.coarse[w:t],
                poses=shard.poses[w:t], transl=shard.transl[w:t], penetration=shard.penetration[w:t],
                authored_points=(authored or {}).get(_draped_key(shard.garment_vertices)))


def warmup_frames(meta: dict) -> int:
    """The first frames of a sequence that training and evaluation leave out (its job
    ``meta``'s ``warmup_frames``: the ease-in of a real clip; 0 for procedural motions)."""
    return max(0, int(meta.get("warmup_frames", 0)))


class CoarseTarget(str, enum.Enum):
    """The coarse model's ground truth ``M_coarse^GT``."""

    STORED = "stored"
    """The shards' coarse target: Laplacian smoothing as the factory's DatasetConfig made it
    (docs/method.md's). Plain Laplacian smoothing shrinks the garment: on the large data set's
    test-garment and validation sequences the 10-pass target is 11.8 mm from the simulation."""
    TAUBIN = "taubin"
    """Taubin lambda|mu smoothing of the simulation, re-derived when loading: it removes the
    wrinkles but keeps the garment's size (3.2 mm from the simulation on the same sequences)."""


#: The passes of the :attr:`CoarseTarget.TAUBIN` target (its steps: Taubin's,
#: :data:`~cloth_usd.core.mesh.TAUBIN_LAMBDA` and ``TAUBIN_MU``).
TAUBIN_PASSES = 10


def taubin_smooth(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """A simulated garment (T, N, 3) with its wrinkles smoothed out as the :attr:`CoarseTarget.TAUBIN`
    target is (the garment's size kept), in the dtype it came in."""
    return laplacian_smooth(positions, faces, iterations=TAUBIN_PASSES, lam=TAUBIN_LAMBDA, mu=TAUBIN_MU)


def with_coarse_target(data: DataSet, target: CoarseTarget | str) -> DataSet:
    """``data`` with every clip's :attr:`Clip.coarse` made the ``target`` way (itself for STORED)."""
    if CoarseTarget(target) is CoarseTarget.STORED:
        return data
    clips = _in_threads(lambda c: dataclasses.replace(c, coarse=taubin_smooth(c.positions, c.pair.faces)), data.clips)
    return dataclasses.replace(data, clips=clips)


def _in_threads(fn, items: Sequence) -> tuple:
    """``fn`` over ``items``, in order, a few at a time (unzipping, numpy and scipy free the GIL
    in their loops)."""
    if len(items) < 2:
        return tuple(fn(i) for i in items)
    with ThreadPoolExecutor(max_workers=max(1, min(8, os.cpu_count() or 1))) as pool:
        return tuple(pool.map(fn, items))


def with_heading(data: DataSet, heading: Heading | str) -> DataSet:
    """``data`` in the frame the models see (itself for WORLD): with ``canonical``, every
    clip's poses lose their heading and its simulated and coarse garments turn with the
    body (:class:`~cloth_usd.core.heading.HeadingFrame`), as the runtime does."""
    if Heading(heading) is Heading.WORLD:
        return data

    def turn(c: Clip) -> Clip:
        frame = heading_frame(c.poses, c.transl, c.pair.joints[0])
        return dataclasses.replace(c, poses=frame.canonical_poses(c.poses),
                                   positions=frame.to_canonical(c.positions).astype(np.float32),
                                   coarse=frame.to_canonical(c.coarse).astype(np.float32))

    return dataclasses.replace(data, clips=_in_threads(turn, data.clips))


def even_frames(num_frames: int, count: int | None) -> np.ndarray:
    """(K,) int64 ``count`` frames spread evenly over ``[0, num_frames)`` (all when None or 0)."""
    if not count or count >= num_frames:
        return np.arange(num_frames, dtype=np.int64)
    return np.unique(np.linspace(0, num_frames - 1, count).round().astype(np.int64))


def plan_batches(clips: Sequence, batch: int, rng: np.random.Generator | None = None, *,
                 frames: int | None = None, first: Sequence[int] | None = None) -> list[tuple[int, np.ndarray]]:
    """Batches of frames, each from one clip (a batch shares one garment graph).

    Args:
        clips: the clips (anything with ``num_frames``).
        batch: frames per batch (B).
        rng: shuffles the frames of every clip and the batch order; None keeps both in order.
        frames: use only this many evenly spread frames per clip (all when None).
        first: per clip, its first frame to plan (the ones before are never used; a clip
            with none left gives no batch); None: every frame.
    Returns:
        ``[(clip index, frames (B',) int64), ...]``, B' <= B.
    """
    if batch < 1:
        raise ArgumentError(f"batch must be >= 1 frame, got {batch}")
    out = []
    for k, clip in enumerate(clips):
        start = 0 if first is None else int(first[k])
        if first is not None and clip.num_frames <= start:
            continue
        idx = start + even_frames(clip.num_frames - start, frames)
        if rng is not None:
            idx = rng.permutation(idx)
        out += [(k, idx[lo:lo + batch]) for lo in range(0, idx.shape[0], batch)]
    if rng is not None:
        out = [out[i] for i in rng.permutation(len(out))]
    return out


@dataclass(frozen=True)
class CoarseExample:
    """Coarse model inputs and target for a batch of frames of one clip."""

    features: np.ndarray
    """(B, N, F) float64 node features (F: :func:`~cloth_usd.core.pipeline.coarse_feature_count`)."""
    base: np.ndarray
    """(B, N, 3) float64 the points the displacement is added to [m]: ``I M_b`` (the
    associated posed body vertices) or the skinned garment."""
    target: np.ndarray
    """(B, N, 3) float64 ``Delta_coarse^GT`` [m]."""
    posed: PosedBody


@dataclass(frozen=True)
class DetailExample:
    """Detail model inputs and target for a batch of frames of one clip."""

    features: np.ndarray
    """(B, N, 30) float64 node features on the coarse garment."""
    attributes: np.ndarray
    """(B, 85) float64 (alpha, beta, theta)."""
    base: np.ndarray
    """(B, N, 3) float64 the coarse garment ``M_coarse`` [m] the features were made on."""
    target: np.ndarray
    """(B, N, 3) float64 ``Delta_detail^GT = M_sim - M_coarse`` [m]."""


def coarse_example(body: BodyModel, clip: Clip, frames: np.ndarray, base: CoarseBase | str = CoarseBase.BODY,
                   features: CoarseFeatures | str = CoarseFeatures.BODY) -> CoarseExample:
    """Coarse inputs (``features``, :class:`~cloth_usd.core.pipeline.CoarseFeatures`) and
    target of ``frames`` of ``clip`` (the runtime's feature path), the displacement measured
    from ``base`` (:class:`~cloth_usd.core.pipeline.CoarseBase`)."""
    poses, transl = clip.poses[frames], clip.transl[frames]
    posed = pose_body(body, clip.pair, poses, transl)
    points = coarse_base_points(body, clip.pair, posed, poses, transl, base)
    feats = coarse_model_features(clip.pair, posed, transl, features, base=points)
    return CoarseExample(features=feats, base=points, target=clip.coarse[frames].astype(np.float64) - points,
                         posed=posed)


def detail_example(clip: Clip, frames: np.ndarray, posed: PosedBody, coarse_points: np.ndarray) -> DetailExample:
    """Detail inputs and target of ``frames`` of ``clip`` on the coarse garment ``coarse_points``.

    Args:
        posed: the posed body of those frames (:attr:`CoarseExample.posed`).
        coarse_points: (B, N, 3) ``M_coarse`` [m]: the coarse model's prediction, or the
            coarse target.
    """
    coarse_points = np.asarray(coarse_points, dtype=np.float64)
    feats, attrs = detail_model_inputs(clip.pair, coarse_points, posed, clip.poses[frames], clip.transl[frames])
    return DetailExample(features=feats, attributes=attrs, base=coarse_points,
                         target=clip.positions[frames].astype(np.float64) - coarse_points)


class Moments:
    """Running per-channel mean and standard deviation over the last axis (float64 sums)."""

    def __init__(self, channels: int) -> None:
        self.count = 0
        self.total = np.zeros(channels)
        self.squares = np.zeros(channels)

    def add(self, x: np.ndarray) -> None:
        """Add samples ``x`` (..., C)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.total.shape[0])
        self.count += x.shape[0]
        self.total += x.sum(axis=0)
        self.squares += (x * x).sum(axis=0)

    @property
    def mean(self) -> np.ndarray:
        return self.total / max(self.count, 1)

    @property
    def std(self) -> np.ndarray:
        """Standard deviation; channels below :data:`MIN_STD` get 1 (never divide by ~0)."""
        var = np.maximum(self.squares / max(self.count, 1) - self.mean ** 2, 0.0)
        std = np.sqrt(var)
        return np.where(std < MIN_STD, 1.0, std)

    @property
    def rms(self) -> np.ndarray:
        """Root mean square, at least :data:`MIN_SCALE`."""
        return np.maximum(np.sqrt(self.squares / max(self.count, 1)), MIN_SCALE)


@dataclass(frozen=True)
class Statistics:
    """Normalisation statistics of one generator, computed on the training split."""

    input_mean: np.ndarray
    """(F,) float64 node feature mean."""
    input_std: np.ndarray
    """(F,) float64 node feature standard deviation (1 where constant)."""
    output_scale: np.ndarray
    """(3,) float64 root mean square of the target displacement per axis [m]."""
    attribute_mean: np.ndarray
    """(85,) float64 parser input mean (zeros for the coarse model)."""
    attribute_std: np.ndarray
    """(85,) float64 parser input standard deviation (ones for the coarse model)."""

    @classmethod
    def from_moments(cls, features: Moments, target: Moments, attributes: Moments | None = None) -> "Statistics":
        attrs = attributes if attributes is not None and attributes.count else None
        return cls(input_mean=features.mean, input_std=features.std, output_scale=target.rms,
                   attribute_mean=attrs.mean if attrs else np.zeros(ATTRIBUTE_FEATURES),
                   attribute_std=attrs.std if attrs else np.ones(ATTRIBUTE_FEATURES))

    def save(self, path: str | Path) -> None:
        np.savez(path, input_mean=self.input_mean, input_std=self.input_std, output_scale=self.output_scale,
                 attribute_mean=self.attribute_mean, attribute_std=self.attribute_std)

    @classmethod
    def load(cls, path: str | Path) -> "Statistics":
        with np.load(path, allow_pickle=False) as d:
            return cls(**{k: d[k] for k in ("input_mean", "input_std", "output_scale", "attribute_mean",
                                             "attribute_std")})

    def to_json(self) -> dict:
        return {k: np.round(getattr(self, k), 8).tolist() for k in
                ("input_mean", "input_std", "output_scale", "attribute_mean", "attribute_std")}
