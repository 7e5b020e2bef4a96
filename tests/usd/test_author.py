"""cloth_usd.usd.author: what is authored, and that read.py reads it back unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel

from cloth_usd.core.rotations import axis_angle_to_matrix
from cloth_usd.core.scene import Category, Tier
from cloth_usd.core.smpl import JOINT_NAMES
from cloth_usd.errors import ArgumentError
from cloth_usd.usd import author, read

SETUPS = [("Y", 1.0), ("Z", 0.01), ("Y", 0.001)]
T = 5


def _random_motion(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(24, 3) rest joints [m], (T, 72) poses with angles up to 2.5 rad, (T, 3) root [m]."""
    rng = np.random.default_rng(seed)
    joints = rng.normal(scale=0.3, size=(24, 3))
    axis = rng.normal(size=(T, 24, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    poses = (axis * rng.uniform(0.0, 2.5, size=(T, 24, 1))).reshape(T, 72)
    root = rng.normal(size=(T, 3))
    return joints, poses, root


def _stage(up: str, mpu: float) -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    author.set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu, fps=30.0, start=10, end=14)
    return stage


@pytest.mark.parametrize("up,mpu", SETUPS)
def test_motion_round_trip(up, mpu):
    joints, poses, root = _random_motion(seed=7)
    times = np.arange(T, dtype=np.float64) + 10.0
    stage = _stage(up, mpu)
    author.author_skeleton(
        stage, "/Char/Skel", joint_positions=joints, betas=np.linspace(-1, 1, 10),
        gender="female", poses=poses, root_positions=root, times=times,
    )
    (character,) = read.read_scene(stage).characters
    assert character.prim_path == "/Char/Skel"
    assert character.gender == "female" and character.betas_authored
    np.testing.assert_allclose(character.betas, np.linspace(-1, 1, 10), atol=1e-6)
    np.testing.assert_array_equal(character.joint_indices, np.arange(24))
    np.testing.assert_allclose(character.rest_root_position, joints[0], atol=1e-5)

    motion = read.read_motion(stage, character, times)
    np.testing.assert_array_equal(motion.times, times)
    assert motion.poses.shape == (T, 72) and motion.root_position.shape == (T, 3)
    got = axis_angle_to_matrix(motion.poses.reshape(T, 24, 3))
    want = axis_angle_to_matrix(poses.reshape(T, 24, 3))
    np.testing.assert_allclose(got, want, atol=1e-5)
    np.testing.assert_allclose(motion.root_position, root, atol=1e-5)


@pytest.mark.parametrize("up,mpu", SETUPS)
def test_unanimated_skeleton_reads_rest_pose(up, mpu):
    joints, _, _ = _random_motion(seed=8)
    stage = _stage(up, mpu)
    author.author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=np.zeros(3))
    (character,) = read.read_scene(stage).characters
    motion = read.read_motion(stage, character, np.array([0.0, 5.0]))
    np.testing.assert_allclose(motion.poses, 0.0, atol=1e-7)
    np.testing.assert_allclose(motion.root_position, np.tile(joints[0], (2, 1)), atol=1e-6)


@pytest.mark.parametrize("up,mpu", SETUPS)
def test_garment_round_trip(up, mpu):
    rng = np.random.default_rng(3)
    points = rng.normal(scale=0.5, size=(12, 3)) + [0.0, 1.0, 0.0]
    faces = [[0, 1, 2, 3], [4, 5, 6], [7, 8, 9, 10, 11]]
    stage = _stage(up, mpu)
    joints, _, _ = _random_motion(seed=9)
    author.author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=np.zeros(10))
    author.author_garment(
        stage, "/Char/Shirt", points=points, faces=faces, category="dress",
        body_path="/Char/Skel", tier="detail", enabled=False,
    )
    (garment,) = read.read_scene(stage).garments
    assert garment.prim_path == "/Char/Shirt" and garment.body_path == "/Char/Skel"
    assert garment.category is Category.DRESS and garment.tier is Tier.DETAIL
    assert garment.enabled is False
    np.testing.assert_allclose(garment.rest_points, points, atol=1e-5)
    np.testing.assert_array_equal(
        garment.triangles, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [7, 9, 10], [7, 10, 11]]
    )
    np.testing.assert_array_equal(garment.face_map, [0, 0, 1, 2, 2, 2])

    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Char/Shirt"))
    local = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
    to_local = read.garment_from_internal(stage, "/Char/Shirt", np.array([10.0, 12.0]))
    assert to_local.shape == (2, 4, 4)
    for m in to_local:
        np.testing.assert_allclose(points @ m[:3, :3].T + m[:3, 3], local, atol=1e-5 / mpu)


def test_garment_under_transformed_parent_round_trips():
    stage = _stage("Z", 0.01)
    xform = UsdGeom.Xform.Define(stage, "/World")
    xform.AddTranslateOp().Set((5.0, -3.0, 2.0))
    xform.AddRotateZOp().Set(30.0)
    points = np.random.default_rng(4).normal(size=(4, 3))
    author.author_skeleton(stage, "/World/Char/Skel", joint_positions=_random_motion(1)[0], betas=[])
    author.author_garment(stage, "/World/Shirt", points=points, faces=np.array([[0, 1, 2], [0, 2, 3]]),
                          body_path="/World/Char/Skel")
    scene = read.read_scene(stage)
    np.testing.assert_allclose(scene.garments[0].rest_points, points, atol=1e-5)
    np.testing.assert_allclose(scene.characters[0].rest_root_position, _random_motion(1)[0][0], atol=1e-5)


def test_z_up_rotation_lives_on_the_skeleton_prim():
    stage = _stage("Z", 0.01)
    author.author_skeleton(stage, "/Char/Skel", joint_positions=np.zeros((24, 3)), betas=[])
    skel = stage.GetPrimAtPath("/Char/Skel")
    l2w = np.array(UsdGeom.Xformable(skel).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
    # Internal +Y (up) is stage +Z; internal +Z (the body's front) is stage -Y.
    np.testing.assert_allclose(l2w[:3, :3] @ [0, 1, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(l2w[:3, :3] @ [0, 0, 1], [0, -1, 0], atol=1e-12)
    assert stage.GetPrimAtPath("/Char").IsA(UsdSkel.Root)


def test_authored_structure():
    joints, poses, root = _random_motion(seed=5)
    stage = _stage("Y", 1.0)
    author.author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=[0.5], poses=poses,
                           root_positions=root)
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Char/Skel"))
    paths = list(skel.GetJointsAttr().Get())
    assert paths[0] == "pelvis" and paths[1] == "pelvis/left_hip"
    assert [p.split("/")[-1] for p in paths] == list(JOINT_NAMES)
    rest = np.array(skel.GetRestTransformsAttr().Get())
    np.testing.assert_allclose(rest[:, :3, :3], np.broadcast_to(np.eye(3), (24, 3, 3)))
    source = UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSourceRel()
    assert list(source.GetTargets()) == ["/Char/Skel/Motion"]
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Motion"))
    assert anim.GetRotationsAttr().GetTimeSamples() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert list(skel.GetPrim().GetAttribute("smpl:betas").Get()) == [0.5]
    assert skel.GetPrim().GetAttribute("smpl:gender").Get() == "neutral"


def test_garment_extent_and_attributes():
    stage = _stage("Y", 0.01)
    author.author_garment(stage, "/Shirt", points=[[0, 0, 0], [1, 0, 0], [0, 2, 0]], faces=[[0, 1, 2]],
                          body_path="/Char/Skel")
    prim = stage.GetPrimAtPath("/Shirt")
    np.testing.assert_allclose(np.array(UsdGeom.Mesh(prim).GetExtentAttr().Get()), [[0, 0, 0], [100, 200, 0]])
    assert prim.GetAttribute("cloth:category").Get() == "tshirt"
    assert prim.GetAttribute("cloth:category").GetVariability() == Sdf.VariabilityUniform
    assert prim.GetAttribute("cloth:enabled").Get() is True
    assert not prim.GetAttribute("cloth:tier")
    assert list(prim.GetRelationship("cloth:body").GetTargets()) == ["/Char/Skel"]


def test_set_stage_metadata():
    stage = _stage("Z", 0.01)
    info = read.read_stage_info(stage)
    assert (info.up_axis, info.meters_per_unit, info.meters_per_unit_authored) == ("Z", 0.01, True)
    assert (info.time_codes_per_second, info.frames_per_second) == (30.0, 30.0)
    assert (info.start_time_code, info.end_time_code) == (10.0, 14.0)
    np.testing.assert_allclose(info.stage_to_internal[:3, :3] @ [0, 0, 100], [0, 1, 0])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"joint_positions": np.zeros((23, 3))}, "joint_positions"),
        ({"betas": np.zeros(11)}, "betas"),
        ({"gender": "other"}, "neutral, female, male"),
        ({"poses": np.zeros((3, 69))}, "poses"),
        ({"poses": np.zeros((3, 72)), "times": np.zeros(2)}, "times"),
    ],
)
def test_author_skeleton_rejects_bad_arguments(kwargs, match):
    args = {"joint_positions": np.zeros((24, 3)), "betas": np.zeros(10), **kwargs}
    with pytest.raises(ArgumentError, match=match):
        author.author_skeleton(_stage("Y", 1.0), "/Char/Skel", **args)


def test_author_rejects_root_level_skeleton_and_bad_garments():
    stage = _stage("Y", 1.0)
    with pytest.raises(ArgumentError, match="/Char/Skel"):
        author.author_skeleton(stage, "/Skel", joint_positions=np.zeros((24, 3)), betas=[])
    with pytest.raises(ArgumentError, match="tshirt, dress, trousers"):
        author.author_garment(stage, "/G", points=np.zeros((3, 3)), faces=[[0, 1, 2]], category="hat",
                              body_path="/Char/Skel")
    with pytest.raises(ArgumentError, match="skinning, coarse, detail"):
        author.author_garment(stage, "/G", points=np.zeros((3, 3)), faces=[[0, 1, 2]], tier="ultra",
                              body_path="/Char/Skel")
    with pytest.raises(ArgumentError, match="outside"):
        author.author_garment(stage, "/G", points=np.zeros((3, 3)), faces=[[0, 1, 3]], body_path="/Char/Skel")
