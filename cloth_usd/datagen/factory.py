"""The ground-truth factory: garments x bodies x motions, simulated, from one config.

Splits follow the paper: training shirts on training bodies with training motions;
new bodies (training shirts on test bodies), new garments (test shirts on training
bodies) and new motions (training pairs with test motions) for testing; a small
validation set from both sides. The fit attribute's factor analysis is fitted on the
training pairs and saved beside the shards (``fit.npz``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.association import associate
from ..core.body import load_body_model, posed_vertices, shape_body
from ..core.files import check_keys, read_config
from ..core.fit import FitModel, common_anchors, fit_factor_analysis, pair_distances
from ..core.scene import Category
from ..errors import ArgumentError
from ..core.transfer import transfer_garment
from .bodies import body_shapes
from .dataset import MANIFEST_NAME, DatasetConfig, DatasetError, Job, Manifest, run_jobs
from .floor import FLOOR_SPLIT, FloorSpec, floor_jobs
from .mocap import MocapSpec, mocap_motion, stored_motion
from .simulate import SimConfig
from .motion import MotionKind, MotionSpec, generate
from .tshirt import make_tshirt, tshirt_variants

__all__ = ["FactoryConfig", "MOCAP_ENV", "OWN_BODY", "OwnGarment", "own_garment_files", "save_own_garment", "load_own_garment", "load_config", "plan_jobs", "train_poses", "train_betas", "drape_pairs", "run_factory"]

#: Simulation processes start fresh rather than forked: a process forked from one that has
#: used CUDA (a batched drape runs in the parent) cannot use it.
_SPAWN = multiprocessing.get_context("spawn")

#: The environment variable naming the mocap folder when neither the config nor ``--mocap`` does.
MOCAP_ENV = "CLOTH_USD_MOCAP"

log = logging.getLogger(__name__)

_DEFAULT_TRAIN_MOTIONS = tuple({"kind": k, "seconds": 4.0, "seed": i} for i, k in enumerate(
    ("walk", "run", "arm_raise", "arm_swing", "torso_twist", "torso_bend", "dance")))
_DEFAULT_TEST_MOTIONS = ({"kind": "dance", "seconds": 4.0, "seed": 100},
                         {"kind": "walk", "seconds": 4.0, "seed": 101})


@dataclass(frozen=True)
class FactoryConfig:
    """A whole data set; the defaults are the paper's split at full scale."""

    seed: int = 0
    """Draws the T-shirt variants beyond the three fixed extremes."""
    shirts: int = 9
    test_shirts: tuple[int, ...] = (0, 1, 8)
    """Variant indices held out: 0 is the short shirt, 1 the long one, 8 a drawn one; the
    other six on eight bodies make the paper's 48 training pairs."""
    bodies: tuple[str, ...] = tuple(s.name for s in body_shapes())
    test_bodies: tuple[str, ...] = ("medium_thin", "medium_regular", "medium_fat")
    train_motions: tuple[dict, ...] = _DEFAULT_TRAIN_MOTIONS
    """Per motion, the fields of a procedural :class:`~cloth_usd.datagen.motion.MotionSpec`, or
    of a :class:`~cloth_usd.datagen.mocap.MocapSpec` (an entry with a ``bvh`` key): a real clip,
    eased in, whose warm-up frames training and evaluation leave out, or ``{"stored": name}``:
    one of the CMU stretches shipped with the package (:func:`~cloth_usd.datagen.mocap.stored_motion`),
    retargeted already, so no mocap folder is needed."""
    test_motions: tuple[dict, ...] = _DEFAULT_TEST_MOTIONS
    garment_vertices: int | None = None
    """Override every shirt's target vertex count (small data sets, tests)."""
    sim: dict = field(default_factory=dict)
    """SimConfig field overrides."""
    dataset: dict = field(default_factory=dict)
    """DatasetConfig field overrides."""
    max_frames: int | None = None
    """Cut every motion to this many frames (tests)."""
    test_body_shirts: int | None = None
    """Training shirts worn by each test body (the first ones); None: all of them."""
    simulate_splits: tuple[str, ...] | None = None
    """Simulate only the sequences of these splits (a test set: ``["test_motion"]``); the fit
    attribute is still fitted on the training pairs, as planned (undraped) where they are not
    simulated. None: all."""
    simulate_sequences: dict | None = None
    """Per split, how many of its sequences to simulate, drawn at random (``seed``) without
    replacement; a split it does not name is simulated whole (``{"train": 80}``: simulated
    targets for part of a physics data set, where the hybrid objective adds its supervised
    term). None: all."""
    floor: dict | None = None
    """The per-frame error floor (a :class:`FloorSpec`'s fields): for some of the sequences
    to be simulated, a few of their frames' poses held until the cloth settles, each its own
    sequence of split ``floor`` (see :mod:`cloth_usd.datagen.floor`). None: none."""
    garment: str | tuple[str, ...] | None = None
    """A garment of the user's own instead of the generated T-shirts, or a list of them (all
    of one category): each a ``.npz`` with ``vertices`` (N, 3) [m] (worn by the rest body,
    canonical body frame), ``faces`` (M, 3), ``betas`` (the body it was made for) and
    optionally ``category`` (default ``tshirt``); a relative path is relative to the config
    file's folder. Each is worn by every body of ``bodies`` (carried onto each shape by
    :func:`~cloth_usd.core.transfer.transfer_garment`) and by its own body, named
    ``own``; ``shirts``, ``seed``, ``garment_vertices`` and ``test_shirts`` do not apply
    (there is no unseen garment). Written by ``cloth-usd train-garment``."""
    mocap_dir: str | None = None
    """The folder the ``bvh`` motions are relative to (a relative one: to the config file's
    folder). Usually given at run time (``--mocap DIR`` or ``$CLOTH_USD_MOCAP``), since the
    clips are not part of the project."""


def load_config(path: str | Path, *, mocap_dir: str | Path | None = None) -> FactoryConfig:
    """A FactoryConfig from ``.json`` or ``.toml``; unknown keys are an error naming them.

    Args:
        path: the config file.
        mocap_dir: the mocap folder (overrides the config's ``mocap_dir``; when neither
            names one, ``$CLOTH_USD_MOCAP``).
    """
    path = Path(path)
    raw = check_keys(read_config(path, "the data set config"), FactoryConfig, str(path))
    for key in ("test_shirts", "bodies", "test_bodies", "train_motions", "test_motions", "simulate_splits"):
        if key in raw:
            raw[key] = tuple(raw[key])
    if raw.get("garment"):
        files = raw["garment"]
        if isinstance(files, str):
            raw["garment"] = str(path.parent / files)
        elif isinstance(files, list) and all(isinstance(f, str) for f in files):
            raw["garment"] = tuple(str(path.parent / f) for f in files)
        else:
            raise ArgumentError(f"{path}: garment must be a file name or a list of them, got {files!r}")
    if mocap_dir is not None:
        raw["mocap_dir"] = str(mocap_dir)
    elif raw.get("mocap_dir"):
        raw["mocap_dir"] = str(path.parent / raw["mocap_dir"])
    elif os.environ.get(MOCAP_ENV):
        raw["mocap_dir"] = os.environ[MOCAP_ENV]
    return FactoryConfig(**raw)


@dataclass(frozen=True)
class _Motion:
    name: str
    poses: np.ndarray
    transl: np.ndarray
    fps: float
    warmup_frames: int = 0
    source: dict | None = None


def _check_speed(body, poses: np.ndarray, transl: np.ndarray, spec: MocapSpec, where: str) -> None:
    """Refuse a clip stretch whose body jumps (see :attr:`MocapSpec.max_body_speed`)."""
    v = posed_vertices(body, np.zeros(1), poses, transl)  # (T, V, 3), the mean body
    speed = np.linalg.norm(np.diff(v, axis=0), axis=2).max(axis=1) * spec.fps
    t = int(np.argmax(speed))
    if speed[t] > spec.max_body_speed:
        raise ArgumentError(f"{where} ({spec.bvh} from {spec.start_seconds:g} s): the body moves {speed[t]:.1f} m/s "
                            f"between frames {t} and {t + 1}, past max_body_speed {spec.max_body_speed:g} (a capture "
                            "glitch?); pick another start_seconds, or raise max_body_speed for this entry")


def _motion(fields: dict, config: FactoryConfig, where: str, smpl_joints: np.ndarray, body=None) -> _Motion:
    if not isinstance(fields, dict):
        raise ArgumentError(f"{where}: expected a table of motion fields, got {fields!r}")
    if "stored" in fields:
        extra = sorted(set(fields) - {"stored"})
        if extra:
            raise ArgumentError(f"{where}: a stored motion takes no other field than 'stored' (got {', '.join(extra)})")
        m, fps = stored_motion(str(fields["stored"]))
        poses, transl, warmup = m.poses, m.transl, m.warmup_frames
        name, source = str(fields["stored"]), m.source
    elif "bvh" in fields:
        try:
            spec = MocapSpec(**fields)
        except TypeError as exc:
            raise ArgumentError(f"{where}: {exc} (MocapSpec fields: bvh, start_seconds, seconds, fps, "
                                "ease_seconds, ramp_seconds, name, max_body_speed)") from None
        if not config.mocap_dir:
            raise ArgumentError(f"{where} names the clip {spec.bvh!r} but no mocap folder is given: pass --mocap DIR "
                                f"(or set ${MOCAP_ENV})")
        m = mocap_motion(spec, config.mocap_dir, smpl_joints=smpl_joints)
        poses, transl, warmup = m.poses, m.transl, m.warmup_frames
        if body is not None:
            _check_speed(body, poses, transl, spec, where)
        name, source, fps = spec.label, m.source, spec.fps
    else:
        try:
            spec = MotionSpec(**fields)
        except TypeError as exc:
            raise ArgumentError(f"{where}: {exc}") from None
        poses, transl = generate(spec)
        name, source, fps, warmup = f"{MotionKind(spec.kind).value}-s{spec.seed}", None, spec.fps, 0
    if config.max_frames:
        poses, transl = poses[:config.max_frames], transl[:config.max_frames]
        warmup = min(warmup, max(config.max_frames - 1, 0))
    return _Motion(name=name, poses=poses, transl=transl, fps=float(fps), warmup_frames=int(warmup), source=source)


def _motions(config: FactoryConfig, key: str, body, *, check_speed: bool = True) -> list[_Motion]:
    """The config's ``train_motions`` or ``test_motions`` (``key``), retargeted to the mean
    body's skeleton; with ``check_speed``, a clip stretch whose body jumps is refused."""
    mean_joints = shape_body(body, np.zeros(1))[1]
    return [_motion(m, config, f"{key}[{i}]", mean_joints, body if check_speed else None)
            for i, m in enumerate(getattr(config, key))]


def _body_label(betas: np.ndarray) -> str:
    """thin / regular / fat from the girth component (beta 1), for evaluation rows."""
    return "thin" if betas[1] < -0.5 else "fat" if betas[1] > 0.5 else "regular"


def _shirt_label(params) -> str:
    """short / regular / long from the hem height, for evaluation rows."""
    return "short" if params.hem >= -0.02 else "long" if params.hem <= -0.10 else "regular"


def _train_bodies(config: FactoryConfig) -> list[str]:
    """The names of the config's training bodies: its bodies that are not test bodies."""
    return [n for n in config.bodies if n not in config.test_bodies]


def plan_jobs(config: FactoryConfig, body=None) -> list[Job]:
    """Every sequence of the data set, each tagged with its split in ``meta``."""
    body = body if body is not None else load_body_model()
    files = own_garment_files(config)
    owns = [load_own_garment(f) for f in files]
    categories = sorted({g.category for g in owns})
    if len(categories) > 1:
        raise ArgumentError(f"garment: the garments are of several categories ({', '.join(categories)}); a data set "
                            "trains one category")
    own = owns[0] if owns else None
    if own is not None:
        config = dataclasses.replace(config, test_shirts=())
        variants = [None] * len(owns)
    else:
        variants = tshirt_variants(config.shirts, seed=config.seed)
        if config.garment_vertices:
            variants = [dataclasses.replace(v, target_vertices=config.garment_vertices) for v in variants]
    bad = [i for i in config.test_shirts if not 0 <= i < len(variants)]
    if bad:
        raise ArgumentError(f"test_shirts {bad}: out of range for {len(variants)} shirts")
    splits = ("train", "val", "test_body", "test_garment", "test_motion")
    bad = sorted(set(config.simulate_splits or ()) - set(splits))
    if bad:
        raise ArgumentError(f"simulate_splits {bad}: unknown (valid: {', '.join(splits)})")
    counts = config.simulate_sequences
    if counts is not None and (not isinstance(counts, dict) or any(
            k not in splits or isinstance(n, bool) or not isinstance(n, int) or n < 1 for k, n in counts.items())):
        raise ArgumentError(f"simulate_sequences must map splits ({', '.join(splits)}) to whole numbers >= 1, "
                            f"got {counts!r}")
    shapes = {s.name: s for s in body_shapes([b for b in config.bodies if b != OWN_BODY])}
    if own is None and OWN_BODY in config.bodies:
        raise ArgumentError(f"bodies: {OWN_BODY!r} is the body of the config's own garment, and it names none")
    body_shapes([b for b in config.test_bodies if b != OWN_BODY])  # validates the names
    train_shirts = [i for i in range(len(variants)) if i not in config.test_shirts]
    train_bodies = _train_bodies(config)
    train_m, test_m = _motions(config, "train_motions", body), _motions(config, "test_motions", body)
    sim_fps = float(config.sim.get("fps", SimConfig.fps))
    for kind, motions in (("train_motions", train_m), ("test_motions", test_m)):
        for i, m in enumerate(motions):
            if abs(m.fps - sim_fps) > 1e-6 * sim_fps:
                raise ArgumentError(f"{kind}[{i}] ({m.name}) runs at {m.fps:g} fps but the simulation at {sim_fps:g} "
                                    "(sim.fps): give them the same rate")
    plan: list[tuple[str, int, str, _Motion]] = []
    plan += [("train", s, b, m) for s in train_shirts for b in train_bodies for m in train_m]
    plan += [("test_body", s, b, m) for s in train_shirts[:config.test_body_shirts] for b in config.test_bodies
             for m in test_m[:1]]
    plan += [("test_garment", s, b, m) for s in config.test_shirts for b in train_bodies for m in test_m[:1]]
    plan += [("test_motion", s, b, m) for s in train_shirts[:2] for b in train_bodies[:2] for m in test_m]
    plan += [("val", train_shirts[0], train_bodies[-1], m) for m in test_m[-1:]]
    plan += [("val", config.test_shirts[0], config.test_bodies[-1], m) for m in test_m[-1:]] \
        if config.test_shirts and config.test_bodies else []
    garments: dict[tuple[int, str], tuple[np.ndarray, np.ndarray]] = {}
    jobs = []
    for split, s, b, motion in plan:
        betas = owns[s].betas if b == OWN_BODY else shapes[b].betas
        if (s, b) not in garments:
            garments[(s, b)] = make_tshirt(body, betas, variants[s]) if own is None else \
                (transfer_garment(body, owns[s].vertices, owns[s].betas, betas), owns[s].faces)
        verts, faces = garments[(s, b)]
        params = {"file": Path(files[s]).name} if own is not None else dataclasses.asdict(variants[s])
        meta = {"split": split, "shirt": s, "shirt_params": params,
                "shirt_label": "own" if own is not None else _shirt_label(variants[s]), "body": b,
                "body_label": _body_label(betas), "motion": motion.name, "fps": motion.fps,
                "category": own.category if own is not None else "tshirt"}
        if motion.warmup_frames:
            meta["warmup_frames"] = motion.warmup_frames
        if motion.source is not None:
            meta["motion_source"] = motion.source
        jobs.append(Job(
            name=f"{split}.shirt{s}.{b}.{motion.name}", garment_vertices=verts, garment_faces=faces,
            betas=betas, poses=motion.poses, transl=motion.transl, seed=config.seed, meta=meta))
    if config.floor is not None:
        jobs += floor_jobs(_to_simulate(config, jobs), FloorSpec.from_mapping(config.floor))
    return jobs


def train_poses(config: FactoryConfig, body=None) -> np.ndarray:
    """(T, 72) axis-angle [rad] every frame of the config's training motions, each motion once
    (every training garment and body wears the same ones): what a bundle trained on the config
    records as its pose range (:func:`~cloth_usd.core.limits.pose_range_record`). No garment is
    made."""
    motions = _motions(config, "train_motions", body if body is not None else load_body_model(), check_speed=False)
    if not motions:
        raise ArgumentError("train_motions: the config lists no training motion")
    return np.concatenate([m.poses for m in motions])


def train_betas(config: FactoryConfig) -> np.ndarray:
    """(K, B) the shape coefficients of the config's training bodies (its own garments' bodies
    among them, read from their files): what a bundle trained on the config records as its
    range of bodies (:func:`~cloth_usd.core.limits.betas_range_record`)."""
    names = _train_bodies(config)
    rows = [s.betas for s in body_shapes([b for b in names if b != OWN_BODY])]
    if OWN_BODY in names:
        rows += [load_own_garment(f).betas for f in own_garment_files(config)]
    if not rows:
        raise ArgumentError("bodies: the config lists no training body")
    width = max(len(r) for r in rows)
    return np.stack([np.pad(np.asarray(r, dtype=np.float64), (0, width - len(r))) for r in rows])


def _to_simulate(config: FactoryConfig, jobs: list[Job]) -> list[Job]:
    """The planned sequences the factory simulates, in plan order: those of ``simulate_splits``,
    ``simulate_sequences`` of them drawn at random, and every floor sequence. The draw is the
    head of one seeded order, so a larger count keeps every sequence a smaller one drew: raised
    in the config and run again into the same folder, only the new sequences are simulated."""
    chosen = [j for j in jobs if j.meta["split"] != FLOOR_SPLIT
              and (config.simulate_splits is None or j.meta["split"] in config.simulate_splits)]
    drop: set[int] = set()
    for split, count in (config.simulate_sequences or {}).items():
        inside = [k for k, j in enumerate(chosen) if j.meta["split"] == split]
        if count < len(inside):
            kept = np.random.default_rng(config.seed).permutation(len(inside))[:count]
            drop |= set(inside) - {inside[i] for i in kept}
    return [j for k, j in enumerate(chosen) if k not in drop] + [j for j in jobs if j.meta["split"] == FLOOR_SPLIT]


#: The body name of a config's own garment (:attr:`FactoryConfig.garment`): the body it was made for.
OWN_BODY = "own"


def own_garment_files(config: FactoryConfig) -> tuple[str, ...]:
    """The files of :attr:`FactoryConfig.garment`, in order (none: the generated T-shirts)."""
    if not config.garment:
        return ()
    return (config.garment,) if isinstance(config.garment, (str, Path)) else tuple(config.garment)


@dataclass(frozen=True)
class OwnGarment:
    """A user's garment as :attr:`FactoryConfig.garment` names it."""

    vertices: np.ndarray
    """(N, 3) float64 rest points [m], canonical body frame."""
    faces: np.ndarray
    """(M, 3) int64 triangles."""
    betas: np.ndarray
    """(10,) float64 the shape of the body it was made for."""
    category: str = "tshirt"
    """The garment's category (a :class:`~cloth_usd.core.scene.Category` value)."""


def save_own_garment(path: str | Path, vertices: np.ndarray, faces: np.ndarray, betas: np.ndarray, *,
                     category: str = "tshirt") -> Path:
    """Write the ``.npz`` :attr:`FactoryConfig.garment` reads (no pickle)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    b = np.zeros(10)
    b[:min(10, len(betas))] = np.asarray(betas, dtype=np.float64)[:10]
    np.savez(path, vertices=np.asarray(vertices, dtype=np.float64), faces=np.asarray(faces, dtype=np.int64),
             betas=b, category=np.array(Category(category).value))
    return path


def load_own_garment(path: str | Path) -> OwnGarment:
    """Read a :attr:`FactoryConfig.garment` file; anything malformed is an error naming it."""
    try:
        with np.load(path, allow_pickle=False) as z:
            v, f, b = (np.asarray(z[k]) for k in ("vertices", "faces", "betas"))
            category = str(z["category"]) if "category" in z.files else Category.TSHIRT.value
    except (OSError, KeyError, ValueError) as exc:
        raise ArgumentError(f"garment {path}: unreadable ({exc}); it needs vertices, faces and betas") from None
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)) or f.ndim != 2 or f.shape[1] != 3 \
            or f.size == 0 or f.min() < 0 or f.max() >= v.shape[0]:
        raise ArgumentError(f"garment {path}: vertices must be finite (N, 3) and faces (M, 3) indices below N")
    try:
        category = Category(category).value
    except ValueError:
        valid = ", ".join(c.value for c in Category)
        raise ArgumentError(f"garment {path}: category {category!r} is unknown (valid: {valid})") from None
    betas = np.zeros(10)
    betas[:min(10, b.size)] = b.ravel()[:10]
    return OwnGarment(vertices=v.astype(np.float64), faces=f.astype(np.int64), betas=betas, category=category)


def _worker(args: tuple) -> None:
    jobs, out_dir, sim, dataset, name, batch, penetration_frames, deadline = args
    run_jobs(jobs, out_dir, SimConfig(**sim), dataset=DatasetConfig(**dataset), manifest_name=name, batch=batch,
             penetration_frames=penetration_frames, deadline=deadline)


def fit_training_pairs(jobs: list[Job], body) -> tuple[FitModel, dict[str, list[float]]]:
    """Fit the fit-attribute factor analysis on the training garment-body pairs.

    Returns the model and alpha for every pair of the data set (keyed ``shirt<i>.<body>``).
    """
    pairs = {}
    for job in jobs:
        key = f"shirt{job.meta['shirt']}.{job.meta['body']}"
        if key not in pairs:
            v_b, _ = shape_body(body, job.betas)
            pairs[key] = (job.meta["split"] == "train", job.garment_vertices,
                          associate(job.garment_vertices, v_b, body.faces), v_b)
    train = [p for p in pairs.values() if p[0]]
    if len(train) < 4:
        raise ArgumentError(f"the fit attribute needs at least 4 training garment-body pairs for its "
                            f"3 factors; this config has {len(train)} (add training shirts or bodies)")
    anchors = common_anchors([(a, v_b) for _, _, a, v_b in train], shape_body(body, np.zeros(10))[0],
                             min(len(p[1]) for p in train))
    d_train = np.stack([pair_distances(g, a, v_b, anchors) for _, g, a, v_b in train])
    model, _ = fit_factor_analysis(d_train, anchors)
    alphas = {k: model.transform(pair_distances(g, a, v_b, anchors)).tolist()
              for k, (_, g, a, v_b) in pairs.items()}
    return model, alphas


def _pair(job: Job) -> str:
    return f"shirt{job.meta['shirt']}.{job.meta['body']}"


def _drape_path(out_dir, key: str, verts, faces, betas, sim: dict) -> Path:
    """The cached drape of a pair: named by a digest of its inputs, so a changed garment or
    solver setting drapes again."""
    h = hashlib.sha256(json.dumps(SimConfig(**sim).to_json(), sort_keys=True).encode())
    for a in (verts, faces, betas):
        h.update(np.ascontiguousarray(a).tobytes())
    return Path(out_dir) / "drape" / f"{key}.{h.hexdigest()[:16]}.npz"


def _save_drape(path: Path, draped: np.ndarray, faces: np.ndarray, verts: np.ndarray, result) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, vertices=draped, faces=faces, source=verts, quality=json.dumps(result.quality()))
    tmp.replace(path)


def _drape_batch(args: list[tuple], batch: int, penetration_frames: int | None) -> list[tuple[str, str]]:
    """Drape the pairs of ``args`` (as :func:`_drape_worker` takes them) ``batch`` at a time,
    each chunk as one model (:func:`~cloth_usd.datagen.simulate.drape_batch`)."""
    from .simulate import drape_batch

    cached = [_drape_path(a[4], a[0], a[1], a[2], a[3], a[5]).exists() for a in args]
    todo = [a for a, c in zip(args, cached) if not c]
    done = [(a[0], "") for a, c in zip(args, cached) if c]
    if not todo:
        return done
    config = SimConfig(**todo[0][5])
    body = load_body_model()
    for i in range(0, len(todo), batch):
        chunk = todo[i:i + batch]
        log.info("draping %d pairs as one model", len(chunk))
        results = drape_batch(body, [(b, v, f) for _, v, f, b, _, _ in chunk], config,
                              penetration_frames=penetration_frames)
        for (key, verts, faces, betas, out_dir, sim), result in zip(chunk, results):
            if not result.is_stable:
                done.append((key, f"drape unstable: {result.failure}"))
                continue
            _save_drape(_drape_path(out_dir, key, verts, faces, betas, sim), result.positions[-1].astype(np.float64),
                        faces, verts, result)
            done.append((key, ""))
    return done


def _drape_worker(args: tuple) -> tuple[str, str]:
    """Drape one garment-body pair into ``out/drape/<pair>.npz`` (atomic); returns (pair, failure)."""
    key, verts, faces, betas, out_dir, sim = args
    from .simulate import SimulationError, drape

    path = _drape_path(out_dir, key, verts, faces, betas, sim)
    if path.exists():
        return key, ""
    try:
        draped, result = drape(load_body_model(), betas, verts, faces, SimConfig(**sim))
    except SimulationError as exc:
        return key, str(exc)
    _save_drape(path, draped, faces, verts, result)
    return key, ""


def drape_pairs(jobs: list[Job], out_dir: str | Path, sim: dict, *, workers: int = 1,
                batch: int = 1, penetration_frames: int | None = None) -> tuple[list[Job], dict]:
    """Drape every garment-body pair once (cached in ``out_dir/drape``) and put the draped
    garment into its jobs. Pairs whose drape went unstable are dropped, with their reason.
    With ``batch`` > 1 the pairs are draped that many at a time as one model, in this process
    (their penetration measured at ``penetration_frames`` frames, as a batch's sequences)."""
    pairs = {}
    for job in jobs:
        pairs.setdefault(_pair(job), (job.garment_vertices, job.garment_faces, job.betas))
    args = [(k, v, f, b, str(out_dir), sim) for k, (v, f, b) in pairs.items()]
    if batch > 1 and len(args) > 1:
        done = _drape_batch(args, batch, penetration_frames)
    elif workers > 1 and len(args) > 1:
        with ProcessPoolExecutor(max_workers=min(workers, len(args)), mp_context=_SPAWN) as pool:
            done = list(pool.map(_drape_worker, args))
    else:
        done = [_drape_worker(a) for a in args]
    failed = {k: why for k, why in done if why}
    for k, why in failed.items():
        log.warning("%s: %s; its sequences are left out", k, why)
    draped = {k: np.load(_drape_path(out_dir, k, v, f, b, sim))["vertices"]
              for k, (v, f, b) in pairs.items() if k not in failed}
    out = [dataclasses.replace(j, garment_vertices=draped[_pair(j)]) for j in jobs if _pair(j) not in failed]
    return out, failed


def _merge_worker_manifests(out: Path) -> Manifest:
    """Fold every ``manifest.worker-*.json`` in ``out`` (this run's, or those a killed run
    left) into the data set's manifest, and remove them."""
    try:
        merged = Manifest.read(out)
    except DatasetError:  # no earlier manifest
        merged = Manifest(config={}, dataset={}, engine={})
    for path in sorted(out.glob("manifest.worker-*.json")):
        part = Manifest.read(out, path.name)
        merged.sequences.update(part.sequences)
        merged.config, merged.dataset, merged.engine = part.config, part.dataset, part.engine
        path.unlink()
    return merged


def run_factory(config: FactoryConfig, out_dir: str | Path, *, workers: int = 1, batch: int = 1,
                penetration_frames: int | None = None, deadline: float | None = None) -> Manifest:
    """Plan, drape every pair to be simulated, fit alpha, simulate (in ``workers``
    processes, each simulating ``batch`` sequences at a time as one model; see
    :func:`~cloth_usd.datagen.dataset.run_jobs` for ``penetration_frames`` and ``deadline``),
    merge the workers' manifests. Resumable: the manifest is merged even when the run is
    interrupted, and a run killed outright leaves worker manifests the next run folds in.

    With ``batch`` > 1 the sequences are simulated in a seeded random order after the
    validation ones, so a run stopped by its deadline leaves a validation split and a spread
    of garments, bodies and motions rather than the first ones."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    body = load_body_model()
    planned = plan_jobs(config, body)
    log.info("%d sequences planned", len(planned))
    simulated = _to_simulate(config, planned)
    wanted, drape_failed = drape_pairs(simulated, out, config.sim, workers=workers, batch=batch,
                                       penetration_frames=penetration_frames)
    # The fit attribute is fitted on the training pairs: draped where they are simulated, as
    # planned where simulate_splits or simulate_sequences leaves them out (a test set is never
    # trained on).
    draped = {_pair(j): j.garment_vertices for j in wanted}
    jobs = [dataclasses.replace(j, garment_vertices=draped[_pair(j)]) if _pair(j) in draped else j
            for j in planned if _pair(j) not in drape_failed]
    # The fit does not depend on what the simulation makes, so it comes first: a run that is
    # interrupted still leaves a manifest ``cloth-usd evaluate`` reads.
    model, alphas = fit_training_pairs(jobs, body)
    model.save(out / "fit.npz")
    if batch > 1:  # a seeded random order, the validation sequences first (a deadline never leaves none)
        wanted = [wanted[i] for i in np.random.default_rng(config.seed).permutation(len(wanted))]
        wanted.sort(key=lambda j: j.meta["split"] != "val")
    workers = max(1, min(workers, len(wanted)))
    names = [f"manifest.worker-{k}.json" for k in range(workers)]
    parts = [(wanted[k::workers], out, config.sim, config.dataset, names[k], batch, penetration_frames, deadline)
             for k in range(workers)]
    try:
        if workers == 1:
            _worker(parts[0])
        else:
            with ProcessPoolExecutor(max_workers=workers, mp_context=_SPAWN) as pool:
                list(pool.map(_worker, parts))
    finally:
        merged = _merge_worker_manifests(out)
        for job in simulated:
            if _pair(job) in drape_failed:
                merged.sequences[job.name] = {"status": "rejected", "shard": None, "seed": int(job.seed),
                                              "digest": None, "meta": job.meta,
                                              "quality": {"stable": False, "failure": drape_failed[_pair(job)]}}
        for job in jobs:
            entry = merged.sequences.get(job.name)
            if entry is not None:
                entry["split"] = job.meta["split"]
                entry["alpha"] = alphas[f"shirt{job.meta['shirt']}.{job.meta['body']}"]
        merged.write(out, MANIFEST_NAME)
    return merged
