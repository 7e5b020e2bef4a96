"""Which skeleton joint is which SMPL joint: the naming conventions rigs use, and joint maps.

A skeleton's joints are matched by the last element of each joint path (its leaf
name). Every skeleton uses one convention; :func:`match_joints` finds the one that
names all 24 SMPL joints:

- ``smpl``: SMPL's official names (``pelvis``, ``left_hip``, ...), the scene contract's.
- ``smplx``: SMPL-H and SMPL-X as the ``smplx`` package and the Meshcapade add-on name
  them: SMPL's body names, then ``jaw``, eyes and per-finger chains. These models have no
  ``left_hand`` / ``right_hand``: SMPL's hand joint sits at the knuckles and bends the
  four fingers as one, so the middle finger's first joint (``left_middle1``, a child of
  the wrist like SMPL's hand joint) stands in for it and its bend becomes the whole
  hand's. Garments do not reach the hands, so only the body's fingers see the choice.
- ``smpl-fbx``: the SMPL FBX / Unity model, ``m_avg_`` or ``f_avg_`` then ``Pelvis``,
  ``L_Hip``, ...; its ``m_avg_root`` bone above the pelvis is ignored like any extra joint.
- ``meshcapade``: the same names without the prefix, as the Meshcapade Blender add-on
  exports SMPL.
- ``phc``: PHC / SMPLSim (``SMPL_BONE_ORDER_NAMES``), mapped by kinematic position:
  ``Torso`` spine1, ``Spine`` spine2, ``Chest`` spine3, ``L_Toe`` left_foot,
  ``L_Thorax`` left_collar; ``L_Middle1`` stands in for a missing ``L_Hand`` as above.

The official names win when they name all 24 joints; otherwise the conventions that
do must agree on the joints. Anything else takes a :class:`JointMap`, ``{their name:
SMPL name}``, whose entries come before each convention's names (so a map may rename
just a few joints); a skeleton the map does not fit is matched as if there were none.
Extra joints (a root bone, fingers, twist bones) are ignored.
"""

from __future__ import annotations

import json
import tomllib
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from ..errors import ArgumentError
from .smpl import JOINT_NAMES, NUM_JOINTS

__all__ = ["JointNaming", "NAMINGS", "JointMap", "JointMatch", "parse_joint_map", "load_joint_map", "as_joint_map",
           "match_joints"]


@dataclass(frozen=True)
class JointNaming:
    """One convention for naming SMPL's 24 joints."""

    name: str
    """Short name used in messages, e.g. ``smpl-fbx``."""
    description: str
    """Where the names come from."""
    names: tuple[tuple[str, ...], ...]
    """(24,) per SMPL joint in SMPL's order, the leaf names it accepts, preferred first."""
    prefixes: tuple[str, ...] = ("",)
    """Prefixes every name carries (one of them), e.g. ``m_avg_``."""


def _caps(*names: str | tuple[str, ...]) -> tuple[tuple[str, ...], ...]:
    return tuple(n if isinstance(n, tuple) else (n,) for n in names)


_FBX_NAMES = _caps(
    "Pelvis", "L_Hip", "R_Hip", "Spine1", "L_Knee", "R_Knee", "Spine2", "L_Ankle", "R_Ankle", "Spine3",
    "L_Foot", "R_Foot", "Neck", "L_Collar", "R_Collar", "Head", "L_Shoulder", "R_Shoulder", "L_Elbow",
    "R_Elbow", "L_Wrist", "R_Wrist", "L_Hand", "R_Hand",
)

#: The conventions recognised without a joint map, in order of preference.
NAMINGS: tuple[JointNaming, ...] = (
    JointNaming("smpl", "SMPL's official joint names", _caps(*JOINT_NAMES)),
    JointNaming("smplx", "SMPL-H / SMPL-X (smplx package, Meshcapade add-on); hands from left_middle1",
                _caps(*JOINT_NAMES[:22], "left_middle1", "right_middle1")),
    JointNaming("smpl-fbx", "the SMPL FBX / Unity model", _FBX_NAMES, prefixes=("m_avg_", "f_avg_")),
    JointNaming("meshcapade", "the Meshcapade Blender add-on's SMPL export", _FBX_NAMES),
    JointNaming("phc", "PHC / SMPLSim bone names", _caps(
        "Pelvis", "L_Hip", "R_Hip", "Torso", "L_Knee", "R_Knee", "Spine", "L_Ankle", "R_Ankle", "Chest",
        "L_Toe", "R_Toe", "Neck", "L_Thorax", "R_Thorax", "Head", "L_Shoulder", "R_Shoulder", "L_Elbow",
        "R_Elbow", "L_Wrist", "R_Wrist", ("L_Hand", "L_Middle1"), ("R_Hand", "R_Middle1"),
    )),
)

_LISTED = ", ".join(n.name for n in NAMINGS)
_TODO = (f"rename its joints after one convention ({_LISTED}; matched by the last element of each joint "
         "path), pass a joint map (--joint-map FILE, a JSON object {\"their name\": \"SMPL name\"}) "
         "or retarget the motion onto SMPL")


@dataclass(frozen=True)
class JointMap:
    """A user's names for SMPL joints, validated."""

    entries: Mapping[str, int]
    """Joint leaf name -> SMPL joint index (0..23); no two entries share a target."""
    source: str
    """Where the map came from (its file), for messages."""


def parse_joint_map(entries: Mapping[str, str], *, source: str = "joint_map") -> JointMap:
    """Validate ``{their joint name: SMPL joint name}`` into a :class:`JointMap`.

    Raises:
        ArgumentError: not a non-empty mapping of strings, a key is a path rather than
            a leaf name, a value is not an SMPL joint name, or two keys map to the same
            SMPL joint; the message names ``source`` and the entry.
    """
    if not isinstance(entries, Mapping) or not entries:
        raise ArgumentError(f"{source}: expected a non-empty object {{\"their joint name\": \"SMPL joint name\"}}, "
                            f"got {type(entries).__name__} {str(entries)[:60]!r}")
    out: dict[str, int] = {}
    by_target: dict[int, str] = {}
    for key, value in entries.items():
        if not isinstance(key, str) or not key or "/" in key:
            raise ArgumentError(f"{source}: entry {key!r}: keys are joint names (the last element of a "
                                "joint path, e.g. \"Hips\"), not paths")
        if not isinstance(value, str) or value not in JOINT_NAMES:
            raise ArgumentError(f"{source}: entry {key!r}: {value!r} is not an SMPL joint; valid: "
                                f"{', '.join(JOINT_NAMES)}")
        target = JOINT_NAMES.index(value)
        if target in by_target:
            raise ArgumentError(f"{source}: entries {by_target[target]!r} and {key!r} both map to {value!r}; "
                                "each SMPL joint may be the target of one entry")
        by_target[target] = key
        out[key] = target
    return JointMap(entries=out, source=source)


def load_joint_map(path: str | PathLike) -> JointMap:
    """Read a joint map file: a JSON object (or, for ``.toml``, a TOML table) of
    ``their joint name = SMPL joint name`` entries.

    Raises:
        ArgumentError: the file is unreadable or malformed, a key appears twice, or an
            entry is invalid (see :func:`parse_joint_map`); the message names the file.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ArgumentError(f"{path}: cannot read the joint map ({exc.strerror})") from None
    try:
        if path.suffix == ".toml":
            data = tomllib.loads(text)
        else:
            data = json.loads(text, object_pairs_hook=lambda pairs: _unique_keys(pairs, path))
    except (ValueError, tomllib.TOMLDecodeError) as exc:
        kind = "TOML" if path.suffix == ".toml" else "JSON"
        raise ArgumentError(f"{path}: the joint map is not valid {kind} ({exc})") from None
    return parse_joint_map(data, source=str(path))


def as_joint_map(value: JointMap | Mapping[str, str] | str | PathLike | None) -> JointMap | None:
    """A :class:`JointMap` from a file path, a ``{their name: SMPL name}`` mapping, a
    JointMap or None (no map); raises ArgumentError as :func:`load_joint_map` does."""
    if value is None or isinstance(value, JointMap):
        return value
    if isinstance(value, Mapping):
        return parse_joint_map(value)
    return load_joint_map(value)


def _unique_keys(pairs: list[tuple[str, object]], path: Path) -> dict:
    """A JSON object's dict; ArgumentError on a repeated key (json would keep the last)."""
    seen: dict[str, object] = {}
    for key, value in pairs:
        if key in seen:
            raise ArgumentError(f"{path}: entry {key!r} appears twice; give each joint name once")
        seen[key] = value
    return seen


@dataclass(frozen=True)
class JointMatch:
    """How a skeleton's joints name SMPL's, from :func:`match_joints`."""

    naming: str
    """The convention that matched, or came closest (e.g. ``smpl-fbx``; ``smpl + map.json``
    when a joint map's entries come first, the map's source when it names all 24)."""
    indices: np.ndarray
    """(24,) int64: per SMPL joint, its index in the skeleton's joints; -1 where none."""
    missing: tuple[str, ...]
    """Names (as ``naming`` spells them) of the SMPL joints not found; empty when all are."""
    problem: str | None
    """None when the joints name SMPL's unambiguously; else one sentence: why not, what to do."""


@dataclass(frozen=True)
class _Candidate:
    naming: str
    lookup: dict[str, tuple[int, int]]  # leaf name -> (SMPL joint, rank: lower is preferred)
    spelled: tuple[str, ...]  # (24,) the preferred name of each SMPL joint, for messages


def match_joints(joints: Sequence[str], joint_map: JointMap | None = None) -> JointMatch:
    """Match a skeleton's joint paths to SMPL's 24 joints.

    The joint map's entries, put before each convention's names, are tried first;
    then the conventions alone (so a map for one rig leaves the stage's other rigs
    as they were). In each round the official names (or the map with them) win when
    they name all 24 joints; otherwise the complete conventions must agree.

    Args:
        joints: the skeleton's joint paths (``"pelvis/left_hip"``), in its order.
        joint_map: optional names that come before each convention's.
    """
    leaves = [j.rstrip("/").rsplit("/", 1)[-1] for j in joints]
    rounds = ([_candidates(leaves, joint_map)] if joint_map else []) + [_candidates(leaves, None)]
    tried = []
    for candidates in rounds:
        results = [(cand, _found(cand, leaves)) for cand in candidates]
        tried.extend(results)
        complete = [(c, f) for c, f in results if len(f) == NUM_JOINTS]
        if not complete:
            continue
        cand, found = complete[0]
        if cand is not candidates[0] and len({tuple(_indices(f)) for _, f in complete}) > 1:
            names = ", ".join(c.naming for c, _ in complete)
            problem = (f"its joint names fit several conventions ({names}) that pick different joints; "
                       f"pass a joint map (--joint-map FILE) naming all {NUM_JOINTS} SMPL joints")
        else:
            problem = _duplicate(cand, found, joints)
        return JointMatch(naming=cand.naming, indices=_indices(found), missing=(), problem=problem)
    cand, found = max(tried, key=lambda r: len(r[1]))  # the first of the best
    missing = tuple(cand.spelled[j] for j in range(NUM_JOINTS) if j not in found)
    problem = (f"not an SMPL skeleton (closest naming: {cand.naming}, lacks SMPL joint(s) "
               f"{', '.join(missing)}: {len(found)} of {NUM_JOINTS} found); {_TODO}")
    return JointMatch(naming=cand.naming, indices=_indices(found), missing=missing, problem=problem)


def _found(cand: _Candidate, leaves: list[str]) -> dict[int, list[tuple[int, int]]]:
    """SMPL joint -> sorted (rank, joint index) of every joint that names it."""
    found: dict[int, list[tuple[int, int]]] = {}
    for i, leaf in enumerate(leaves):
        if leaf in cand.lookup:
            smpl, rank = cand.lookup[leaf]
            found.setdefault(smpl, []).append((rank, i))
    return {s: sorted(v) for s, v in found.items()}


def _candidates(leaves: list[str], joint_map: JointMap | None) -> list[_Candidate]:
    """One candidate per convention, with the joint map's entries first (one candidate,
    the map alone, when it names all 24 joints)."""
    mapped = dict(joint_map.entries) if joint_map else {}
    by_target = {t: k for k, t in mapped.items()}
    if len(by_target) == NUM_JOINTS:
        return [_Candidate(joint_map.source, {k: (t, -1) for k, t in mapped.items()},
                           tuple(by_target[j] for j in range(NUM_JOINTS)))]
    out = []
    for naming in NAMINGS:
        prefix = _prefix(naming, leaves)
        lookup = {f"{p}{name}": (j, rank) for j, alts in enumerate(naming.names) if j not in by_target
                  for rank, name in enumerate(alts) for p in naming.prefixes}
        lookup.update({k: (t, -1) for k, t in mapped.items()})
        spelled = tuple(by_target.get(j, f"{prefix}{alts[0]}") for j, alts in enumerate(naming.names))
        label = f"{naming.name} + {joint_map.source}" if joint_map else naming.name
        out.append(_Candidate(label, lookup, spelled))
    return out


def _prefix(naming: JointNaming, leaves: list[str]) -> str:
    """The prefix most of the skeleton's joints carry (the first one if none does)."""
    if len(naming.prefixes) == 1:
        return naming.prefixes[0]
    counts = Counter(p for leaf in leaves for p in naming.prefixes if leaf.startswith(p))
    return max(naming.prefixes, key=lambda p: counts[p])


def _indices(found: dict[int, list[tuple[int, int]]]) -> np.ndarray:
    """(24,) int64: the preferred joint per SMPL joint, -1 where none."""
    return np.array([found[j][0][1] if j in found else -1 for j in range(NUM_JOINTS)], dtype=np.int64)


def _duplicate(cand: _Candidate, found: dict[int, list[tuple[int, int]]], joints: Sequence[str]) -> str | None:
    """A sentence about the first SMPL joint that two joints name equally well, else None."""
    for j in range(NUM_JOINTS):
        hits = found[j]
        if len(hits) > 1 and hits[0][0] == hits[1][0]:
            return (f"SMPL joint '{JOINT_NAMES[j]}' appears twice ({joints[hits[0][1]]!r} and "
                    f"{joints[hits[1][1]]!r}, named as {cand.naming}); rename one so each SMPL joint "
                    "name is unique")
    return None
