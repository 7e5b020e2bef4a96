"""Joint-name conventions and joint maps: the same rig under other names reads the same."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.cli import main
from cloth_usd.core.joint_names import NAMINGS, load_joint_map, match_joints, parse_joint_map
from cloth_usd.core.rotations import axis_angle_to_matrix
from cloth_usd.core.smpl import JOINT_NAMES, PARENTS
from cloth_usd.errors import ArgumentError, SceneError
from cloth_usd.usd import author, read

WALK = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"
TIMES = np.array([0.0, 1.0, 2.0])
NAMES = {n.name: tuple(alts[0] for alts in n.names) for n in NAMINGS}
FBX = NAMES["smpl-fbx"]
#: A Mixamo-like rig: no convention knows these names.
CUSTOM = tuple(f"rig_{n}" for n in (
    "Hips", "LeftUpLeg", "RightUpLeg", "Spine", "LeftLeg", "RightLeg", "Spine1", "LeftFoot", "RightFoot",
    "Spine2", "LeftToeBase", "RightToeBase", "Neck", "LeftShoulder", "RightShoulder", "Head", "LeftArm",
    "RightArm", "LeftForeArm", "RightForeArm", "LeftHand", "RightHand", "LeftHandMiddle1", "RightHandMiddle1"))
#: SMPL-X's extra joints (identity motion), each under an SMPL joint (by index).
SMPLX_EXTRAS = ((15, "jaw"), (15, "left_eye_smplhf"), (15, "right_eye_smplhf"), (20, "left_index1"),
                (22, "left_middle2"), (21, "right_thumb1"))

# --------------------------------------------------------------------- fixtures


def _paths(names) -> list[str]:
    paths: list[str] = []
    for j, name in enumerate(names):
        paths.append(name if PARENTS[j] < 0 else f"{paths[PARENTS[j]]}/{name}")
    return paths


def _rename(stage, skel_path: str, names, *, root: str | None = None, extras=()) -> None:
    """Rename an SMPL-ordered Skeleton's joints (and its animation's), optionally adding
    a root bone above the pelvis and extra joints, all with identity transforms."""
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath(skel_path))
    assert [str(j) for j in skel.GetJointsAttr().Get()] == author.smpl_joint_paths()
    smpl_paths = _paths(names)
    if root:
        smpl_paths = [f"{root}/{p}" for p in smpl_paths]
    paths = ([root] if root else []) + smpl_paths + [f"{smpl_paths[p]}/{leaf}" for p, leaf in extras]
    src = ([None] if root else []) + list(range(24)) + [None] * len(extras)  # None: an added joint
    parent = ([None] if root else []) + [None] * 24 + [p for p, _ in extras]

    def expand(values, identity, inherit=False):
        values = list(values)
        return [values[s] if s is not None else (values[p] if inherit and p is not None else identity)
                for s, p in zip(src, parent)]

    skel.GetJointsAttr().Set(paths)
    skel.GetRestTransformsAttr().Set(Vt.Matrix4dArray(expand(skel.GetRestTransformsAttr().Get(), Gf.Matrix4d(1))))
    bind = skel.GetBindTransformsAttr()
    bind.Set(Vt.Matrix4dArray(expand(bind.Get(), Gf.Matrix4d(1), inherit=True)))
    targets = UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSourceRel().GetTargets()
    anim = UsdSkel.Animation(stage.GetPrimAtPath(targets[0]))
    anim.GetJointsAttr().Set(paths)
    for attr, kind, identity in ((anim.GetRotationsAttr(), Vt.QuatfArray, Gf.Quatf(1.0)),
                                 (anim.GetTranslationsAttr(), Vt.Vec3fArray, Gf.Vec3f(0.0)),
                                 (anim.GetScalesAttr(), Vt.Vec3hArray, Gf.Vec3h(1.0))):
        default = attr.Get(Usd.TimeCode.Default())
        if default is not None:
            attr.Set(kind(expand(default, identity)))
        for t in attr.GetTimeSamples():
            attr.Set(kind(expand(attr.Get(t), identity)), t)


def _author(stage, path: str) -> None:
    """An animated SMPL skeleton with official names at ``path``."""
    rng = np.random.default_rng(3)
    joints = rng.normal(scale=0.3, size=(24, 3))
    poses = rng.normal(scale=0.5, size=(len(TIMES), 72))
    roots = rng.normal(size=(len(TIMES), 3))
    author.author_skeleton(stage, path, joint_positions=joints, betas=[0.5, -1.0], poses=poses,
                           root_positions=roots, times=TIMES)


def _stage(names=None, **rename) -> Usd.Stage:
    """/Ref/Skel with official names and /Rig/Skel, the same rig renamed."""
    stage = Usd.Stage.CreateInMemory()
    author.set_stage_metadata(stage, up_axis="Y", meters_per_unit=1.0)
    _author(stage, "/Ref/Skel")
    _author(stage, "/Rig/Skel")
    if names is not None:
        _rename(stage, "/Rig/Skel", names, **rename)
    return stage


def _assert_same_as_reference(stage, **read_args) -> None:
    chars = {c.prim_path: c for c in read.read_scene(stage, **read_args).characters}
    ref, rig = chars["/Ref/Skel"], chars["/Rig/Skel"]
    np.testing.assert_allclose(rig.rest_joints, ref.rest_joints, atol=1e-6)
    np.testing.assert_array_equal(rig.betas, ref.betas)
    m_ref, m_rig = (read.read_motion(stage, c, TIMES) for c in (ref, rig))
    rot = [axis_angle_to_matrix(m.poses.reshape(-1, 24, 3)) for m in (m_ref, m_rig)]
    np.testing.assert_allclose(rot[1], rot[0], atol=1e-6)
    np.testing.assert_allclose(m_rig.root_position, m_ref.root_position, atol=1e-6)


# ------------------------------------------------------------------ conventions

CONVENTIONS = {
    "smpl": (JOINT_NAMES, {}),
    "smplx": (NAMES["smplx"], {"extras": SMPLX_EXTRAS}),
    "smpl-fbx": (tuple(f"m_avg_{n}" for n in FBX), {"root": "m_avg_root"}),
    "smpl-fbx-female": (tuple(f"f_avg_{n}" for n in FBX), {"root": "f_avg_root"}),
    "meshcapade": (FBX, {}),
    "phc": (NAMES["phc"], {}),
    "phc-smplh": (NAMES["phc"][:22] + ("L_Middle1", "R_Middle1"), {"extras": ((20, "L_Index1"),)}),
}


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_each_convention_reads_the_same_rest_pose_and_motion(convention):
    names, rename = CONVENTIONS[convention]
    stage = _stage(names, **rename)
    joints = [str(j) for j in UsdSkel.Skeleton(stage.GetPrimAtPath("/Rig/Skel")).GetJointsAttr().Get()]
    assert match_joints(joints).naming == convention.removesuffix("-female").removesuffix("-smplh")
    _assert_same_as_reference(stage)


def test_the_official_names_win_over_smplx_fingers():
    joints = author.smpl_joint_paths() + [author.smpl_joint_paths()[22] + "/left_middle1"]
    match = match_joints(joints)
    assert match.naming == "smpl" and match.problem is None
    np.testing.assert_array_equal(match.indices, np.arange(24))


def test_partial_convention_is_one_line_naming_the_closest_and_what_it_lacks():
    names = list(f"m_avg_{n}" for n in FBX)
    names[6], names[22], names[23] = "m_avg_Spine_2", "m_avg_LeftHand", "m_avg_RightHand"
    stage = _stage(names, root="m_avg_root")
    author.author_garment(stage, "/Rig/Shirt", points=np.eye(3), faces=[[0, 1, 2]], body_path="/Rig/Skel")
    with pytest.raises(SceneError) as info:
        read.read_scene(stage)
    message = str(info.value)
    assert "\n" not in message
    assert ("</Rig/Skel>: not an SMPL skeleton (closest naming: smpl-fbx, lacks SMPL joint(s) "
            "m_avg_Spine2, m_avg_L_Hand, m_avg_R_Hand: 21 of 24 found)") in message
    assert "--joint-map" in message and "retarget" in message


def test_untargeted_partial_skeleton_is_skipped_with_a_note():
    stage = _stage(FBX[:22] + ("L_Palm", "R_Palm"))
    skipped: list[str] = []
    scene = read.read_scene(stage, skipped=skipped)
    assert [c.prim_path for c in scene.characters] == ["/Ref/Skel"]
    (line,) = skipped
    assert "</Rig/Skel>: not an SMPL skeleton (closest naming: meshcapade" in line and "L_Hand, R_Hand" in line


def test_two_conventions_picking_different_joints_are_ambiguous():
    joints = [f"a/{p}" for p in _paths(f"m_avg_{n}" for n in FBX)] + [f"b/{p}" for p in _paths(FBX)]
    match = match_joints(["a", "b"] + joints)
    assert not match.missing
    assert "several conventions (smpl-fbx, meshcapade)" in match.problem and "joint map" in match.problem


def test_a_joint_named_twice_in_one_convention():
    joints = _paths(f"m_avg_{n}" for n in FBX)
    match = match_joints(joints + [joints[0] + "/f_avg_Pelvis"])
    assert "SMPL joint 'pelvis' appears twice" in match.problem and "smpl-fbx" in match.problem


def test_no_known_name_at_all_lists_the_official_ones():
    match = match_joints(["hips", "hips/spine"])
    assert match.naming == "smpl" and len(match.missing) == 24
    assert "lacks SMPL joint(s) pelvis, left_hip" in match.problem and "0 of 24 found" in match.problem


# -------------------------------------------------------------------- joint maps


def _write_map(tmp_path: Path, entries, name="joints.json") -> Path:
    path = tmp_path / name
    path.write_text(entries if isinstance(entries, str) else json.dumps(entries))
    return path


def test_joint_map_file_reads_a_custom_rig_the_same(tmp_path):
    stage = _stage(CUSTOM, root="rig_Root")
    skipped: list[str] = []
    assert [c.prim_path for c in read.read_scene(stage, skipped=skipped).characters] == ["/Ref/Skel"]
    assert "</Rig/Skel>" in skipped[0]
    path = _write_map(tmp_path, dict(zip(CUSTOM, JOINT_NAMES)))
    _assert_same_as_reference(stage, joint_map=path)
    toml = _write_map(tmp_path, "\n".join(f'{k} = "{v}"' for k, v in zip(CUSTOM, JOINT_NAMES)), "joints.toml")
    _assert_same_as_reference(stage, joint_map=toml)


def test_a_partial_joint_map_renames_a_few_joints_of_a_convention():
    names = list(FBX)
    names[0], names[3] = "Hips", "LowerBack"
    stage = _stage(names)
    entries = {"Hips": "pelvis", "LowerBack": "spine1"}
    joints = [str(j) for j in UsdSkel.Skeleton(stage.GetPrimAtPath("/Rig/Skel")).GetJointsAttr().Get()]
    assert match_joints(joints, parse_joint_map(entries)).naming == "meshcapade + joint_map"
    _assert_same_as_reference(stage, joint_map=entries)


@pytest.mark.parametrize("text, expect", [
    ({"Hips": "hips"}, "entry 'Hips': 'hips' is not an SMPL joint; valid: pelvis, left_hip"),
    ({"Hips": "pelvis", "Root": "pelvis"}, "entries 'Hips' and 'Root' both map to 'pelvis'"),
    ('{"Hips": "pelvis", "Hips": "spine1"}', "entry 'Hips' appears twice"),
    ({"Hips/Spine": "spine1"}, "entry 'Hips/Spine': keys are joint names"),
    ({"Hips": 3}, "entry 'Hips': 3 is not an SMPL joint"),
    (["Hips", "pelvis"], "expected a non-empty object"),
    ({}, "expected a non-empty object"),
    ("{oops", "not valid JSON"),
])
def test_joint_map_errors_name_the_file_and_entry(tmp_path, text, expect):
    path = _write_map(tmp_path, text)
    with pytest.raises(ArgumentError) as info:
        load_joint_map(path)
    assert str(info.value).startswith(f"{path}: ") and expect in str(info.value)


def test_missing_joint_map_file(tmp_path):
    with pytest.raises(ArgumentError, match=r"nope\.json: cannot read the joint map"):
        read.read_scene(Usd.Stage.CreateInMemory(), joint_map=tmp_path / "nope.json")


# --------------------------------------------------------------------------- CLI


def _renamed_walk(tmp_path: Path, names, **rename) -> Path:
    path = tmp_path / "renamed.usda"
    shutil.copy(WALK, path)
    stage = Usd.Stage.Open(str(path))
    _rename(stage, "/Character/Skeleton", names, **rename)
    stage.GetRootLayer().Save()
    return path


def _baked(cache: Path) -> np.ndarray:
    layer_stage = Usd.Stage.Open(str(cache))
    attr = UsdGeom.Mesh(layer_stage.GetPrimAtPath("/Character/Tshirt")).GetPointsAttr()
    return np.stack([np.array(attr.Get(t)) for t in (1001.0, 1010.0)])


def test_bake_with_fbx_names_and_with_a_joint_map_gives_the_same_points(tmp_path, capsys):
    frames = ["--frames", "1001:1010:9"]
    assert main(["bake", str(WALK), "-o", str(tmp_path / "ref.usdc"), *frames]) == 0
    fbx = _renamed_walk(tmp_path, [f"m_avg_{n}" for n in FBX], root="m_avg_root")
    assert main(["bake", str(fbx), "-o", str(tmp_path / "fbx.usdc"), *frames]) == 0
    np.testing.assert_allclose(_baked(tmp_path / "fbx.usdc"), _baked(tmp_path / "ref.usdc"), atol=1e-6)

    custom = _renamed_walk(tmp_path, CUSTOM)
    out = tmp_path / "custom.usdc"
    assert main(["bake", str(custom), "-o", str(out), *frames]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "</Character/Skeleton>: not an SMPL skeleton" in err
    joint_map = _write_map(tmp_path, dict(zip(CUSTOM, JOINT_NAMES)))
    assert main(["bake", str(custom), "-o", str(out), *frames, "--joint-map", str(joint_map)]) == 0
    np.testing.assert_allclose(_baked(out), _baked(tmp_path / "ref.usdc"), atol=1e-6)


def test_bake_joint_map_error_is_one_line(tmp_path, capsys):
    joint_map = _write_map(tmp_path, {"Hips": "pelvis", "Root": "pelvis"})
    out = tmp_path / "c.usdc"
    assert main(["bake", str(WALK), "-o", str(out), "--joint-map", str(joint_map)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(joint_map) in err and "'Root'" in err
    assert not out.exists()


def test_inspect_names_a_skipped_skeleton_and_what_to_do(tmp_path, capsys):
    path = tmp_path / "scene.usda"
    stage = _stage(CUSTOM)
    stage.RemovePrim("/Ref")
    stage.GetRootLayer().Export(str(path))
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "characters  0" in out and "problems    0" in out
    (line,) = [s for s in out.splitlines() if s.startswith("  skipped")]
    assert line.startswith(f"  skipped {path} </Rig/Skel>: not an SMPL skeleton (closest naming: ")
    assert "--joint-map" in line and "retarget the motion onto SMPL" in line
    joint_map = _write_map(tmp_path, dict(zip(CUSTOM, JOINT_NAMES)))
    assert main(["inspect", str(path), "--joint-map", str(joint_map)]) == 0
    out = capsys.readouterr().out
    assert "characters  1" in out and "  /Rig/Skel  gender neutral" in out and "  skipped" not in out


def test_the_joint_map_is_part_of_the_bake_digest(tmp_path):
    """A cache baked through one map is not 'up to date' for a bake through another."""
    from cloth_usd.baking import bake_plan

    custom = _renamed_walk(tmp_path, CUSTOM)
    names = dict(zip(CUSTOM, JOINT_NAMES))
    first = bake_plan(custom, joint_map=_write_map(tmp_path, names)).inputs_sha256
    assert bake_plan(custom, joint_map=names).inputs_sha256 == first  # the same map, from a dict
    mirror = {n: n.replace("left_", "R#").replace("right_", "left_").replace("R#", "right_") for n in JOINT_NAMES}
    swapped = {k: mirror[v] for k, v in names.items()}  # the rig read mirrored: a valid, different map
    assert bake_plan(custom, joint_map=swapped).inputs_sha256 != first


@pytest.fixture(scope="module")
def official_bake(tmp_path_factory):
    out = tmp_path_factory.mktemp("official") / "ref.usdc"
    assert main(["bake", str(WALK), "-o", str(out), "--frames", "1001:1049:24", "--no-progress"]) == 0
    return _baked_at(out, (1001.0, 1025.0, 1049.0))


def _baked_at(cache: Path, times) -> np.ndarray:
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(cache))
    return np.stack([np.array(layer.QueryTimeSample("/Character/Tshirt.points", t)) for t in times])


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_each_convention_bakes_the_same_points_as_the_official_names(convention, official_bake, tmp_path):
    names, rename = CONVENTIONS[convention]
    stage = _renamed_walk(tmp_path, names, **rename)
    out = tmp_path / "c.usdc"
    assert main(["bake", str(stage), "-o", str(out), "--frames", "1001:1049:24", "--no-progress"]) == 0
    np.testing.assert_allclose(_baked_at(out, (1001.0, 1025.0, 1049.0)), official_bake, atol=1e-6)
