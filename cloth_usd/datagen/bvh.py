"""BVH motion capture: a reader, and a retargeter onto the 24 SMPL joints.

Shape letters: T frames, J BVH joints, C channels. A BVH joint's local transform is
``translate(offset) @ R`` with ``R`` the product of its rotation channels in the order
they are listed (``Zrotation Xrotation Yrotation`` gives ``Rz @ Rx @ Ry``, angles in
degrees); a joint with position channels takes them as its local translation instead
of its OFFSET (as Blender's importer does).

Retargeting works on world-space rotations, so the two skeletons need not share bone
lengths, joint counts or local axes. Each mapped bone's direction in the reference
posture (the BVH rest, every channel zero, unless ``reference_frame`` names a frame) is
turned onto the same bone's direction in SMPL's T-pose, so a rig whose rest is a T-pose,
an A-pose or the arms hanging retargets the same way: at every frame each mapped SMPL
bone points where the BVH bone points (after the ``up_axis`` conversion), and its twist
follows the BVH joint's. ``align_rest=False`` keeps the older rule, which takes the
reference posture to BE SMPL's T-pose (exact joint rotations for rigs built like SMPL).

Known rigs (:data:`BVH_RIGS`, told apart by :func:`detect_rig`): CMU's cgspeed
conversions with MotionBuilder names (``cmu-mb``: root ``Hips``, 31 joints) and Daz
names (``cmu-daz``: root ``hip``, 43 joints), Mixamo (``mixamo``, any ``mixamorig:``
namespace) and BVH exported from SMPL (``smpl``).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.rotations import matrix_to_axis_angle
from ..core.smpl import JOINT_NAMES, NUM_JOINTS, PARENTS
from ..errors import ArgumentError
from .motion import MotionFileError, blend_from_rest, resample

__all__ = [
    "Bvh",
    "BvhError",
    "BVH_RIGS",
    "DEFAULT_BVH_MAPPING",
    "REQUIRED_JOINTS",
    "SMPL_NAMED_BVH_MAPPING",
    "bvh_forward_kinematics",
    "detect_rig",
    "detect_scale",
    "detect_up_axis",
    "load_bvh",
    "parse_bvh",
    "synthetic_first_frame",
    "read_bvh",
    "read_rigged_bvh",
    "retarget_bvh",
    "rig_mapping",
    "trim_bvh",
]

log = logging.getLogger(__name__)

_AXES = ("X", "Y", "Z")


class BvhError(MotionFileError):
    """A BVH file is malformed, or lacks a joint the retargeting needs."""


@dataclass(frozen=True)
class Bvh:
    """A parsed BVH file: the hierarchy and the raw channel values."""

    names: tuple[str, ...]
    """(J,) joint names, in file order (a parent precedes its children)."""
    parents: np.ndarray
    """(J,) int64 parent index of each joint; -1 for a root."""
    offsets: np.ndarray
    """(J, 3) float64 OFFSET of each joint from its parent [file units]."""
    channels: tuple[tuple[str, ...], ...]
    """(J,) channel names of each joint, in file order (e.g. ``"Zrotation"``)."""
    end_sites: np.ndarray
    """(E, 3) float64 End Site offsets from their parent joint [file units]."""
    end_site_parents: np.ndarray
    """(E,) int64 joint index each End Site hangs from."""
    frame_time: float
    """Seconds per frame [s]."""
    motion: np.ndarray
    """(T, C) float64 channel values, joints' channels concatenated in file order
    (positions in file units, rotations in degrees)."""
    source: str = "<string>"
    """Where the text came from (a file path), for messages."""

    @property
    def num_frames(self) -> int:
        """T."""
        return int(self.motion.shape[0])

    @property
    def fps(self) -> float:
        """Frame rate [1/s]."""
        return 1.0 / self.frame_time

    def channel_start(self) -> np.ndarray:
        """(J,) int64 column of each joint's first channel in :attr:`motion`."""
        counts = np.array([len(c) for c in self.channels], dtype=np.int64)
        return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


# --------------------------------------------------------------------------- reading
def read_bvh(path: str | Path) -> Bvh:
    """Read a BVH file. Raises :class:`BvhError` naming the file (and line) at fault."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise BvhError(f"{path}: cannot read BVH file: {exc.strerror or exc}") from exc
    return parse_bvh(text, source=str(path))


_CHANNEL_RE = re.compile(r"^([XYZ])(position|rotation)$", re.IGNORECASE)


def parse_bvh(text: str, *, source: str = "<string>") -> Bvh:
    """Parse BVH text (HIERARCHY and MOTION sections); ``source`` names it in errors."""
    tokens = [(tok, i + 1) for i, line in enumerate(text.splitlines()) for tok in line.split()]
    pos = 0

    def fail(msg: str, line: int | None = None) -> BvhError:
        where = f"{source}:{line}" if line is not None else source
        return BvhError(f"{where}: {msg}")

    def take(expected: str | None = None, what: str | None = None) -> tuple[str, int]:
        """The next token; ``expected`` is a literal it must equal, ``what`` describes it."""
        nonlocal pos
        if pos >= len(tokens):
            raise fail(f"unexpected end of file (expected {expected or what or 'more data'})",
                       tokens[-1][1] if tokens else None)
        tok, line = tokens[pos]
        pos += 1
        if expected is not None and tok.upper() != expected.upper():
            raise fail(f"expected {expected!r}, found {tok!r}", line)
        return tok, line

    def number(what: str) -> float:
        tok, line = take()
        try:
            return float(tok)
        except ValueError:
            raise fail(f"expected a number for {what}, found {tok!r}", line) from None

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_sites: list[list[float]] = []
    end_parents: list[int] = []

    def joint_body() -> None:  # after "ROOT name" / "JOINT name"
        index = len(names) - 1
        take("{")
        while True:
            tok, line = take(what="'}' or a joint field")
            key = tok.upper()
            if key == "}":
                return
            if key == "OFFSET":
                offsets[index] = [number("OFFSET") for _ in range(3)]
            elif key == "CHANNELS":
                count_tok, cline = take()
                if not count_tok.isdigit():
                    raise fail(f"CHANNELS count must be an integer, found {count_tok!r}", cline)
                names_here = []
                for _ in range(int(count_tok)):
                    ch, chline = take()
                    m = _CHANNEL_RE.match(ch)
                    if m is None:
                        raise fail(f"joint {names[index]!r}: unknown channel {ch!r} "
                                   "(valid: X/Y/Z position, X/Y/Z rotation)", chline)
                    names_here.append(m.group(1).upper() + m.group(2).lower())
                channels[index] = tuple(names_here)
            elif key == "JOINT":
                child, _ = take(what="a joint name")
                _new_joint(child, index)
                joint_body()
            elif key == "END":
                take("Site")
                take("{")
                take("OFFSET")
                end_sites.append([number("End Site OFFSET") for _ in range(3)])
                end_parents.append(index)
                take("}")
            else:
                raise fail(f"joint {names[index]!r}: unexpected {tok!r} "
                           "(valid: OFFSET, CHANNELS, JOINT, End Site, '}')", line)

    def _new_joint(name: str, parent: int) -> None:
        names.append(name)
        parents.append(parent)
        offsets.append([0.0, 0.0, 0.0])
        channels.append(())

    take("HIERARCHY")
    while pos < len(tokens) and tokens[pos][0].upper() == "ROOT":
        take()
        name, _ = take(what="a joint name")
        _new_joint(name, -1)
        joint_body()
    if not names:
        line = tokens[pos][1] if pos < len(tokens) else None
        raise fail("no ROOT joint in HIERARCHY", line)
    take("MOTION")
    take("Frames:")
    frames_tok, fline = take(what="a frame count")
    if not frames_tok.isdigit():
        raise fail(f"Frames: must be a non-negative integer, found {frames_tok!r}", fline)
    take("Frame")
    take("Time:")
    frame_time = number("Frame Time")
    if not frame_time > 0:
        raise fail(f"Frame Time must be > 0, got {frame_time}")
    num_frames = int(frames_tok)
    num_channels = sum(len(c) for c in channels)
    values = tokens[pos:]
    if len(values) != num_frames * num_channels:
        raise fail(f"MOTION holds {len(values)} values, expected {num_frames} frames x "
                   f"{num_channels} channels = {num_frames * num_channels}")
    try:
        motion = np.array([float(v) for v, _ in values], dtype=np.float64)
    except ValueError:
        bad = next((v, ln) for v, ln in values if not _is_float(v))
        raise fail(f"MOTION value {bad[0]!r} is not a number", bad[1]) from None
    if not np.all(np.isfinite(motion)):
        raise fail("MOTION holds non-finite values")
    return Bvh(
        names=tuple(names),
        parents=np.array(parents, dtype=np.int64),
        offsets=np.array(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(channels),
        end_sites=np.array(end_sites, dtype=np.float64).reshape(-1, 3),
        end_site_parents=np.array(end_parents, dtype=np.int64),
        frame_time=frame_time,
        motion=motion.reshape(num_frames, num_channels),
        source=source,
    )


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------- kinematics
def _local_transforms(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """(T, J, 3, 3) local rotations and (T, J, 3) local translations [file units]."""
    n, num_joints = bvh.num_frames, len(bvh.names)
    rot = np.broadcast_to(np.eye(3), (n, num_joints, 3, 3)).copy()
    trans = np.broadcast_to(bvh.offsets, (n, num_joints, 3)).copy()
    for j, (start, chans) in enumerate(zip(bvh.channel_start(), bvh.channels)):
        order = "".join(c[0] for c in chans if c.endswith("rotation"))
        cols = [start + k for k, c in enumerate(chans) if c.endswith("rotation")]
        if order and n:
            rot[:, j] = Rotation.from_euler(order, bvh.motion[:, cols], degrees=True).as_matrix()
        for k, c in enumerate(chans):
            if c.endswith("position"):
                trans[:, j, _AXES.index(c[0])] = bvh.motion[:, start + k]
    return rot, trans


def bvh_forward_kinematics(bvh: Bvh, *, rest: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """World rotations and positions of every BVH joint, in the file's axes and units.

    Args:
        rest: if True, the rest posture (every channel zero; OFFSETs only), one frame.
    Returns:
        ``(rotations (T, J, 3, 3), positions (T, J, 3) [file units])``; T = 1 for ``rest``.
    """
    if rest:
        num_joints = len(bvh.names)
        rot = np.broadcast_to(np.eye(3), (1, num_joints, 3, 3)).copy()
        loc = bvh.offsets[None].copy()
    else:
        rot, loc = _local_transforms(bvh)
    world_rot = np.empty_like(rot)
    world_pos = np.empty_like(loc)
    for j, p in enumerate(bvh.parents):
        if p < 0:
            world_rot[:, j], world_pos[:, j] = rot[:, j], loc[:, j]
        else:
            world_rot[:, j] = world_rot[:, p] @ rot[:, j]
            world_pos[:, j] = world_pos[:, p] + np.einsum("tab,tb->ta", world_rot[:, p], loc[:, j])
    return world_rot, world_pos


#: Length units a BVH may be written in, [m] per unit. "cmu" is the CMU mocap unit of the
#: cgspeed conversions (1/0.45 inch).
_UNITS = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.0254 / 0.45}
#: The rest skeleton's largest bounding-box side (joints and End Sites) of an adult [m]:
#: height in a T-pose, roughly equal to the arm span.
_TYPICAL_EXTENT_M = 1.65


def detect_scale(bvh: Bvh) -> float:
    """Guess the file's length unit from its rest skeleton's size [m per file unit].

    Takes the largest side of the rest skeleton's bounding box (height or arm span,
    which for people are close) and picks, among m, dm, cm, mm, inch and CMU units, the
    unit that makes it closest (in ratio) to an adult's 1.65 m. Snapping to a unit
    rather than normalising keeps children and tall people their size.
    """
    _, pos = bvh_forward_kinematics(bvh, rest=True)
    points = pos[0]
    if len(bvh.end_sites):
        ends = points[bvh.end_site_parents] + bvh.end_sites  # rest: world rotations are I
        points = np.concatenate([points, ends])
    extent = float(np.max(np.ptp(points, axis=0)))
    if not extent > 0:
        raise BvhError(f"{bvh.source}: the rest skeleton has zero size; pass scale= explicitly")
    unit = min(_UNITS, key=lambda u: abs(np.log(extent * _UNITS[u] / _TYPICAL_EXTENT_M)))
    log.info("%s: rest skeleton spans %.4g units; reading them as %s", bvh.source, extent, unit)
    return _UNITS[unit]


# --------------------------------------------------------------------------- mapping
def _mirror(name: str) -> str:
    """A left-side (normalised) joint name -> its right-side twin."""
    if name.startswith("left"):
        return "right" + name[4:]
    if name.endswith("_l"):
        return name[:-2] + "_r"
    if name.startswith("l_"):
        return "r_" + name[2:]
    if name.startswith("l"):
        return "r" + name[1:]
    raise ValueError(name)


_LEFT_ALIASES = {  # normalised BVH names (lower case, namespace stripped) -> SMPL joint
    "left_hip": ("leftupleg", "lefthip", "leftthigh", "leftupperleg", "lthigh", "l_thigh", "thigh_l",
                 "upperleg_l"),
    "left_knee": ("leftleg", "leftknee", "leftshin", "leftlowerleg", "lshin", "l_calf", "calf_l",
                  "lowerleg_l"),
    "left_ankle": ("leftfoot", "leftankle", "lfoot", "l_foot", "foot_l"),
    "left_foot": ("lefttoebase", "lefttoe", "lefttoes", "ltoe", "l_toe", "toe_l", "ball_l"),
    "left_collar": ("leftshoulder", "leftcollar", "leftclavicle", "lcollar", "l_clavicle", "clavicle_l"),
    "left_shoulder": ("leftarm", "leftupperarm", "leftuparm", "lshldr", "l_upperarm", "upperarm_l"),
    "left_elbow": ("leftforearm", "leftlowerarm", "leftelbow", "lforearm", "l_forearm", "lowerarm_l"),
    "left_wrist": ("lefthand", "leftwrist", "lhand", "l_hand", "hand_l"),
    "left_hand": ("lefthandmiddle1", "leftfingerbase", "lefthandindex1", "middle_01_l", "lmid1"),
}
_MID_ALIASES = {
    "pelvis": ("hips", "hip", "pelvis"),
    "spine1": ("lowerback", "abdomen", "spine", "spine_01"),
    "spine2": ("spine1", "spine_02"),
    "spine3": ("spine2", "chest", "upperchest", "spine_03"),
    "neck": ("neck", "neck_01"),
    "head": ("head",),
}


def _build_default_mapping() -> dict[str, str]:
    table: dict[str, str] = {}
    for smpl, names in _MID_ALIASES.items():
        table.update(dict.fromkeys(names, smpl))
    for smpl, names in _LEFT_ALIASES.items():
        table.update(dict.fromkeys(names, smpl))
        table.update(dict.fromkeys((_mirror(n) for n in names), "right_" + smpl[5:]))
    return table


#: BVH joint name (case-insensitive, namespace such as ``mixamorig:`` ignored) -> SMPL
#: joint, for the common CMU / Mixamo / Truebones / Poser / Unreal naming. Where several
#: BVH joints map to one SMPL joint (CMU's LowerBack and Spine), the first in file order wins.
DEFAULT_BVH_MAPPING: Mapping[str, str] = _build_default_mapping()

#: The same for BVH files exported from SMPL itself (``Pelvis``, ``L_Hip``, ``Spine1``...).
SMPL_NAMED_BVH_MAPPING: Mapping[str, str] = {
    **{n: n for n in JOINT_NAMES},
    **{("l_" + n[5:] if n.startswith("left_") else "r_" + n[6:]): n
       for n in JOINT_NAMES if n.startswith(("left_", "right_"))},
}

#: SMPL joints a BVH must provide; without them the garment's motion would be wrong.
REQUIRED_JOINTS: tuple[str, ...] = ("pelvis", "left_hip", "right_hip", "left_knee", "right_knee",
                                    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow")


def _rig(mid: Mapping[str, str], left: Mapping[str, str], right_of) -> dict[str, str]:
    """A rig's table from its middle joints and its left side (the right side mirrored)."""
    table = dict(mid)
    for name, smpl in left.items():
        table[name] = smpl
        table[right_of(name)] = "right_" + smpl[5:]
    return table


def _left_to_right(name: str) -> str:
    return "Right" + name[4:]


#: The BVH rigs recognised without a joint map: rig name -> {BVH joint: SMPL joint}.
#: ``cmu-mb``: the cgspeed MotionBuilder-friendly conversion of the CMU database (root
#: ``Hips``, 31 joints). Its ``LeftShoulder`` is CMU's clavicle (``lclavicle``: it sits
#: on the chest, its bone runs to ``LeftArm``, the shoulder) and ``LeftArm`` the upper
#: arm; ``LHipJoint``, ``Neck1`` and the finger joints are extra. ``cmu-daz``: the
#: Daz-friendly conversion (root ``hip``, 43 joints; ``lButtock``, eyes and fingers
#: extra; no toe joint). ``mixamo``: Mixamo's names, with or without the ``mixamorig:``
#: namespace. ``smpl``: BVH exported from SMPL (:data:`SMPL_NAMED_BVH_MAPPING`).
BVH_RIGS: Mapping[str, Mapping[str, str]] = {
    "cmu-mb": _rig(
        {"Hips": "pelvis", "LowerBack": "spine1", "Spine": "spine2", "Spine1": "spine3", "Neck": "neck",
         "Head": "head"},
        {"LeftUpLeg": "left_hip", "LeftLeg": "left_knee", "LeftFoot": "left_ankle", "LeftToeBase": "left_foot",
         "LeftShoulder": "left_collar", "LeftArm": "left_shoulder", "LeftForeArm": "left_elbow",
         "LeftHand": "left_wrist", "LeftFingerBase": "left_hand"}, _left_to_right),
    "cmu-daz": _rig(
        {"hip": "pelvis", "abdomen": "spine1", "chest": "spine3", "neck": "neck", "head": "head"},
        {"lThigh": "left_hip", "lShin": "left_knee", "lFoot": "left_ankle", "lCollar": "left_collar",
         "lShldr": "left_shoulder", "lForeArm": "left_elbow", "lHand": "left_wrist", "lMid1": "left_hand"},
        lambda n: "r" + n[1:]),
    "mixamo": _rig(
        {"Hips": "pelvis", "Spine": "spine1", "Spine1": "spine2", "Spine2": "spine3", "Neck": "neck",
         "Head": "head"},
        {"LeftUpLeg": "left_hip", "LeftLeg": "left_knee", "LeftFoot": "left_ankle", "LeftToeBase": "left_foot",
         "LeftShoulder": "left_collar", "LeftArm": "left_shoulder", "LeftForeArm": "left_elbow",
         "LeftHand": "left_wrist", "LeftHandMiddle1": "left_hand"}, _left_to_right),
    "smpl": SMPL_NAMED_BVH_MAPPING,
}

#: Joints (normalised names) whose presence tells a rig apart from the others.
_RIG_SIGNATURES = {
    "cmu-mb": ("lowerback", "lhipjoint", "neck1"),
    "cmu-daz": ("abdomen", "lshldr", "lbuttock"),
    "mixamo": ("spine2", "leftarm", "leftupleg"),
    "smpl": ("pelvis", "l_hip", "l_shoulder"),
}


def _normalise(name: str) -> str:
    return re.split(r"[:|]", name)[-1].strip().lower()


def detect_rig(bvh: Bvh) -> str | None:
    """The name of the :data:`BVH_RIGS` rig the file's joint names follow, or None.

    A rig matches when the file has its signature joints and every joint of
    :data:`REQUIRED_JOINTS` that the rig names; the first match in :data:`BVH_RIGS`
    order wins (``cmu-mb`` before ``mixamo``, which share most names).
    """
    names = {_normalise(n) for n in bvh.names}
    for rig, table in BVH_RIGS.items():
        required = [k for k, v in table.items() if v in REQUIRED_JOINTS]
        if all(n in names for n in _RIG_SIGNATURES[rig]) and all(_normalise(k) in names for k in required):
            return rig
    return None


def rig_mapping(bvh: Bvh, joint_map: Mapping[str, str] | None = None) -> tuple[str | None, dict[str, str]]:
    """The BVH joint -> SMPL joint table for a file: its rig's, overridden by ``joint_map``.

    Entries of ``joint_map`` replace the rig's entries for the same SMPL joints, so a map
    may rename a few joints and let the rig name the rest; without a recognised rig the
    map is used alone.

    Returns:
        ``(rig name or None, mapping)``; the mapping is empty when there is neither.
    """
    rig = detect_rig(bvh)
    table = dict(BVH_RIGS[rig]) if rig else {}
    if joint_map:
        replaced = set(joint_map.values())
        table = {k: v for k, v in table.items() if v not in replaced}
        table.update(joint_map)
    return rig, table


def trim_bvh(bvh: Bvh, start: int, stop: int) -> Bvh:
    """The file's frames ``start..stop`` (0-based, both included) as a new :class:`Bvh`.

    Raises:
        ArgumentError: the range is empty or outside the file's frames.
    """
    if not 0 <= start <= stop < bvh.num_frames:
        raise ArgumentError(f"frames {start}:{stop} are outside {bvh.source}'s frames 0:{bvh.num_frames - 1}")
    return replace(bvh, motion=bvh.motion[start:stop + 1].copy())


def synthetic_first_frame(bvh: Bvh, rig: str | None) -> bool:
    """True for a CMU conversion by cgspeed whose frame 0 is the T-pose it prepends to every
    take (the root unturned, every joint near its rest), not captured motion."""
    if rig not in ("cmu-mb", "cmu-daz") or bvh.num_frames < 2:
        return False
    root = [k for k, c in enumerate(bvh.channels[0]) if c.endswith("rotation")]
    return bool(np.all(bvh.motion[0, root] == 0.0) and np.abs(bvh.motion[0, len(bvh.channels[0]):]).max() < 30.0)


def read_rigged_bvh(path: str | Path, joint_map: Mapping[str, str] | None = None, *, hint: str = ""
                    ) -> tuple[Bvh, str | None, dict[str, str], int]:
    """A BVH file read with its joint table (:func:`rig_mapping`) and its first captured frame.

    Returns:
        ``(bvh, rig name or None, mapping, first)``: ``first`` is 1 past a CMU conversion's
        synthetic T-pose frame (:func:`synthetic_first_frame`), else 0.
    Raises:
        MotionFileError: the file is unreadable, or its joints follow no known rig and
            ``joint_map`` maps none (the line names the file and ends with ``hint``).
    """
    bvh = read_bvh(path)
    rig, mapping = rig_mapping(bvh, joint_map)
    if not mapping:
        raise MotionFileError(f"{path}: its joints ({', '.join(bvh.names[:8])}, ...) follow no known BVH rig "
                              f"(known: {', '.join(BVH_RIGS)}){hint}")
    return bvh, rig, mapping, 1 if synthetic_first_frame(bvh, rig) else 0


def _resolve_mapping(bvh: Bvh, mapping: Mapping[str, str] | None) -> dict[int, int]:
    """SMPL joint index -> BVH joint index."""
    if mapping is None:
        rig = detect_rig(bvh)
        if rig is not None:
            mapping = BVH_RIGS[rig]
        else:
            tables = (DEFAULT_BVH_MAPPING, SMPL_NAMED_BVH_MAPPING)
            hits = [sum(_normalise(n) in t for n in bvh.names) for t in tables]
            mapping = tables[int(np.argmax(hits))]
    table = {}
    for bvh_name, smpl_name in mapping.items():
        if smpl_name not in JOINT_NAMES:
            raise ArgumentError(f"mapping[{bvh_name!r}] = {smpl_name!r} is not an SMPL joint; "
                                f"valid: {', '.join(JOINT_NAMES)}")
        table[_normalise(bvh_name)] = JOINT_NAMES.index(smpl_name)
    found: dict[int, int] = {}
    for b, name in enumerate(bvh.names):
        s = table.get(_normalise(name))
        if s is not None and s not in found:
            found[s] = b
    return found


# --------------------------------------------------------------------------- retargeting
_UP_CONVERSION = {
    "Y": np.eye(3),
    "Z": Rotation.from_euler("x", -90, degrees=True).as_matrix(),  # Z up, -Y forward -> Y up, +Z forward
}


def retarget_bvh(
    bvh: Bvh,
    *,
    mapping: Mapping[str, str] | None = None,
    fps: float | None = None,
    up_axis: str | None = "Y",
    scale: float | None = None,
    reference_frame: int | None = None,
    blend_seconds: float = 0.5,
    required: Iterable[str] = REQUIRED_JOINTS,
    align_rest: bool = True,
    smpl_joints: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Retarget a BVH motion onto the 24 SMPL joints.

    For each mapped joint, SMPL's world rotation is ``C G(t) G_ref^-1 C^-1 A``: the BVH
    world rotation at frame t relative to the reference posture, with C the up-axis
    conversion, after ``A``, the rest alignment. ``A`` turns SMPL's T-pose bone (from
    the joint to its mapped SMPL child) onto the BVH bone in the reference posture;
    a joint with several children (pelvis, chest) takes the smallest rotation that turns
    its left-right axis (hip to hip, collar to collar) onto the BVH's, keeping the
    reference posture's pitch (least squares over all its bones where no left-right pair
    is mapped), a joint with none its parent's. A joint with one child
    then gets the smallest extra turn that points its bone exactly along the BVH bone
    at frame t (BVH joints between the two mapped ones, such as CMU's ``Neck1``, bend
    it too). SMPL local rotations follow through SMPL's parents; unmapped SMPL joints
    keep their parent's world rotation (identity local rotation). With
    ``align_rest=False``, ``A`` is the identity and nothing is corrected: the
    reference posture must be SMPL's T-pose (a warning says when its arm is not).

    Args:
        bvh: a parsed file (:func:`read_bvh`).
        mapping: BVH joint name -> SMPL joint name; None picks whichever of
            :data:`DEFAULT_BVH_MAPPING` and :data:`SMPL_NAMED_BVH_MAPPING` maps more joints.
            To extend the default: ``{**DEFAULT_BVH_MAPPING, "MyHip": "pelvis"}``.
        fps: output frame rate [1/s]; None keeps the file's.
        up_axis: the file's up axis, ``"Y"`` or ``"Z"``; None detects it
            (:func:`detect_up_axis`). The facing direction does not matter.
        scale: metres per file unit; None guesses it (:func:`detect_scale`).
        reference_frame: the frame whose posture is aligned to SMPL's T-pose; None
            uses the BVH rest posture (every channel zero).
        blend_seconds: ease-in from the SMPL rest pose [s]; 0 keeps the motion as is.
        required: SMPL joints that must be mapped.
        align_rest: align each bone's reference direction to SMPL's T-pose (above).
        smpl_joints: (24, 3) float SMPL rest joint positions [m] whose T-pose bones
            the alignment aims at (the body's ``J(betas)``); None uses the embedded
            model's mean shape.
    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``: the root offset is
        the hips' displacement from frame 0, in SMPL's axes.
    Raises:
        BvhError: a required joint is not in the file (the message names file and joint).
        ArgumentError: a bad ``up_axis``, ``scale``, ``fps``, ``reference_frame`` or mapping.
    """
    up = None if up_axis is None else up_axis.upper()
    if up is not None and up not in _UP_CONVERSION:
        raise ArgumentError(f"up_axis must be one of {', '.join(_UP_CONVERSION)}, got {up_axis!r}")
    if scale is not None and not scale > 0:
        raise ArgumentError(f"scale must be > 0 (metres per file unit), got {scale}")
    if fps is not None and not fps > 0:
        raise ArgumentError(f"fps must be > 0, got {fps}")
    if bvh.num_frames == 0:
        raise BvhError(f"{bvh.source}: the file has no frames")
    if reference_frame is not None and not -bvh.num_frames <= reference_frame < bvh.num_frames:
        raise ArgumentError(f"reference_frame {reference_frame} is outside the file's "
                            f"{bvh.num_frames} frames ({bvh.source})")
    found = _resolve_mapping(bvh, mapping)
    missing = [name for name in required if JOINT_NAMES.index(name) not in found]
    if missing:
        wanted = missing[0]
        aliases = sorted(k for k, v in (mapping or DEFAULT_BVH_MAPPING).items() if v == wanted)
        raise BvhError(f"{bvh.source}: no BVH joint maps to the SMPL joint {wanted!r} "
                       f"(missing: {', '.join(missing)}; looked for {', '.join(aliases) or 'nothing'}); "
                       f"the file's joints are {', '.join(bvh.names)}; pass mapping= to name them")

    if up is None:
        up = detect_up_axis(bvh, mapping)
    world_rot, world_pos = bvh_forward_kinematics(bvh)
    conv = _UP_CONVERSION[up]
    if reference_frame is None:
        ref_rot, ref_pos = bvh_forward_kinematics(bvh, rest=True)
    else:
        ref_rot, ref_pos = world_rot[[reference_frame]], world_pos[[reference_frame]]
    delta = conv @ world_rot @ np.swapaxes(ref_rot, -1, -2) @ conv.T  # (T, J, 3, 3)

    n = bvh.num_frames
    if align_rest:
        if smpl_joints is None:
            from ..core.body import load_body_model, shape_body

            smpl_joints = shape_body(load_body_model(), np.zeros(1))[1]
        smpl_joints = np.asarray(smpl_joints, dtype=np.float64)
        if smpl_joints.shape != (NUM_JOINTS, 3) or not np.all(np.isfinite(smpl_joints)):
            raise ArgumentError(f"smpl_joints must be (24, 3) finite positions, got shape {smpl_joints.shape}")
        glob = _aligned_rotations(found, delta, world_pos @ conv.T, ref_pos[0] @ conv.T, smpl_joints)
    else:
        _check_t_pose(bvh, found, conv, ref_pos[0])
        glob = np.empty((n, NUM_JOINTS, 3, 3))
        for s in range(NUM_JOINTS):
            p = PARENTS[s]
            if s in found:
                glob[:, s] = delta[:, found[s]]
            else:
                glob[:, s] = np.eye(3) if p < 0 else glob[:, p]
    local = glob.copy()
    local[:, 1:] = np.swapaxes(glob[:, PARENTS[1:]], -1, -2) @ glob[:, 1:]
    poses = matrix_to_axis_angle(local).reshape(n, 72)

    metres = detect_scale(bvh) if scale is None else float(scale)
    hips = world_pos[:, found[0]] if 0 in found else np.zeros((n, 3))
    root = (hips - hips[0]) @ conv.T * metres
    if fps is not None:
        poses, root = resample(poses, root, bvh.fps, fps)
    out_fps = bvh.fps if fps is None else fps
    if blend_seconds > 0:
        poses = blend_from_rest(poses, max(1, int(round(blend_seconds * out_fps))))
    return poses, root


_CHILDREN = tuple(tuple(c for c in range(NUM_JOINTS) if PARENTS[c] == j) for j in range(NUM_JOINTS))


def _aligned_rotations(found: dict[int, int], delta: np.ndarray, pos: np.ndarray, ref_pos: np.ndarray,
                       smpl_joints: np.ndarray) -> np.ndarray:
    """SMPL world rotations (T, 24, 3, 3) with each bone turned onto the BVH's.

    Args:
        found: SMPL joint -> BVH joint.
        delta: (T, J, 3, 3) BVH world rotations relative to the reference posture, SMPL axes.
        pos: (T, J, 3) BVH joint positions, SMPL axes [file units].
        ref_pos: (J, 3) the same in the reference posture.
        smpl_joints: (24, 3) SMPL rest joint positions [m].
    """
    eps = 1e-3 * max(float(np.max(np.ptp(ref_pos, axis=0))), 1e-12)

    def targets(s: int, c: int) -> list[int]:
        """The first mapped SMPL joints below ``c`` (or ``c``) that lie away from ``s`` at rest."""
        if c in found and np.linalg.norm(ref_pos[found[c]] - ref_pos[found[s]]) > eps:
            return [c]
        return [d for cc in _CHILDREN[c] for d in targets(s, cc)]

    n = delta.shape[0]
    glob = np.empty((n, NUM_JOINTS, 3, 3))
    align = np.empty((NUM_JOINTS, 3, 3))
    for s in range(NUM_JOINTS):  # parents come first
        p = PARENTS[s]
        if s not in found:
            glob[:, s] = np.eye(3) if p < 0 else glob[:, p]
            align[s] = np.eye(3) if p < 0 else align[p]
            continue
        b = found[s]
        if p >= 0 and len(_CHILDREN[p]) > 1 and PARENTS[p] >= 0 and p in found and \
                np.linalg.norm(ref_pos[b] - ref_pos[found[p]]) <= eps:
            # The BVH joint sits on its parent's, where the SMPL joint branches off to the side
            # (CMU's clavicle starts mid-chest, SMPL's collar beside the neck): the two bones
            # start at different places, so their directions are not compared; the joint keeps
            # its BVH rotation relative to the reference posture.
            align[s] = align[p]
            glob[:, s] = delta[:, b] @ align[s]
            continue
        ends = [d for c in _CHILDREN[s] for d in targets(s, c)]
        smpl_dirs = _unit(smpl_joints[ends] - smpl_joints[s])
        bvh_dirs = _unit(ref_pos[[found[d] for d in ends]] - ref_pos[b])
        if not ends:
            align[s] = np.eye(3) if p < 0 else align[p]
        elif len(ends) == 1:
            align[s] = _swing(smpl_dirs[0], bvh_dirs[0])
        elif (pair := _left_right(ends)) is not None:
            # Only the left-right axis is lined up (facing and roll); the pitch about it stays
            # the reference posture's. Rigs put the spine's first joint differently against the
            # hips (Daz's abdomen stands straight above its hip joint, SMPL's spine1 leans 26
            # degrees back from its pelvis), so turning that bone too tipped the pelvis 30 degrees.
            left, right = pair
            align[s] = _swing(_unit(smpl_joints[left] - smpl_joints[right]),
                              _unit(ref_pos[found[left]] - ref_pos[found[right]]))
        else:
            align[s] = Rotation.align_vectors(bvh_dirs, smpl_dirs)[0].as_matrix()
        g = delta[:, b] @ align[s]
        if len(ends) == 1:
            now = _unit(pos[:, found[ends[0]]] - pos[:, b])  # (T, 3)
            g = _swing(g @ smpl_dirs[0], now) @ g
        glob[:, s] = g
    return glob


def _left_right(ends: list[int]) -> tuple[int, int] | None:
    """The first left joint in ``ends`` whose right twin is also there, with that twin."""
    for e in ends:
        name = JOINT_NAMES[e]
        if name.startswith("left_") and (twin := JOINT_NAMES.index("right_" + name[5:])) in ends:
            return e, twin
    return None


def _unit(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors scaled to length 1 (zero vectors stay zero)."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the smallest rotation taking unit vectors ``a`` onto ``b`` (..., 3)."""
    a, b = np.broadcast_arrays(a, b)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    k = np.zeros(a.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k -= np.swapaxes(k, -1, -2)
    opposite = c < -1.0 + 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.eye(3) + k + (k @ k) / np.where(opposite, 1.0, 1.0 + c)[..., None, None]
    if np.any(opposite):  # a half turn about any axis perpendicular to a
        aa = a[opposite]
        helper = np.eye(3)[np.argmin(np.abs(aa), axis=-1)]
        u = _unit(np.cross(aa, helper))
        r[opposite] = 2.0 * u[..., :, None] * u[..., None, :] - np.eye(3)
    return r


def detect_up_axis(bvh: Bvh, mapping: Mapping[str, str] | None = None) -> str:
    """The file's up axis, ``"Y"`` or ``"Z"``, from its rest skeleton.

    Up is the axis along which the rest skeleton runs from its feet (its lowest mapped
    leg joints) to its head (or highest mapped spine joint); without mapped joints, the
    axis along which the root's descendants reach farthest above and below it.

    Raises:
        BvhError: the skeleton stands along X, or upside down.
    """
    found = _resolve_mapping(bvh, mapping)
    _, pos = bvh_forward_kinematics(bvh, rest=True)
    pos = pos[0]
    top = next((found[j] for j in (15, 12, 9, 6, 3) if j in found), None)
    feet = [found[j] for j in (10, 11, 7, 8, 4, 5) if j in found]
    if top is None or not feet:
        span = np.ptp(pos, axis=0)
        axis = int(np.argmax(span[1:])) + 1
        direction = 1.0
    else:
        v = pos[top] - pos[feet].mean(axis=0)
        axis = int(np.argmax(np.abs(v)))
        direction = float(np.sign(v[axis]))
    if axis == 0 or direction < 0:
        raise BvhError(f"{bvh.source}: the rest skeleton stands along {'-' if direction < 0 else '+'}"
                       f"{_AXES[axis]}; only Y-up and Z-up files are read")
    return _AXES[axis]


def _check_t_pose(bvh: Bvh, found: dict[int, int], conv: np.ndarray, ref_pos: np.ndarray) -> None:
    """Warn when the reference posture's left upper arm does not point along SMPL's +X."""
    shoulder, elbow = JOINT_NAMES.index("left_shoulder"), JOINT_NAMES.index("left_elbow")
    if shoulder not in found or elbow not in found:
        return
    bone = conv @ (ref_pos[found[elbow]] - ref_pos[found[shoulder]])
    length = np.linalg.norm(bone)
    if length > 0 and bone[0] / length < np.cos(np.deg2rad(45)):
        log.warning("%s: in the reference posture the left upper arm points along %s, not +X: "
                    "the retargeting assumes a T-pose facing +Z; pass reference_frame= or up_axis=",
                    bvh.source, np.round(bone / length, 2))


def load_bvh(path: str | Path, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """:func:`read_bvh` then :func:`retarget_bvh` (keyword arguments go to the latter).

    Returns:
        ``(poses (T, 72) axis-angle [rad], root_offset (T, 3) [m])``.
    """
    return retarget_bvh(read_bvh(path), **kwargs)
