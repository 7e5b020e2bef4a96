"""Reading a USD stage into cloth_usd's dataclasses (see docs/scene_contract.md in the repository).

This is the only module that reads a scene. Everything it returns is a frozen
dataclass of numpy arrays in the internal frame (metres, Y-up, SMPL's axes); no
``Usd.Prim`` leaves it. Matrices are returned in the column convention
(``p' = M @ [p, 1]``), the transpose of USD's row-vector ``Gf.Matrix4d``.

Shape letters: T frames, N garment vertices, M triangles, J joints.
"""

from __future__ import annotations

import errno
import logging
import os
import re
from collections.abc import Mapping

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdSkel

from cloth_usd.core.joint_names import JointMap, as_joint_map, match_joints
from cloth_usd.core.limits import BETA_MAX
from cloth_usd.core.rotations import matrix_to_axis_angle
from cloth_usd.core.scene import Category, Character, Garment, Motion, Scene, StageInfo, Tier
from cloth_usd.core.smpl import JOINT_NAMES, NUM_BETAS, NUM_JOINTS, PARENTS
from cloth_usd.errors import ArgumentError, GarmentError, SceneError

__all__ = [
    "open_stage",
    "read_stage_info",
    "stage_to_internal",
    "read_scene",
    "read_motion",
    "garment_from_internal",
    "garment_points_internal",
]

_log = logging.getLogger(__name__)

#: Rotation taking stage axes to internal (Y-up) axes, per stage ``upAxis``.
#: Z-up: -90 degrees about X, (x, y, z) -> (x, z, -y).
_UP_AXIS_ROTATION = {
    "Y": np.eye(3),
    "Z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}
_GENDERS = ("neutral", "female", "male")
_EARLIEST = Usd.TimeCode.EarliestTime()


# --------------------------------------------------------------------------- stage


def open_stage(path: str | os.PathLike) -> Usd.Stage:
    """Open a USD file as a stage (all payloads loaded).

    Every sublayer, reference and payload asset of every layer it uses must resolve
    and open: USD itself only warns and composes the stage without the layer (a
    character without its animation), so that is an error here.

    Raises:
        SceneError: the file is missing, a folder, a broken or looping symbolic link,
            unreadable or not a USD file, or a layer it composes is missing or does
            not open (naming that layer and the one that uses it).
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"{path}: {_not_a_file(path)}; pass the path of a .usd, .usda, .usdc or .usdz scene")
    if not os.access(path, os.R_OK):
        raise SceneError(f"{path}: file is not readable; check its permissions")
    try:
        root = Sdf.Layer.FindOrOpen(path)
        # Held until the stage has them, so that each layer is parsed once.
        layers = _check_layer_stack(root, path) if root is not None else []
        stage = Usd.Stage.Open(root) if root is not None else None
        del layers
    except Tf.ErrorException as exc:
        raise SceneError(
            f"{path}: cannot open as a USD stage ({_tf_reason(exc)}); "
            "pass a valid .usd, .usda, .usdc or .usdz file"
        ) from None
    if stage is None:
        raise SceneError(f"{path}: cannot open as a USD stage; pass a valid .usd, .usda, .usdc or .usdz file")
    _check_composition(stage, path)
    return stage


def _not_a_file(path: str, missing: str = "no such file") -> str:
    """Why ``path`` (which is not a regular file) cannot be read, for messages; ``missing``
    when there is nothing at all there."""
    if os.path.isdir(path):
        return "is a folder, not a USD file"
    if os.path.islink(path):
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "is a symbolic link loop"
        return f"is a broken symbolic link (to {os.readlink(path)!r}, which does not exist)"
    if os.path.exists(path):
        return "is not a regular file"
    return missing


def _asset_file(layer: Sdf.Layer, asset: str) -> str:
    """An asset path of ``layer`` resolved against it (a file path for plain files)."""
    resolved = layer.ComputeAbsolutePath(asset)
    if not os.path.isabs(resolved) and "[" not in resolved and layer.realPath:
        resolved = os.path.normpath(os.path.join(os.path.dirname(layer.realPath), resolved))
    return resolved


def _check_layer_stack(root: Sdf.Layer, path: str) -> list[Sdf.Layer]:
    """SceneError for the first sublayer, reference or payload asset that does not open.

    Checked before the stage is composed, so USD's own warning is never printed.

    Returns:
        Every layer opened on the way, the root first.
    """
    seen = {root.identifier}
    todo = [root]
    opened = [root]
    while todo:
        layer = todo.pop()
        sublayers = list(layer.subLayerPaths)
        others = [a for a in layer.GetCompositionAssetDependencies() if a not in sublayers]
        for asset in sublayers + others:
            if not asset:
                continue
            kind = "sublayer" if asset in sublayers else "referenced or payload layer"
            resolved = _asset_file(layer, asset)
            where = f"{path}: {kind} @{asset}@ of {layer.realPath or layer.identifier}"
            if os.path.isabs(resolved) and not os.path.isfile(resolved):
                raise SceneError(f"{where}: {_not_a_file(resolved, 'does not exist')} "
                                 f"(resolved to {resolved}); restore it or remove it from the layer")
            try:
                dep = Sdf.Layer.FindOrOpen(resolved)
            except Tf.ErrorException as exc:
                raise SceneError(f"{where}: cannot be opened ({_tf_reason(exc)}); repair or replace "
                                 f"{resolved}") from None
            if dep is None:
                raise SceneError(f"{where}: cannot be found or opened (resolved to {resolved}); restore it "
                                 "or remove it from the layer")
            if dep.identifier not in seen:
                seen.add(dep.identifier)
                todo.append(dep)
                opened.append(dep)
    return opened


#: Composition errors that mean the stage is missing content its layers ask for.
_FATAL_COMPOSITION = ("ErrorInvalidSublayerPath", "ErrorInvalidAssetPath", "ErrorMutedAssetPath",
                      "ErrorSublayerCycle", "ErrorArcCycle", "ErrorUnresolvedPrimPath")


def _check_composition(stage: Usd.Stage, path: str) -> None:
    """SceneError for a composition error that drops content; other errors are logged."""
    errors = stage.GetCompositionErrors() if hasattr(stage, "GetCompositionErrors") else []
    for error in errors:
        text = str(error).strip()
        if type(error).__name__ in _FATAL_COMPOSITION:
            raise SceneError(f"{path}: the stage does not compose as its layers say: {text}")
        _log.warning("%s: composition: %s", path, text)


def stage_to_internal(stage: Usd.Stage) -> np.ndarray:
    """The stage's world-to-internal map, without logging.

    Returns:
        (4, 4) float64, column convention: ``internal = M @ [p, 1]`` for a stage
        world point ``p``; scale by ``metersPerUnit`` then, for Z-up, rotate -90
        degrees about X.

    Raises:
        SceneError: ``upAxis`` is neither Y nor Z, or ``metersPerUnit`` is not positive.
    """
    up = str(UsdGeom.GetStageUpAxis(stage))
    if up not in _UP_AXIS_ROTATION:
        raise SceneError(f"{_layer(stage)}: upAxis is {up!r}; author upAxis \"Y\" or \"Z\"")
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    if not (np.isfinite(mpu) and mpu > 0.0):
        raise SceneError(f"{_layer(stage)}: metersPerUnit is {mpu}; author a positive metersPerUnit")
    m = np.eye(4)
    m[:3, :3] = mpu * _UP_AXIS_ROTATION[up]
    return m


def read_stage_info(stage: Usd.Stage) -> StageInfo:
    """Stage metadata; logs a warning when ``metersPerUnit`` is unauthored (0.01 is used)."""
    s2i = stage_to_internal(stage)
    authored = bool(UsdGeom.StageHasAuthoredMetersPerUnit(stage))
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    for key, value in (("timeCodesPerSecond", stage.GetTimeCodesPerSecond()),
                       ("framesPerSecond", stage.GetFramesPerSecond())):
        if not (np.isfinite(value) and value > 0.0):
            raise SceneError(f"{_layer(stage)}: {key} is {value:g}; author a positive {key} (e.g. 24)")
    if not authored:
        _log.warning(
            "%s: metersPerUnit is not authored; using USD's fallback %g (centimetres). "
            "Author metersPerUnit on the root layer to silence this.",
            _layer(stage),
            mpu,
        )
    return StageInfo(
        identifier=_layer(stage),
        up_axis=str(UsdGeom.GetStageUpAxis(stage)),
        meters_per_unit=mpu,
        meters_per_unit_authored=authored,
        time_codes_per_second=float(stage.GetTimeCodesPerSecond()),
        frames_per_second=float(stage.GetFramesPerSecond()),
        start_time_code=_authored_time(stage, "startTimeCode", stage.GetStartTimeCode),
        end_time_code=_authored_time(stage, "endTimeCode", stage.GetEndTimeCode),
        stage_to_internal=s2i,
    )


def read_scene(
    stage: Usd.Stage,
    *,
    problems: list[str] | None = None,
    skipped: list[str] | None = None,
    joint_map: JointMap | Mapping[str, str] | str | os.PathLike | None = None,
) -> Scene:
    """Stage info, characters and garments, as the scene contract defines them.

    Characters are every Skeleton a garment's ``cloth:body`` targets, plus every
    other Skeleton whose joints name all 24 SMPL joints and that reads cleanly (one
    that does not is skipped with a warning, or a problem line). Joint names may
    follow any convention of :mod:`cloth_usd.core.joint_names`, or ``joint_map``.

    Args:
        problems: None to raise on the first contract breach. A list to read
            leniently (``cloth-usd inspect``): each breach is appended as one line
            and its prim left out, together with the garments whose body it is.
        skipped: a list to which each untargeted Skeleton that is not an SMPL
            skeleton is appended as one line saying why and what to do (they are
            left out either way, not a breach).
        joint_map: ``{their joint name: SMPL joint name}``, as a mapping, a JSON or
            TOML file, or a :class:`~cloth_usd.core.joint_names.JointMap`; its
            entries come before the conventions' names.

    Raises:
        SceneError, GarmentError: the stage breaks the scene contract (always for
        stage-level metadata; for prims only when ``problems`` is None); the
        message names the file, the prim and what to author.
        ArgumentError: ``joint_map`` is unreadable or invalid.
    """
    joint_map = as_joint_map(joint_map)
    info = read_stage_info(stage)
    s2i = info.stage_to_internal
    xf_cache = UsdGeom.XformCache(_EARLIEST)
    skel_cache = UsdSkel.Cache()
    prims = list(stage.Traverse())

    def attempt(read, *args):
        if problems is None:
            return read(*args)
        try:
            return read(*args)
        except SceneError as exc:
            problems.append(str(exc))
            return None

    garments = [
        attempt(_read_garment, stage, p, s2i, xf_cache)
        for p in prims
        if p.IsA(UsdGeom.Mesh) and p.HasAttribute("cloth:category")
    ]
    garments = [g for g in garments if g is not None]
    targeted = {g.body_path for g in garments}
    characters = []
    for prim in (p for p in prims if p.IsA(UsdSkel.Skeleton)):
        if str(prim.GetPath()) in targeted:
            character = attempt(_read_character, stage, prim, s2i, xf_cache, skel_cache, joint_map)
        elif (match := match_joints(_joint_paths(prim), joint_map)).missing:
            _log.info("skipping Skeleton %s: %s", prim.GetPath(), match.problem)
            if skipped is not None:
                skipped.append(f"{_where(stage, prim)}: {match.problem}")
            continue
        else:
            character = _read_untargeted(stage, prim, s2i, xf_cache, skel_cache, joint_map, problems)
        if character is not None:
            characters.append(character)
    garments = _drop_bodiless(stage, garments, {c.prim_path for c in characters}, problems)
    return Scene(stage=info, characters=tuple(characters), garments=tuple(garments))


def _read_untargeted(
    stage: Usd.Stage,
    prim: Usd.Prim,
    s2i: np.ndarray,
    xf_cache: UsdGeom.XformCache,
    skel_cache: UsdSkel.Cache,
    joint_map: JointMap | None,
    problems: list[str] | None,
) -> Character | None:
    """A Skeleton no garment targets: a Character if it reads cleanly, else None and a note."""
    try:
        return _read_character(stage, prim, s2i, xf_cache, skel_cache, joint_map)
    except SceneError as exc:
        if problems is None:
            _log.warning("skipping a Skeleton that no garment targets: %s", exc)
        else:
            problems.append(str(exc))
        return None


def _drop_bodiless(
    stage: Usd.Stage, garments: list[Garment], bodies: set[str], problems: list[str] | None
) -> list[Garment]:
    """Garments whose body was read; the others get a problem line (lenient reads only)."""
    kept = []
    for g in garments:
        if g.body_path in bodies:
            kept.append(g)
        elif problems is not None:
            problems.append(
                f"{_layer(stage)} <{g.prim_path}>: skipped, its cloth:body <{g.body_path}> "
                "is not a valid character"
            )
    return kept


# ---------------------------------------------------------------------- characters


def _read_character(
    stage: Usd.Stage,
    prim: Usd.Prim,
    s2i: np.ndarray,
    xf_cache: UsdGeom.XformCache,
    skel_cache: UsdSkel.Cache,
    joint_map: JointMap | None = None,
) -> Character:
    """One Skeleton prim -> Character; raises SceneError on any contract breach."""
    where = _where(stage, prim)
    joints = _joint_paths(prim)
    joint_indices = _smpl_joint_indices(joints, where, joint_map)
    _check_hierarchy(joints, joint_indices, where)
    betas, betas_authored = _read_betas(prim, where)
    query = _skel_query(skel_cache, prim, where)
    rest_skel = _rest_skel_transforms(query, where)[joint_indices]
    rest_world = s2i @ _local_to_world(xf_cache, prim) @ rest_skel  # (24, 4, 4)
    rest_joints = rest_world[:, :3, 3].copy()
    return Character(
        prim_path=str(prim.GetPath()),
        betas=betas,
        betas_authored=betas_authored,
        gender=_read_gender(prim, where),
        joint_indices=joint_indices,
        rest_root_position=rest_joints[0].copy(),
        rest_joints=rest_joints,
    )


def _smpl_joint_indices(joints: list[str], where: str, joint_map: JointMap | None) -> np.ndarray:
    """(24,) int64 index into ``joints`` of each SMPL joint, matched by last path element."""
    match = match_joints(joints, joint_map)
    if match.problem is not None:
        raise SceneError(f"{where}: {match.problem}")
    if match.naming != "smpl":
        _log.info("%s: joints named as %s", where, match.naming)
    return match.indices


def _joint_paths(prim: Usd.Prim) -> list[str]:
    """The Skeleton's ``joints``, as strings ([] when unauthored)."""
    return [str(j) for j in (UsdSkel.Skeleton(prim).GetJointsAttr().Get() or [])]


def _check_hierarchy(joints: list[str], joint_indices: np.ndarray, where: str) -> None:
    """Each SMPL joint's nearest SMPL ancestor in the skeleton must be its SMPL parent."""
    ok, reason = UsdSkel.Topology(joints).Validate()
    if not ok:
        raise SceneError(f"{where}: invalid joint topology: {reason}")
    parents = np.asarray(UsdSkel.Topology(joints).GetParentIndices(), dtype=np.int64)
    smpl_of = {int(k): j for j, k in enumerate(joint_indices)}
    for j, k in enumerate(joint_indices):
        p = parents[k]
        while p >= 0 and int(p) not in smpl_of:
            p = parents[p]
        found = smpl_of.get(int(p), -1)
        if found != PARENTS[j]:
            got = JOINT_NAMES[found] if found >= 0 else "none (a root)"
            want = JOINT_NAMES[PARENTS[j]] if PARENTS[j] >= 0 else "none (the root)"
            raise SceneError(
                f"{where}: joint '{JOINT_NAMES[j]}' ({joints[k]!r}) has parent {got} but SMPL "
                f"expects {want}; fix the joint paths to follow SMPL's hierarchy"
            )


def _read_betas(prim: Usd.Prim, where: str) -> tuple[np.ndarray, bool]:
    """(10,) float64 betas, zero-padded, and whether ``smpl:betas`` is authored."""
    attr = prim.GetAttribute("smpl:betas")
    value = attr.Get(_EARLIEST) if attr and attr.HasAuthoredValue() else None
    if value is None:
        _log.warning("%s: no smpl:betas authored; using zeros (the mean shape)", where)
        return np.zeros(NUM_BETAS), False
    try:
        betas = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SceneError(
            f"{where}: smpl:betas is {type(value).__name__} {str(value)[:60]!r}, not numbers; "
            f"author float[] smpl:betas with at most {NUM_BETAS} values"
        ) from None
    if betas.size > NUM_BETAS:
        raise SceneError(
            f"{where}: smpl:betas has {betas.size} values; author at most {NUM_BETAS}"
        )
    bad = np.flatnonzero(~np.isfinite(betas))
    if bad.size:
        raise SceneError(f"{where}: smpl:betas[{bad[0]}] is {betas[bad[0]]}; author finite values")
    bad = np.flatnonzero(np.abs(betas) > BETA_MAX)
    if bad.size:
        raise SceneError(
            f"{where}: smpl:betas[{bad[0]}] is {betas[bad[0]]:g}, beyond any body SMPL's shape space "
            f"describes (|beta| <= {BETA_MAX:g}); author betas in standard deviations, as the body model's"
        )
    return np.pad(betas, (0, NUM_BETAS - betas.size)), True


def _read_gender(prim: Usd.Prim, where: str) -> str:
    """``smpl:gender`` token, ``neutral`` when unauthored."""
    attr = prim.GetAttribute("smpl:gender")
    value = attr.Get() if attr else None
    if value is None:
        return "neutral"
    if str(value) not in _GENDERS:
        raise SceneError(
            f"{where}: smpl:gender is {str(value)!r}; valid values are {', '.join(_GENDERS)}"
        )
    return str(value)


# -------------------------------------------------------------------------- motion


def read_motion(stage: Usd.Stage, character: Character, times: np.ndarray) -> Motion:
    """SMPL poses and root positions of a character at each time code.

    A joint's pose is its rotation relative to the rest pose: with ``W_t[j]`` and
    ``W_r[j]`` its world rotations (internal frame, scale removed) at ``t`` and at
    rest, ``G_j = W_t[j] @ W_r[j].T``, the root pose is ``G_0`` and every other
    joint's is ``G_parent.T @ G_j``. For a skeleton whose rest rotations are all
    identity this is exactly its animated local rotations. Joint orientations (bone
    rolls) do not matter; a character standing turned in the world at rest reads as
    pose zero at rest, and ``cloth_usd.core.frames.reorient_poses`` adds that turn.

    Args:
        stage: the stage ``character`` was read from.
        character: from :func:`read_scene`.
        times: (T,) float time codes.

    Returns:
        Motion with (T, 72) axis-angle poses [rad] and (T, 3) pelvis positions [m].

    Raises:
        SceneError: the skeleton cannot be evaluated, or is non-finite at a frame.
    """
    times = _as_times(times)
    prim = _skeleton_prim(stage, character.prim_path)
    where = _where(stage, prim)
    s2i = stage_to_internal(stage)
    idx = character.joint_indices
    query = _skel_query(UsdSkel.Cache(), prim, where)
    rest_skel = _rest_skel_transforms(query, where)
    xf_cache = UsdGeom.XformCache(_EARLIEST)
    rest = s2i @ _local_to_world(xf_cache, prim) @ rest_skel[idx]  # (24, 4, 4)
    with np.errstate(invalid="ignore", over="ignore"):  # non-finite frames are reported below
        posed = s2i @ _posed_world_transforms(query, prim, times, rest_skel, where)[:, idx]  # (T, 24, 4, 4)
    _check_finite(posed, times, where)
    w_rest = _orthonormalize(rest[:, :3, :3])
    w_posed = _orthonormalize(posed[..., :3, :3])
    g = w_posed @ np.swapaxes(w_rest, -1, -2)  # (T, 24, 3, 3)
    local = np.swapaxes(g[:, PARENTS[1:]], -1, -2) @ g[:, 1:]
    rots = np.concatenate([g[:, :1], local], axis=1)
    poses = matrix_to_axis_angle(rots).reshape(len(times), 3 * NUM_JOINTS)
    return Motion(times=times, poses=poses, root_position=posed[:, 0, :3, 3].copy())


def _posed_world_transforms(
    query: UsdSkel.SkeletonQuery,
    prim: Usd.Prim,
    times: np.ndarray,
    rest_skel: np.ndarray,
    where: str,
) -> np.ndarray:
    """(T, J, 4, 4) joint-to-stage-world transforms (column convention) at each time.

    The skeleton's own transforms come from its animation source, or are the rest
    transforms when it has none; the Skeleton prim's local-to-world is applied at t.
    """
    anim = query.GetAnimQuery()
    animated = bool(anim)
    _check_sample_keys([anim.GetPrim()] if animated else [], prim, where)
    anim_joints = len(anim.GetJointOrder()) if animated else 0
    xf_cache = UsdGeom.XformCache()
    num_joints = rest_skel.shape[0]
    out = np.empty((len(times), num_joints, 4, 4))
    for i, t in enumerate(times):
        tc = Usd.TimeCode(float(t))
        xf_cache.SetTime(tc)
        skel = rest_skel
        if animated:
            # UsdSkel falls back to the rest pose (with a warning) when the components
            # disagree in size, so check them first.
            sizes = {len(c) for c in anim.ComputeJointLocalTransformComponents(tc)}
            skel = _row_to_col(query.ComputeJointSkelTransforms(tc)) if sizes == {
                anim_joints} else np.empty((0, 4, 4))
            if skel.shape != rest_skel.shape:
                raise SceneError(
                    f"{where}: UsdSkel could not compute the joint transforms at time code "
                    f"{t:g} from animation <{query.GetAnimQuery().GetPrim().GetPath()}>; "
                    "check that its joints, rotations, translations and scales have one value per joint"
                )
        out[i] = _local_to_world(xf_cache, prim) @ skel
    return out


def _check_sample_keys(anims: list[Usd.Prim], prim: Usd.Prim, where: str) -> None:
    """SceneError for a NaN or infinite time-sample key on the animation or on an xformOp
    of the Skeleton and its ancestors (USD sorts and interpolates them as if finite)."""
    attrs = [a for p in anims for a in p.GetAttributes()]
    p = prim
    while p and not p.IsPseudoRoot():
        attrs.extend(a for a in p.GetAttributes() if a.GetName().startswith("xformOp:"))
        p = p.GetParent()
    for attr in attrs:
        # From the layers: a NaN key breaks the composed attribute's sorted sample map.
        keys = np.asarray([t for spec in attr.GetPropertyStack(_EARLIEST)
                           for t in spec.layer.ListTimeSamplesForPath(spec.path)], dtype=np.float64)
        bad = keys[~np.isfinite(keys)]
        if bad.size:
            raise SceneError(
                f"{where}: {attr.GetPath()} has a time sample at time code {bad[0]:g}, not a finite "
                "time code; remove that sample or give it a real frame number"
            )


def _check_finite(posed: np.ndarray, times: np.ndarray, where: str) -> None:
    """SceneError naming the first time code whose (T, J, 4, 4) transforms are non-finite."""
    bad = np.flatnonzero(~np.isfinite(posed).all(axis=(1, 2, 3)))
    if bad.size:
        raise SceneError(
            f"{where}: joint transforms are not finite at time code {times[bad[0]]:g}; "
            "check the animation's rotations, translations and scales at that frame"
        )


# ------------------------------------------------------------------------ garments


def _read_garment(
    stage: Usd.Stage, prim: Usd.Prim, s2i: np.ndarray, xf_cache: UsdGeom.XformCache
) -> Garment:
    """One Mesh prim with ``cloth:category`` -> Garment; raises GarmentError."""
    where = _where(stage, prim)
    category = _read_choice(prim, "cloth:category", Category, where, required=True)
    tier = _read_choice(prim, "cloth:tier", Tier, where, required=False)
    enabled_attr = prim.GetAttribute("cloth:enabled")
    enabled = enabled_attr.Get() if enabled_attr else None
    points = _read_points(prim, where)
    triangles, face_map = _triangulate(prim, len(points), where)
    to_internal = s2i @ _local_to_world(xf_cache, prim)
    return Garment(
        prim_path=str(prim.GetPath()),
        category=category,
        body_path=_read_body(stage, prim, where),
        enabled=True if enabled is None else bool(enabled),
        tier=tier,
        rest_points=points @ to_internal[:3, :3].T + to_internal[:3, 3],
        triangles=triangles,
        face_map=face_map,
    )


def _read_choice(prim: Usd.Prim, name: str, enum_cls: type, where: str, *, required: bool):
    """A token attribute parsed into ``enum_cls``; None when optional and unauthored."""
    attr = prim.GetAttribute(name)
    value = attr.Get() if attr else None
    valid = ", ".join(e.value for e in enum_cls)
    if value is None:
        if required:
            raise GarmentError(f"{where}: {name} has no value; author one of {valid}")
        return None
    try:
        return enum_cls(str(value))
    except ValueError:
        raise GarmentError(f"{where}: {name} is {str(value)!r}; valid values are {valid}") from None


def _read_body(stage: Usd.Stage, prim: Usd.Prim, where: str) -> str:
    """Path of the Skeleton prim that ``cloth:body`` targets."""
    todo = "author `rel cloth:body = </path/to/Skeleton>` targeting the character's UsdSkel Skeleton"
    rel = prim.GetRelationship("cloth:body")
    targets = rel.GetForwardedTargets() if rel else []
    if not targets:
        raise GarmentError(f"{where}: garment has no cloth:body target; {todo}")
    if len(targets) > 1:
        listed = ", ".join(f"<{t}>" for t in targets)
        raise GarmentError(f"{where}: cloth:body has {len(targets)} targets ({listed}); {todo}")
    body = stage.GetPrimAtPath(targets[0])
    if not body:
        raise GarmentError(f"{where}: cloth:body targets <{targets[0]}>, which does not exist; {todo}")
    if not body.IsA(UsdSkel.Skeleton):
        kind = body.GetTypeName() or "typeless prim"
        raise GarmentError(
            f"{where}: cloth:body targets <{targets[0]}>, a {kind}, not a UsdSkel Skeleton; {todo}"
        )
    return str(targets[0])


def _read_points(prim: Usd.Prim, where: str) -> np.ndarray:
    """(N, 3) float64 default-time points in the prim's own space."""
    value = UsdGeom.Mesh(prim).GetPointsAttr().Get(Usd.TimeCode.Default())
    if value is None or len(value) == 0:
        raise GarmentError(
            f"{where}: garment has no points default value; author the rest-pose points "
            "as the default (non time-sampled) value of points"
        )
    points = np.asarray(value, dtype=np.float64).reshape(-1, 3)
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        value = ", ".join(f"{v:g}" for v in points[bad[0]])
        raise GarmentError(
            f"{where}: points[{bad[0]}] is ({value}), not finite ({bad.size} of {len(points)} "
            "points are NaN or infinite); author finite rest-pose points"
        )
    return points


def _triangulate(prim: Usd.Prim, num_points: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate the mesh faces.

    Returns:
        (M, 3) int64 triangles and (M,) int64 source face of each triangle.
    """
    mesh = UsdGeom.Mesh(prim)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    if counts.size == 0:
        raise GarmentError(f"{where}: garment has no faceVertexCounts; author its faces")
    small = np.flatnonzero(counts < 3)
    if small.size:
        raise GarmentError(
            f"{where}: face {small[0]} has {counts[small[0]]} vertices; every face needs at least 3"
        )
    if counts.sum() != indices.size:
        raise GarmentError(
            f"{where}: faceVertexCounts sum to {counts.sum()} but faceVertexIndices has "
            f"{indices.size} entries; make them agree"
        )
    starts = np.cumsum(counts) - counts
    bad = np.flatnonzero((indices < 0) | (indices >= num_points))
    if bad.size:
        face = int(np.searchsorted(starts, bad[0], side="right") - 1)
        raise GarmentError(
            f"{where}: face {face} uses vertex index {indices[bad[0]]}, outside the "
            f"{num_points} points; fix faceVertexIndices"
        )
    per_face = counts - 2
    face_map = np.repeat(np.arange(counts.size, dtype=np.int64), per_face)
    k = np.arange(face_map.size) - np.repeat(np.cumsum(per_face) - per_face, per_face) + 1
    first = starts[face_map]
    triangles = np.stack([indices[first], indices[first + k], indices[first + k + 1]], axis=1)
    return triangles, face_map


def garment_from_internal(stage: Usd.Stage, garment_path: str | Sdf.Path, times: np.ndarray) -> np.ndarray:
    """Maps from internal-frame points to the garment prim's own space, per time code.

    Args:
        garment_path: path of the garment Mesh prim.
        times: (T,) float time codes.

    Returns:
        (T, 4, 4) float64, column convention: ``local = M[t] @ [p_internal, 1]``;
        the inverse of ``stage_to_internal @ local_to_world(t)``.
    """
    times = _as_times(times)
    prim = stage.GetPrimAtPath(Sdf.Path(str(garment_path)))
    if not prim or not prim.IsA(UsdGeom.Xformable):
        raise GarmentError(f"{_layer(stage)} <{garment_path}>: no garment Mesh prim at this path")
    s2i = stage_to_internal(stage)
    xf_cache = UsdGeom.XformCache()
    forward = np.empty((len(times), 4, 4))
    for i, t in enumerate(times):
        xf_cache.SetTime(Usd.TimeCode(float(t)))
        forward[i] = s2i @ _local_to_world(xf_cache, prim)
    try:
        return np.linalg.inv(forward)
    except np.linalg.LinAlgError:
        raise GarmentError(
            f"{_where(stage, prim)}: its local-to-world transform is singular at some time code "
            f"in [{times.min():g}, {times.max():g}]; remove zero scales"
        ) from None


def garment_points_internal(stage: Usd.Stage, garment_path: str | Sdf.Path, time: float) -> np.ndarray:
    """A garment Mesh's points at one time code, in cloth_usd's internal frame (Y-up metres).

    Args:
        garment_path: path of the garment Mesh prim.
        time: the time code.

    Returns:
        (N, 3) float64.
    """
    pts = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath(garment_path)).GetPointsAttr().Get(float(time)),
                     dtype=np.float64)
    to_internal = np.linalg.inv(garment_from_internal(stage, garment_path, np.asarray([time], dtype=np.float64))[0])
    return pts @ to_internal[:3, :3].T + to_internal[:3, 3]


# ------------------------------------------------------------------------- helpers


def _skel_query(cache: UsdSkel.Cache, prim: Usd.Prim, where: str) -> UsdSkel.SkeletonQuery:
    """A valid SkeletonQuery for a Skeleton prim."""
    query = cache.GetSkelQuery(UsdSkel.Skeleton(prim))
    if not query:
        raise SceneError(f"{where}: UsdSkel cannot evaluate this Skeleton; check its joints and transforms")
    return query


def _rest_skel_transforms(query: UsdSkel.SkeletonQuery, where: str) -> np.ndarray:
    """(J, 4, 4) joint-to-skeleton rest transforms: from restTransforms, else bindTransforms."""
    if query.HasRestPose():
        xforms = _row_to_col(query.ComputeJointSkelTransforms(_EARLIEST, True))
    elif query.HasBindPose():
        xforms = _row_to_col(query.GetJointWorldBindTransforms())
    else:
        xforms = np.empty((0, 4, 4))
    if xforms.shape[0] != len(query.GetJointOrder()):
        raise SceneError(
            f"{where}: Skeleton has neither restTransforms nor bindTransforms with one matrix "
            "per joint; author restTransforms (local) or bindTransforms (skeleton space)"
        )
    if not np.isfinite(xforms).all():
        raise SceneError(
            f"{where}: the Skeleton's rest transforms are not finite; author finite restTransforms"
        )
    return xforms


def _skeleton_prim(stage: Usd.Stage, path: str) -> Usd.Prim:
    """The Skeleton prim at ``path``; SceneError if there is none."""
    prim = stage.GetPrimAtPath(Sdf.Path(path))
    if not prim or not prim.IsA(UsdSkel.Skeleton):
        raise SceneError(f"{_layer(stage)} <{path}>: no UsdSkel Skeleton prim at this path")
    return prim


def _local_to_world(xf_cache: UsdGeom.XformCache, prim: Usd.Prim) -> np.ndarray:
    """(4, 4) float64 local-to-world of ``prim`` at the cache's time, column convention."""
    return np.array(xf_cache.GetLocalToWorldTransform(prim)).T


def _row_to_col(xforms) -> np.ndarray:
    """A Vt.Matrix4dArray (row-vector convention) -> (J, 4, 4) float64 column convention."""
    arr = np.array(xforms, dtype=np.float64).reshape(-1, 4, 4)
    return np.swapaxes(arr, -1, -2)


def _orthonormalize(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> nearest rotations (polar decomposition), removing scale and shear."""
    u, _, vt = np.linalg.svd(m)
    det = np.linalg.det(u @ vt)
    u[..., :, 2] *= np.where(det < 0.0, -1.0, 1.0)[..., None]
    return u @ vt


def _as_times(times) -> np.ndarray:
    """(T,) float64 time codes, validated."""
    arr = np.asarray(times, dtype=np.float64)
    if arr.ndim != 1 or not np.isfinite(arr).all():
        raise ArgumentError(f"times must be a 1-D array of finite time codes, got shape {arr.shape}")
    return arr


def _authored_time(stage: Usd.Stage, key: str, getter) -> float | None:
    """A stage time-code metadatum, or None when the root layer does not author it."""
    return float(getter()) if stage.HasAuthoredMetadata(key) else None


def _layer(stage: Usd.Stage) -> str:
    """The root layer's identifier, for messages."""
    return stage.GetRootLayer().identifier


def _where(stage: Usd.Stage, prim: Usd.Prim) -> str:
    """``file <prim path>``, the prefix of every message about a prim."""
    return f"{_layer(stage)} <{prim.GetPath()}>"


def _tf_reason(exc: Tf.ErrorException) -> str:
    """The quoted reasons in a Tf error, most specific first (USD's generic "Failed to
    open layer" only when there is nothing else)."""
    try:
        text = str(exc)
    except UnicodeDecodeError:  # USD quotes the offending bytes, which may not be UTF-8
        return "the file holds bytes that are not valid UTF-8 text"
    reasons: list[str] = []
    for block in re.split(r"\n\s*Error in ", text):
        m = re.search(r" : '(.*)'\s*$", block, flags=re.DOTALL)
        if m:
            reason = " ".join(m.group(1).split())
            reasons = [r for r in reasons if r not in reason]  # keep the longer (located) copy
            if not any(reason in r for r in reasons):
                reasons.append(reason)
    specific = [r for r in reasons if not r.startswith("Failed to open layer")]
    reasons = specific or reasons
    return "; ".join(reasons) if reasons else text.strip()
