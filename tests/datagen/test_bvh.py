"""BVH reading and retargeting onto SMPL, on the hand-made fixture and tiny inline files."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bvh_fixture import FRAME_TIME, JOINTS, NAMES, NUM_FRAMES, PATH, SMPL_OF, angles_deg, order, root_position_cm
from cloth_usd.core.smpl import JOINT_NAMES
from cloth_usd.datagen.bvh import (
    DEFAULT_BVH_MAPPING, BvhError, detect_rig, detect_scale, detect_up_axis, load_bvh, parse_bvh, read_bvh,
    retarget_bvh, rig_mapping,
)
from cloth_usd.errors import ArgumentError, ClothUsdError

TOL = 1e-6


def _rotvec_close(a: np.ndarray, b: np.ndarray) -> bool:
    """Same rotations (axis-angle, any batch shape), compared as matrices."""
    ra = Rotation.from_rotvec(np.reshape(a, (-1, 3))).as_matrix()
    rb = Rotation.from_rotvec(np.reshape(b, (-1, 3))).as_matrix()
    return np.allclose(ra, rb, atol=TOL)


def _tiny_bvh(rot_channels: str = "Zrotation Xrotation Yrotation", root_rows=((0, 0, 0),),
              arm_rows=((0, 0, 0),), up: str = "Y", unit: float = 1.0, name_arm: str = "LeftArm") -> str:
    """A 10-joint T-pose skeleton 1.68 m tall, in units of ``unit`` metres: enough for the
    required SMPL joints."""
    def v(x, y, z):
        if up == "Z":  # Y-up (x, y, z) -> Z-up facing -Y: (x, -z, y)
            x, y, z = x, -z, y
        return f"{x / unit:g} {y / unit:g} {z / unit:g}"

    def joint(name, off, body=""):
        return f"JOINT {name}\n{{\nOFFSET {v(*off)}\nCHANNELS 3 {rot_channels}\n{body}}}\n"

    def end(*off):
        return f"End Site\n{{\nOFFSET {v(*off)}\n}}\n"

    legs = "".join(joint(f"{s}UpLeg", (sx * 0.09, -0.08, 0), joint(f"{s}Leg", (0, -0.4, 0), end(0, -0.42, 0)))
                   for s, sx in (("Left", 1), ("Right", -1)))
    arms = "".join(joint(n, (sx * 0.15, 0.5, 0), joint(f"{s}ForeArm", (sx * 0.26, 0, 0), end(sx * 0.25, 0, 0)))
                   for n, s, sx in ((name_arm, "Left", 1), ("RightArm", "Right", -1)))
    head = joint("Head", (0, 0.6, 0), end(0, 0.18, 0))
    text = (f"HIERARCHY\nROOT Hips\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition {rot_channels}\n"
            f"{legs}{arms}{head}}}\nMOTION\nFrames: {len(root_rows)}\nFrame Time: 0.1\n")
    # 3 root positions, 3 root angles, then 3 angles for each of the 9 other joints (file order:
    # LeftUpLeg, LeftLeg, RightUpLeg, RightLeg, LeftArm, LeftForeArm, RightArm, RightForeArm, Head).
    for pos, arm in zip(root_rows, arm_rows):
        values = [*pos, 0, 0, 0] + [0] * 12 + list(arm) + [0] * 12
        text += " ".join(f"{x:g}" for x in values) + "\n"
    return text


# --------------------------------------------------------------------------- parsing
def test_fixture_parses():
    bvh = read_bvh(PATH)
    assert bvh.names == NAMES and len(bvh.names) == 26
    assert bvh.parents[0] == -1 and bvh.names[bvh.parents[NAMES.index("LeftForeArm")]] == "LeftArm"
    assert bvh.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert all(len(c) == 3 for c in bvh.channels[1:])
    assert bvh.motion.shape == (NUM_FRAMES, 6 + 25 * 3)
    assert bvh.frame_time == FRAME_TIME and bvh.fps == pytest.approx(25.0)
    assert len(bvh.end_sites) == 7  # 2 toes, head, 2 x 2 hand tips
    assert np.allclose(bvh.offsets[NAMES.index("LeftToeBase")], [0, -6, 13])


@pytest.mark.parametrize("text, match", [
    ("HIERARCHY\nMOTION\nFrames: 0\nFrame Time: 0.1\n", "no ROOT"),
    ("HIERARCHY\nROOT A\n{\nOFFSET 0 0\n}\n", "number for OFFSET"),
    ("HIERARCHY\nROOT A\n{\nCHANNELS 1 Wrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n", "unknown channel"),
    ("HIERARCHY\nROOT A\n{\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n0\n", "expected 2 frames"),
    ("HIERARCHY\nROOT A\n{\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\nx\n", "'x' is not"),
])
def test_malformed_files_name_the_source(text, match):
    with pytest.raises(BvhError, match=match) as info:
        parse_bvh(text, source="bad.bvh")
    assert "bad.bvh" in str(info.value) and isinstance(info.value, ClothUsdError)


def test_unreadable_file(tmp_path):
    with pytest.raises(BvhError, match="nope.bvh"):
        read_bvh(tmp_path / "nope.bvh")


# --------------------------------------------------------------------------- retargeting
def test_retargeting_recovers_the_fixture_rotations():
    poses, root = load_bvh(PATH, blend_seconds=0.0, align_rest=False)
    assert poses.shape == (NUM_FRAMES, 72) and root.shape == (NUM_FRAMES, 3)
    for j, row in enumerate(JOINTS):
        smpl = SMPL_OF[row[0]]
        if smpl is None:
            continue
        s = JOINT_NAMES.index(smpl)
        for f in range(NUM_FRAMES):
            expected = Rotation.from_euler(order(j), angles_deg(j, f), degrees=True).as_rotvec()
            assert _rotvec_close(poses[f, 3 * s:3 * s + 3], expected), (row[0], f)
    expected_root = np.array([root_position_cm(f) - root_position_cm(0) for f in range(NUM_FRAMES)]) * 0.01
    assert np.allclose(root, expected_root, atol=TOL)


def test_channel_orders_give_the_same_rotation():
    arm = Rotation.from_euler("XYZ", [20, -35, 50], degrees=True)  # the left upper arm's rotation
    results = []
    for chans in ("Zrotation Xrotation Yrotation", "Xrotation Yrotation Zrotation", "Yrotation Xrotation Zrotation"):
        order = "".join(c[0] for c in chans.split())
        angles = arm.as_euler(order, degrees=True)
        text = _tiny_bvh(chans, root_rows=[(0, 0, 0)], arm_rows=[angles])
        poses, _ = retarget_bvh(parse_bvh(text), scale=1.0, blend_seconds=0, align_rest=False)
        results.append(poses[0, 16 * 3:17 * 3])
    for r in results:
        assert _rotvec_close(r, arm.as_rotvec())


def test_channel_order_with_positions_last():
    text = _tiny_bvh().replace("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
                               "CHANNELS 6 Zrotation Xrotation Yrotation Xposition Yposition Zposition")
    text = text.replace("Frames: 1", "Frames: 2") + "0 0 0 1 2 3 " + "0 " * 27 + "\n"
    _, root = retarget_bvh(parse_bvh(text), scale=1.0, blend_seconds=0)
    assert np.allclose(root[1], [1, 2, 3])


def test_scale_and_up_axis_conversion():
    yaw = 30.0
    rows = [(0, 0, 0), (10, 20, 30)]  # file units: inches
    text = _tiny_bvh("Xrotation Yrotation Zrotation", root_rows=rows, up="Z", unit=0.0254,
                     arm_rows=[(0, 0, 0), (0, 0, 0)])
    lines = text.splitlines()
    frame = lines[-1].split()
    frame[5] = str(yaw)  # root Zrotation: a turn about the file's up axis
    text = "\n".join(lines[:-1] + [" ".join(frame)]) + "\n"
    bvh = parse_bvh(text)
    assert detect_scale(bvh) == pytest.approx(0.0254)
    poses, root = retarget_bvh(bvh, up_axis="Z", blend_seconds=0, align_rest=False)
    assert np.allclose(root[1], np.array([10, 30, -20]) * 0.0254)
    assert _rotvec_close(poses[1, :3], [0, np.deg2rad(yaw), 0])  # a turn about SMPL's Y
    assert np.allclose(poses[:, 3:], 0.0, atol=TOL)  # the T-pose maps to the rest pose
    with pytest.raises(ArgumentError, match="up_axis"):
        retarget_bvh(bvh, up_axis="X")


@pytest.mark.parametrize("unit, expected", [(1.0, 1.0), (0.01, 0.01), (0.0254 / 0.45, 0.0254 / 0.45)])
def test_scale_detection_snaps_to_units(unit, expected):
    assert detect_scale(parse_bvh(_tiny_bvh(unit=unit * 1.1))) == pytest.approx(expected)


def test_reference_frame_takes_a_t_pose_from_the_motion(caplog):
    # Rest posture has the arms down (not a T-pose): frame 0 is the T-pose, frame 1 rotates the arm.
    bent = Rotation.from_euler("Z", -80, degrees=True)
    lift = Rotation.from_euler("Z", 30, degrees=True)
    text = _tiny_bvh("Xrotation Yrotation Zrotation", root_rows=[(0, 0, 0), (0, 0, 0)],
                     arm_rows=[bent.inv().as_euler("XYZ", degrees=True),
                               (bent.inv() * lift).as_euler("XYZ", degrees=True)])
    forearm = "JOINT LeftForeArm\n{\nOFFSET "
    assert text.count(forearm + "0.26 0 0") == 1
    text = text.replace(forearm + "0.26 0 0", forearm + "%g %g 0" % tuple(bent.apply([0.26, 0, 0])[:2]))
    with caplog.at_level(logging.WARNING):
        retarget_bvh(parse_bvh(text), scale=1.0, blend_seconds=0, align_rest=False)
    assert "T-pose" in caplog.text
    poses, _ = retarget_bvh(parse_bvh(text), scale=1.0, blend_seconds=0, reference_frame=0,
                            align_rest=False)
    assert np.allclose(poses[0], 0.0, atol=TOL)
    assert _rotvec_close(poses[1, 16 * 3:17 * 3], lift.as_rotvec())


def test_resampling_to_a_target_fps():
    poses, root = load_bvh(PATH, fps=50.0, blend_seconds=0)
    assert poses.shape == (2 * NUM_FRAMES - 1, 72) and root.shape == (2 * NUM_FRAMES - 1, 3)
    native, native_root = load_bvh(PATH, blend_seconds=0)
    assert np.allclose(poses[::2], native, atol=TOL)
    assert np.allclose(root[1], 0.5 * (native_root[0] + native_root[1]))
    halfway = Rotation.from_rotvec(native[:2, 3:6])  # left hip, frames 0 and 1
    mid = Rotation.from_rotvec(poses[1, 3:6])
    d0, d1 = (halfway[0].inv() * mid).magnitude(), (mid.inv() * halfway[1]).magnitude()
    assert d0 == pytest.approx(d1, abs=TOL)


def test_blend_from_rest_is_on_by_default():
    poses, _ = load_bvh(PATH)
    assert np.allclose(poses[0], 0.0) and not np.allclose(poses[-1], 0.0)


def test_missing_joint_names_file_and_joint(tmp_path):
    path = tmp_path / "no_knee.bvh"
    path.write_text(PATH.read_text().replace("LeftLeg", "LeftShin_Renamed"))
    with pytest.raises(BvhError, match=r"no_knee\.bvh.*'left_knee'"):
        load_bvh(path)


def test_mapping_override_and_namespaces():
    text = _tiny_bvh(name_arm="mixamorig:UpperArmThing").replace("Hips", "mixamorig:Hips")
    with pytest.raises(BvhError, match="left_shoulder"):
        retarget_bvh(parse_bvh(text), scale=1.0)
    mapping = {**DEFAULT_BVH_MAPPING, "UpperArmThing": "left_shoulder"}
    poses, _ = retarget_bvh(parse_bvh(text), scale=1.0, mapping=mapping)
    assert poses.shape == (1, 72)
    with pytest.raises(ArgumentError, match="not an SMPL joint"):
        retarget_bvh(parse_bvh(text), mapping={"Hips": "hips"})


def test_default_mapping_covers_common_names():
    for name, smpl in [("Hips", "pelvis"), ("LeftUpLeg", "left_hip"), ("LeftLeg", "left_knee"),
                       ("LeftFoot", "left_ankle"), ("LeftToeBase", "left_foot"), ("Spine", "spine1"),
                       ("Spine1", "spine2"), ("Spine2", "spine3"), ("Chest", "spine3"), ("Neck", "neck"),
                       ("Head", "head"), ("LeftShoulder", "left_collar"), ("LeftArm", "left_shoulder"),
                       ("LeftForeArm", "left_elbow"), ("LeftHand", "left_wrist"), ("RightArm", "right_shoulder"),
                       ("rShldr", "right_shoulder"), ("RightToeBase", "right_foot")]:
        assert DEFAULT_BVH_MAPPING[name.lower()] == smpl, name


# --------------------------------------------------------------------------- rest alignment
def _smpl_bone_dirs(poses: np.ndarray, a: str, b: str) -> np.ndarray:
    """(T, 3) unit direction of SMPL's bone a -> b under ``poses``, on the embedded mean body."""
    from cloth_usd.core.body import joint_transforms, load_body_model, shape_body
    from cloth_usd.core.rotations import axis_angle_to_matrix

    joints = shape_body(load_body_model(), np.zeros(1))[1]
    pos = joint_transforms(axis_angle_to_matrix(poses.reshape(-1, 24, 3)), joints)[0]
    v = pos[:, JOINT_NAMES.index(b)] - pos[:, JOINT_NAMES.index(a)]
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_an_arms_down_rest_puts_the_arms_where_the_file_has_them():
    # The rest posture hangs the left arm 80 deg down; frame 1 lifts it 30 deg, frame 2 swings it forward.
    down = Rotation.from_euler("Z", -80, degrees=True)
    frames = [Rotation.identity(), Rotation.from_euler("Z", 30, degrees=True),
              Rotation.from_euler("Y", -50, degrees=True)]
    text = _tiny_bvh("Xrotation Yrotation Zrotation", root_rows=[(0, 0, 0)] * 3,
                     arm_rows=[r.as_euler("XYZ", degrees=True) for r in frames])
    forearm = "JOINT LeftForeArm\n{\nOFFSET "
    assert text.count(forearm + "0.26 0 0") == 1
    text = text.replace(forearm + "0.26 0 0", forearm + "%g %g %g" % tuple(down.apply([0.26, 0, 0])))
    bvh = parse_bvh(text)
    poses, _ = retarget_bvh(bvh, scale=1.0, blend_seconds=0, up_axis=None)
    got = _smpl_bone_dirs(poses, "left_shoulder", "left_elbow")
    want = np.array([(r * down).apply([1.0, 0, 0]) for r in frames])  # in SMPL's (Y-up) axes
    assert np.degrees(np.arccos(np.clip(np.sum(got * want, axis=-1), -1, 1))).max() < 1e-4
    # the older rule reads the rest as a T-pose: the arm stays 80 deg off
    old, _ = retarget_bvh(bvh, scale=1.0, blend_seconds=0, align_rest=False)
    off = np.degrees(np.arccos(np.sum(_smpl_bone_dirs(old, "left_shoulder", "left_elbow")[0] * want[0])))
    assert off > 60



@pytest.mark.parametrize("clip", ["cmu_mb_02_01_walk.bvh", "cmu_daz_12_01_walk.bvh"])
def test_both_cmu_rigs_walk_upright(clip):
    # The Daz conversion puts its abdomen joint straight above the hip joint and the thighs
    # above it, where SMPL's spine1 leans back from the pelvis: lining up every pelvis bone
    # tipped the Daz walk's pelvis 31 deg forward (hip flexion 39 deg, spine1-3 bent back 53).
    poses, _ = load_bvh(Path(__file__).parents[1] / "data" / "mocap" / clip, blend_seconds=0)
    rot = Rotation.from_rotvec(poses[1:].reshape(-1, 3)).as_matrix().reshape(-1, 24, 3, 3)
    tilt = np.degrees(np.arccos(np.clip(rot[:, 0, 1, 1], -1.0, 1.0)))  # pelvis's up axis from vertical

    def about_x(j):
        return Rotation.from_matrix(rot[:, j]).as_euler("xyz", degrees=True)[:, 0]
    flexion = -(about_x(1) + about_x(2)) / 2
    spine = about_x(3) + about_x(6) + about_x(9)
    assert np.median(tilt) < 8 and np.median(flexion) < 12 and abs(np.median(spine)) < 12

@pytest.mark.parametrize("up", ["Y", "Z"])
def test_up_axis_detection(up):
    assert detect_up_axis(parse_bvh(_tiny_bvh(up=up))) == up
    lying = _tiny_bvh().replace("OFFSET 0 0.6 0", "OFFSET 0.6 0 0")  # the head along +X: neither
    with pytest.raises(BvhError, match=r"stands along \+X"):
        detect_up_axis(parse_bvh(lying, source="lying.bvh"))


def test_rigs_are_told_apart():
    assert detect_rig(read_bvh(PATH)) == "mixamo"
    assert detect_rig(parse_bvh(_tiny_bvh())) is None  # no Spine2, no signature of any rig
    rig, table = rig_mapping(parse_bvh(_tiny_bvh()), {"Head": "neck"})
    assert rig is None and table == {"Head": "neck"}
    rig, table = rig_mapping(read_bvh(PATH), {"Head": "neck"})
    assert rig == "mixamo" and table["Head"] == "neck" and "Neck" not in table
