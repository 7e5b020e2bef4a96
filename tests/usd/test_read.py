"""cloth_usd.usd.read: hand-built skeletons and garments, and every contract breach."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.core.rotations import axis_angle_to_matrix
from cloth_usd.core.smpl import JOINT_NAMES, PARENTS
from cloth_usd.errors import GarmentError, SceneError
from cloth_usd.usd import author, read

# --------------------------------------------------------------------- fixtures


def _stage(up: str = "Y", mpu: float = 1.0) -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    author.set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu)
    return stage


def _matrices(rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations and (..., 3) translations -> (..., 4, 4) column convention."""
    m = np.zeros(rot.shape[:-2] + (4, 4))
    m[..., :3, :3] = rot
    m[..., :3, 3] = trans
    m[..., 3, 3] = 1.0
    return m


def _vt(col: np.ndarray) -> Vt.Matrix4dArray:
    """(J, 4, 4) column convention -> Vt.Matrix4dArray (USD's row convention)."""
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(col, -1, -2)))


def _define_skeleton(stage, path, joint_paths, rest_local, anim_local=None, times=None):
    """A Skeleton (under a SkelRoot parent) with (J, 4, 4) rest and (T, J, 4, 4) animated
    local transforms, column convention, written with the plain UsdSkel API."""
    UsdSkel.Root.Define(stage, Sdf.Path(path).GetParentPath())
    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr(list(joint_paths))
    skel.CreateRestTransformsAttr(_vt(rest_local))
    if anim_local is not None:
        anim = UsdSkel.Animation.Define(stage, f"{path}/Anim")
        anim.CreateJointsAttr(list(joint_paths))
        for t, local in zip(times, anim_local):
            anim.SetTransforms(_vt(local), Usd.TimeCode(float(t)))
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    return skel


def _smpl_paths() -> list[str]:
    return author.smpl_joint_paths()


def _standard_scene(stage=None, *, garment=True):
    """An authored SMPL skeleton at /Char/Skel and, optionally, a garment /Char/Shirt."""
    stage = stage or _stage()
    joints = np.random.default_rng(0).normal(scale=0.3, size=(24, 3))
    author.author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=np.zeros(10))
    if garment:
        author.author_garment(stage, "/Char/Shirt", points=np.eye(3), faces=[[0, 1, 2]],
                              body_path="/Char/Skel")
    return stage


def _garment_prim(stage, path="/Shirt", body="/Char/Skel"):
    """A minimal garment mesh authored with the plain USD API."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 3, 2])
    prim = mesh.GetPrim()
    prim.CreateAttribute("cloth:category", Sdf.ValueTypeNames.Token).Set("tshirt")
    if body is not None:
        prim.CreateRelationship("cloth:body").SetTargets([body])
    return prim


def _topological_shuffle(parent_of: dict[str, str | None], rng) -> list[str]:
    """Joint names in a random order with every parent before its children."""
    order, placed = [], set()
    while len(order) < len(parent_of):
        ready = sorted(n for n, p in parent_of.items() if n not in placed and (p is None or p in placed))
        pick = ready[rng.integers(len(ready))]
        order.append(pick)
        placed.add(pick)
    return order


def _path(name: str, parent_of: dict[str, str | None]) -> str:
    parent = parent_of[name]
    return name if parent is None else f"{_path(parent, parent_of)}/{name}"


# ------------------------------------------------------------ reading skeletons


def test_shuffled_joints_with_extras_read_correctly():
    rng = np.random.default_rng(11)
    parent_of = {n: (JOINT_NAMES[p] if p >= 0 else None) for n, p in zip(JOINT_NAMES, PARENTS)}
    parent_of.update(
        root=None, pelvis="root", spine1_twist="spine1", spine2="spine1_twist",
        left_index1="left_hand", left_index2="left_index1", right_thumb1="right_hand",
    )
    order = _topological_shuffle(parent_of, rng)
    paths = [_path(n, parent_of) for n in order]
    num, times = len(order), np.array([1.0, 2.0, 3.0])
    offsets = rng.normal(scale=0.2, size=(num, 3))
    rest = _matrices(np.broadcast_to(np.eye(3), (num, 3, 3)), offsets)
    smpl_aa = rng.normal(size=(len(times), 24, 3))
    anim_rot = np.tile(np.eye(3), (len(times), num, 1, 1))
    for j, name in enumerate(JOINT_NAMES):
        anim_rot[:, order.index(name)] = axis_angle_to_matrix(smpl_aa[:, j])
    anim_trans = np.tile(offsets, (len(times), 1, 1))
    pelvis = order.index("pelvis")
    anim_trans[:, pelvis] = rng.normal(size=(len(times), 3))
    stage = _stage()
    _define_skeleton(stage, "/Rig/Skel", paths, rest, _matrices(anim_rot, anim_trans), times)
    _garment_prim(stage, body="/Rig/Skel")

    (character,) = read.read_scene(stage).characters
    assert [order[i] for i in character.joint_indices] == list(JOINT_NAMES)
    root_offset = offsets[order.index("root")]
    np.testing.assert_allclose(character.rest_root_position, root_offset + offsets[pelvis], atol=1e-12)
    assert not character.betas_authored and character.gender == "neutral"

    motion = read.read_motion(stage, character, times)
    got = axis_angle_to_matrix(motion.poses.reshape(-1, 24, 3))
    np.testing.assert_allclose(got, axis_angle_to_matrix(smpl_aa), atol=1e-5)
    np.testing.assert_allclose(motion.root_position, root_offset + anim_trans[:, pelvis], atol=1e-5)


def _forward_kinematics(local: np.ndarray) -> np.ndarray:
    """(..., 24, 4, 4) SMPL-ordered local transforms -> skeleton-space transforms."""
    world = local.copy()
    for j in range(1, 24):
        world[..., j, :, :] = world[..., PARENTS[j], :, :] @ local[..., j, :, :]
    return world


def test_non_identity_rest_rotations_give_the_same_poses():
    """A rig with arbitrary joint orients, moved like an identity-rest rig, reads the same poses."""
    rng = np.random.default_rng(12)
    times = np.array([0.0, 1.0])
    joints = rng.normal(scale=0.3, size=(24, 3))
    smpl_aa = rng.normal(size=(2, 24, 3))
    offsets = joints.copy()
    offsets[1:] -= joints[PARENTS[1:]]
    # Rig A: identity rest rotations, SMPL local rotations.
    rest_a = _matrices(np.broadcast_to(np.eye(3), (24, 3, 3)), offsets)
    anim_a = _matrices(axis_angle_to_matrix(smpl_aa), np.broadcast_to(offsets, (2, 24, 3)))
    # Rig B: random rest rotations; same world rotations relative to rest.
    orient = axis_angle_to_matrix(rng.normal(size=(24, 3)))  # world rest rotations W_r
    world_rest_b = _matrices(orient, joints)
    g = _forward_kinematics(anim_a)[..., :3, :3]  # G_j, world rotation relative to rest
    world_anim_b = _matrices(g @ orient, _forward_kinematics(anim_a)[..., :3, 3])
    inv = np.linalg.inv
    rest_b = world_rest_b.copy()
    rest_b[1:] = inv(world_rest_b[PARENTS[1:]]) @ world_rest_b[1:]
    anim_b = world_anim_b.copy()
    anim_b[:, 1:] = inv(world_anim_b[:, PARENTS[1:]]) @ world_anim_b[:, 1:]

    stage = _stage()
    _define_skeleton(stage, "/A/Skel", _smpl_paths(), rest_a, anim_a, times)
    _define_skeleton(stage, "/B/Skel", _smpl_paths(), rest_b, anim_b, times)
    chars = read.read_scene(stage).characters
    assert [c.prim_path for c in chars] == ["/A/Skel", "/B/Skel"]  # untargeted but complete
    motion_a, motion_b = (read.read_motion(stage, c, times) for c in chars)
    got_a = axis_angle_to_matrix(motion_a.poses.reshape(2, 24, 3))
    got_b = axis_angle_to_matrix(motion_b.poses.reshape(2, 24, 3))
    np.testing.assert_allclose(got_a, axis_angle_to_matrix(smpl_aa), atol=1e-5)
    np.testing.assert_allclose(got_b, got_a, atol=1e-5)
    np.testing.assert_allclose(motion_b.root_position, motion_a.root_position, atol=1e-6)


def test_animated_skeleton_prim_xform_is_the_root_orientation():
    stage = _standard_scene(garment=False)
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/Char")).AddRotateYOp()
    op.Set(0.0, 0.0)
    op.Set(90.0, 1.0)
    (character,) = read.read_scene(stage).characters
    motion = read.read_motion(stage, character, np.array([0.0, 1.0]))
    np.testing.assert_allclose(motion.poses[0], 0.0, atol=1e-7)
    np.testing.assert_allclose(motion.poses[1, :3], [0.0, np.pi / 2, 0.0], atol=1e-7)
    np.testing.assert_allclose(motion.poses[1, 3:], 0.0, atol=1e-7)


def test_rest_falls_back_to_bind_transforms():
    stage = _standard_scene(garment=False)
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Char/Skel"))
    expected = read.read_scene(stage).characters[0].rest_root_position
    skel.GetRestTransformsAttr().Clear()
    (character,) = read.read_scene(stage).characters
    np.testing.assert_allclose(character.rest_root_position, expected, atol=1e-12)
    motion = read.read_motion(stage, character, np.array([0.0]))
    np.testing.assert_allclose(motion.poses, 0.0, atol=1e-9)


def test_betas_padding_gender_and_missing_betas_warning(caplog):
    stage = _standard_scene()
    prim = stage.GetPrimAtPath("/Char/Skel")
    prim.GetAttribute("smpl:betas").Set(Vt.FloatArray([1.0, 2.0]))
    prim.GetAttribute("smpl:gender").Set("male")
    (character,) = read.read_scene(stage).characters
    np.testing.assert_array_equal(character.betas, [1, 2, 0, 0, 0, 0, 0, 0, 0, 0])
    assert character.gender == "male"
    prim.RemoveProperty("smpl:betas")
    with caplog.at_level(logging.WARNING, logger="cloth_usd.usd.read"):
        (character,) = read.read_scene(stage).characters
    assert not character.betas_authored and not character.betas.any()
    assert "/Char/Skel" in caplog.text and "smpl:betas" in caplog.text


def test_untargeted_incomplete_skeleton_is_ignored():
    stage = _standard_scene()
    skel = UsdSkel.Skeleton.Define(stage, "/Other/Skel")
    skel.CreateJointsAttr(["hips", "hips/spine"])
    scene = read.read_scene(stage)
    assert [c.prim_path for c in scene.characters] == ["/Char/Skel"]


# ------------------------------------------------------------ reading the stage


def test_unauthored_meters_per_unit_warns_and_uses_centimetres(caplog):
    stage = Usd.Stage.CreateInMemory()
    _garment_prim(stage, body="/Char/Skel")
    author.author_skeleton(stage, "/Char/Skel", joint_positions=np.zeros((24, 3)), betas=np.zeros(10))
    with caplog.at_level(logging.WARNING, logger="cloth_usd.usd.read"):
        scene = read.read_scene(stage)
    assert "metersPerUnit" in caplog.text
    assert scene.stage.meters_per_unit == 0.01 and not scene.stage.meters_per_unit_authored
    assert scene.stage.start_time_code is None and scene.stage.end_time_code is None
    np.testing.assert_allclose(scene.garments[0].rest_points[3], [0.01, 0.01, 0.0])


def test_garment_points_use_the_earliest_local_to_world():
    stage = _stage("Z", 0.01)
    _standard_scene(stage, garment=False)
    op = UsdGeom.Xform.Define(stage, "/Xf").AddTranslateOp()
    prim = _garment_prim(stage, path="/Xf/Shirt")
    op.Set((0.0, 0.0, 100.0), 5.0)
    op.Set((0.0, 0.0, 900.0), 50.0)
    (garment,) = read.read_scene(stage).garments
    assert garment.prim_path == str(prim.GetPath())
    # Stage (1, 1, 100) cm, Z-up -> internal (0.01, 1.0, -0.01) m.
    np.testing.assert_allclose(garment.rest_points[3], [0.01, 1.0, -0.01], atol=1e-12)
    to_local = read.garment_from_internal(stage, "/Xf/Shirt", np.array([5.0, 50.0]))
    np.testing.assert_allclose(to_local[0] @ [0.01, 1.0, -0.01, 1.0], [1.0, 1.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(to_local[1] @ [0.01, 9.0, -0.01, 1.0], [1.0, 1.0, 0.0, 1.0], atol=1e-9)


def test_open_stage_reads_a_file(tmp_path):
    path = tmp_path / "scene.usda"
    source = _standard_scene()  # keep the stage alive: its layer is held by a weak pointer
    source.GetRootLayer().Export(str(path))
    stage = read.open_stage(path)
    assert read.read_scene(stage).stage.identifier == str(path)


@pytest.mark.parametrize(
    "name, content", [("missing.usda", None), ("notes.txt", "hi"), ("broken.usda", "hi")]
)
def test_open_stage_errors_name_the_file(tmp_path, name, content):
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(SceneError, match=name):
        read.open_stage(path)


# ----------------------------------------------------------------------- errors


def test_missing_joint_is_named():
    stage = _stage()
    paths = [p for p in _smpl_paths() if not p.endswith("left_hand")]
    rest = _matrices(np.broadcast_to(np.eye(3), (23, 3, 3)), np.zeros((23, 3)))
    _define_skeleton(stage, "/Rig/Skel", paths, rest)
    _garment_prim(stage, body="/Rig/Skel")
    with pytest.raises(SceneError, match=r"</Rig/Skel>.*left_hand"):
        read.read_scene(stage)


def test_wrong_hierarchy_names_joint_found_and_expected_parent():
    stage = _stage()
    paths = [p.replace("pelvis/left_hip", "pelvis/spine1/left_hip") for p in _smpl_paths()]
    order = sorted(range(24), key=lambda i: paths[i].count("/"))  # parents before children
    paths = [paths[i] for i in order]
    rest = _matrices(np.broadcast_to(np.eye(3), (24, 3, 3)), np.zeros((24, 3)))
    _define_skeleton(stage, "/Rig/Skel", paths, rest)
    _garment_prim(stage, body="/Rig/Skel")
    with pytest.raises(SceneError, match=r"</Rig/Skel>.*'left_hip'.*parent spine1.*expects pelvis"):
        read.read_scene(stage)


def test_garment_without_body():
    stage = _standard_scene(garment=False)
    _garment_prim(stage, body=None)
    with pytest.raises(GarmentError, match=r"</Shirt>.*cloth:body"):
        read.read_scene(stage)


def test_body_targeting_a_non_skeleton():
    stage = _standard_scene(garment=False)
    _garment_prim(stage, body="/Char")
    with pytest.raises(GarmentError, match=r"</Shirt>.*</Char>, a SkelRoot, not a UsdSkel Skeleton"):
        read.read_scene(stage)


def test_body_targeting_nothing():
    stage = _standard_scene(garment=False)
    _garment_prim(stage, body="/Nobody")
    with pytest.raises(GarmentError, match=r"</Shirt>.*</Nobody>, which does not exist"):
        read.read_scene(stage)


def test_nan_points():
    stage = _standard_scene(garment=False)
    prim = _garment_prim(stage)
    prim.GetAttribute("points").Set([(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0), (1, 1, 0)])
    with pytest.raises(GarmentError, match=r"</Shirt>: points\[2\]"):
        read.read_scene(stage)


def test_time_sampled_only_points():
    stage = _standard_scene(garment=False)
    prim = _garment_prim(stage)
    attr = prim.GetAttribute("points")
    attr.Set(attr.Get(), 1.0)
    attr.ClearDefault()
    with pytest.raises(GarmentError, match=r"</Shirt>.*default"):
        read.read_scene(stage)


def test_bad_category():
    stage = _standard_scene(garment=False)
    _garment_prim(stage).GetAttribute("cloth:category").Set("hat")
    with pytest.raises(GarmentError, match=r"</Shirt>: cloth:category is 'hat'.*tshirt, dress, trousers"):
        read.read_scene(stage)


def test_bad_tier():
    stage = _standard_scene(garment=False)
    prim = _garment_prim(stage)
    prim.CreateAttribute("cloth:tier", Sdf.ValueTypeNames.Token).Set("ultra")
    with pytest.raises(GarmentError, match=r"</Shirt>: cloth:tier is 'ultra'.*skinning, coarse, detail"):
        read.read_scene(stage)


def test_bad_gender():
    stage = _standard_scene()
    stage.GetPrimAtPath("/Char/Skel").GetAttribute("smpl:gender").Set("robot")
    with pytest.raises(SceneError, match=r"</Char/Skel>.*'robot'.*neutral, female, male"):
        read.read_scene(stage)


def test_too_many_betas():
    stage = _standard_scene()
    stage.GetPrimAtPath("/Char/Skel").GetAttribute("smpl:betas").Set(Vt.FloatArray([0.0] * 11))
    with pytest.raises(SceneError, match=r"</Char/Skel>: smpl:betas has 11 values"):
        read.read_scene(stage)


def test_nan_betas():
    stage = _standard_scene()
    stage.GetPrimAtPath("/Char/Skel").GetAttribute("smpl:betas").Set(Vt.FloatArray([0.0, float("nan")]))
    with pytest.raises(SceneError, match=r"</Char/Skel>: smpl:betas\[1\]"):
        read.read_scene(stage)


@pytest.mark.parametrize(
    "counts, indices, match",
    [
        ([2, 3], [0, 1, 0, 1, 2], "face 0 has 2 vertices"),
        ([3, 3], [0, 1, 2, 1, 2, 7], "face 1 uses vertex index 7"),
    ],
)
def test_bad_faces(counts, indices, match):
    stage = _standard_scene(garment=False)
    prim = _garment_prim(stage)
    prim.GetAttribute("faceVertexCounts").Set(counts)
    prim.GetAttribute("faceVertexIndices").Set(indices)
    with pytest.raises(GarmentError, match=rf"</Shirt>: {match}"):
        read.read_scene(stage)


def test_non_finite_frame_is_named():
    stage = _stage()
    poses = np.zeros((4, 72))
    author.author_skeleton(stage, "/Char/Skel", joint_positions=np.zeros((24, 3)), betas=[], poses=poses)
    attr = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Motion")).GetTranslationsAttr()
    bad = np.array(attr.Get(2.0))
    bad[0, 1] = np.inf
    attr.Set(Vt.Vec3fArray.FromNumpy(bad), 2.0)
    (character,) = read.read_scene(stage).characters
    with pytest.raises(SceneError, match=r"</Char/Skel>.*time code 2"):
        read.read_motion(stage, character, np.arange(4.0))


def test_lenient_read_collects_problems():
    stage = _standard_scene()  # a good character and garment
    _garment_prim(stage, path="/Hat").GetAttribute("cloth:category").Set("hat")
    paths = [p for p in _smpl_paths() if not p.endswith("right_hand")]
    rest = _matrices(np.broadcast_to(np.eye(3), (23, 3, 3)), np.zeros((23, 3)))
    _define_skeleton(stage, "/Rig/Skel", paths, rest)
    _garment_prim(stage, path="/Rig/Dress", body="/Rig/Skel")
    problems: list[str] = []
    scene = read.read_scene(stage, problems=problems)
    assert [g.prim_path for g in scene.garments] == ["/Char/Shirt"]
    assert [c.prim_path for c in scene.characters] == ["/Char/Skel"]
    assert len(problems) == 3
    assert "</Hat>: cloth:category is 'hat'" in problems[0]
    assert "</Rig/Skel>" in problems[1] and "right_hand" in problems[1]
    assert "</Rig/Dress>: skipped" in problems[2]


# ------------------------------------------------- layers that do not compose, odd paths


def _layered(tmp_path, sublayers: list[str], body: str = ""):
    """scene.usda sublayering ``sublayers`` and then base.usda (the standard scene)."""
    source = _standard_scene()
    source.GetRootLayer().Export(str(tmp_path / "base.usda"))
    paths = ", ".join(f"@{p}@" for p in [*sublayers, "base.usda"])
    (tmp_path / "scene.usda").write_text(f"#usda 1.0\n(\n    subLayers = [{paths}]\n)\n{body}")
    return tmp_path / "scene.usda"


def test_a_missing_sublayer_is_an_error_naming_it(tmp_path):
    path = _layered(tmp_path, ["anim.usda"])
    with pytest.raises(SceneError, match=r"scene.usda: sublayer @anim.usda@ of .*scene.usda: does not exist"):
        read.open_stage(path)


def test_an_empty_sublayer_file_is_an_error_naming_it(tmp_path):
    path = _layered(tmp_path, ["anim.usda"])
    (tmp_path / "anim.usda").write_bytes(b"")
    with pytest.raises(SceneError, match=r"sublayer @anim.usda@ .*cannot be opened"):
        read.open_stage(path)


def test_a_reference_to_a_missing_prim_is_an_error(tmp_path):
    path = _layered(tmp_path, [], 'def Xform "Extra" (references = @base.usda@</Nope>) {}\n')
    with pytest.raises(SceneError, match=r"does not compose as its layers say: .*</Nope>"):
        read.open_stage(path)


def test_a_sound_layer_stack_opens(tmp_path):
    (tmp_path / "anim.usda").write_text("#usda 1.0\n")
    stage = read.open_stage(_layered(tmp_path, ["anim.usda"]))
    assert read.read_scene(stage).characters


def test_a_folder_and_a_symlink_loop_are_named_for_what_they_are(tmp_path):
    import os

    (tmp_path / "dir.usda").mkdir()
    with pytest.raises(SceneError, match=r"dir.usda: is a folder"):
        read.open_stage(tmp_path / "dir.usda")
    os.symlink(tmp_path / "b.usda", tmp_path / "a.usda")
    os.symlink(tmp_path / "a.usda", tmp_path / "b.usda")
    with pytest.raises(SceneError, match=r"a.usda: is a symbolic link loop"):
        read.open_stage(tmp_path / "a.usda")


def test_a_parse_error_keeps_usds_reason(tmp_path):
    path = tmp_path / "scene.usda"
    path.write_text("#usda 1.0\n(\n    framesPerSecond = 0\n)\n")
    with pytest.raises(SceneError, match=r'invalid value for field "framesPerSecond"'):
        read.open_stage(path)


@pytest.mark.parametrize("value", [0.0, -24.0])
def test_time_codes_per_second_must_be_positive(value):
    stage = _standard_scene()
    stage.SetTimeCodesPerSecond(value)
    with pytest.raises(SceneError, match=rf"timeCodesPerSecond is {value:g}; author a positive"):
        read.read_scene(stage)


def test_absurd_betas_are_refused_naming_the_prim_and_value():
    stage = _standard_scene()
    stage.GetPrimAtPath("/Char/Skel").GetAttribute("smpl:betas").Set(Vt.FloatArray([0.5, 1e30]))
    with pytest.raises(SceneError, match=r"</Char/Skel>: smpl:betas\[1\] is 1e\+30"):
        read.read_scene(stage)


@pytest.mark.parametrize("key", [float("-inf"), float("inf")])
def test_a_non_finite_time_sample_key_is_named(key):
    stage = _stage()
    author.author_skeleton(stage, "/Char/Skel", joint_positions=np.zeros((24, 3)), betas=[],
                           poses=np.zeros((4, 72)))
    attr = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Motion")).GetTranslationsAttr()
    attr.Set(attr.Get(1.0), key)
    (character,) = read.read_scene(stage).characters
    with pytest.raises(SceneError, match=rf"Motion.translations has a time sample at time code {key:g}"):
        read.read_motion(stage, character, np.arange(4.0))
