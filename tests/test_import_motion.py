"""`cloth-usd import-motion`: real CMU clips (two rigs) and an AMASS file as shots that bake.

The two BVH fixtures in tests/data/mocap are 1 s of CMU walks (see CREDITS.md there).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("pxr", reason="import-motion writes USD (pip install usd-core)")

from pxr import Sdf, Usd, UsdSkel  # noqa: E402

import cloth_usd  # noqa: E402
from cloth_usd.cli import main  # noqa: E402
from cloth_usd.core.body import joint_transforms  # noqa: E402
from cloth_usd.core.rotations import axis_angle_to_matrix  # noqa: E402
from cloth_usd.core.smpl import JOINT_NAMES  # noqa: E402
from cloth_usd.datagen.bvh import BVH_RIGS, bvh_forward_kinematics, read_bvh  # noqa: E402
from cloth_usd.errors import ArgumentError, GarmentError, MotionFileError, OutputExistsError  # noqa: E402
from cloth_usd.motion_import import import_motion  # noqa: E402
from cloth_usd.usd.author import smpl_joint_paths  # noqa: E402
from cloth_usd.usd.read import read_motion, read_scene  # noqa: E402

DATA = Path(__file__).parent / "data" / "mocap"
SAMPLE = Path(__file__).parents[1] / "samples" / "walk_tshirt" / "scene.usda"
SAMPLE_BETAS = [0.6, -0.4, 0.2]
CLIPS = {"cmu-mb": DATA / "cmu_mb_02_01_walk.bvh", "cmu-daz": DATA / "cmu_daz_12_01_walk.bvh"}
#: (SMPL joint, SMPL joint further down the same limb): the bones compared with the BVH's.
BONES = {
    "left upper arm": ("left_shoulder", "left_elbow"), "right upper arm": ("right_shoulder", "right_elbow"),
    "left forearm": ("left_elbow", "left_wrist"), "right forearm": ("right_elbow", "right_wrist"),
    "left thigh": ("left_hip", "left_knee"), "right thigh": ("right_hip", "right_knee"),
    "left shin": ("left_knee", "left_ankle"), "right shin": ("right_knee", "right_ankle"),
    "spine": ("spine1", "spine3"),
}
TOL_DEG = 2.0  # measured: < 0.3 deg (float32 quaternions in USD)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _read_back(path: Path):
    """(character, motion, stage) as the baker reads them."""
    stage = Usd.Stage.Open(str(path))
    scene = read_scene(stage)
    assert len(scene.characters) == 1
    char = scene.characters[0]
    times = np.arange(stage.GetStartTimeCode(), stage.GetEndTimeCode() + 1)
    return char, read_motion(stage, char, times), stage


@pytest.mark.parametrize("rig", sorted(CLIPS))
def test_each_rig_imports_into_a_shot_that_bakes(rig, tmp_path):
    shot = tmp_path / "shot.usda"
    result = import_motion(CLIPS[rig], shot, garments=[SAMPLE])
    assert result.rig == rig and result.fps == 30.0
    assert result.source_frames == (1, 29) and result.frames == 29  # frame 0: cgspeed's synthetic T-pose
    assert np.allclose(result.betas[:3], SAMPLE_BETAS, atol=1e-6)  # taken from the garment's skeleton

    stage = Usd.Stage.Open(str(shot))
    assert stage.GetTimeCodesPerSecond() == 30.0 and stage.GetFramesPerSecond() == 30.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1001.0, 1000.0 + result.frames)
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Character/Skeleton"))
    assert stage.GetPrimAtPath("/Character").IsA(UsdSkel.Root)
    assert list(skel.GetJointsAttr().Get()) == smpl_joint_paths()
    assert np.allclose(skel.GetPrim().GetAttribute("smpl:betas").Get()[:3], SAMPLE_BETAS, atol=1e-6)
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Character/Skeleton/Motion"))
    assert len(anim.GetRotationsAttr().GetTimeSamples()) == result.frames
    garment = stage.GetPrimAtPath("/Character/Tshirt")
    assert garment.GetAttribute("cloth:category").Get() == "tshirt"
    assert [str(t) for t in garment.GetRelationship("cloth:body").GetTargets()] == ["/Character/Skeleton"]

    baked = cloth_usd.bake(shot, tmp_path / "cache.usdc", shot=tmp_path / "shot_cloth.usda", tier="skinning")
    (g,) = baked.garments
    assert g.prim_path == "/Character/Tshirt" and g.frames == result.frames
    assert g.mean_body_distance_mm < 30.0  # the garment sits on the imported body
    cache = Usd.Stage.Open(str(tmp_path / "shot_cloth.usda"))
    points = cache.GetPrimAtPath("/Character/Tshirt").GetAttribute("points")
    assert len(points.GetTimeSamples()) == result.frames


@pytest.mark.parametrize("rig", sorted(CLIPS))
def test_bones_point_where_the_mocap_has_them(rig, tmp_path):
    result = import_motion(CLIPS[rig], tmp_path / "shot.usda")
    char, motion, _ = _read_back(result.output)
    rot = axis_angle_to_matrix(motion.poses.reshape(-1, 24, 3))
    smpl_pos = joint_transforms(rot, char.rest_joints)[0]  # (T, 24, 3)

    bvh = read_bvh(CLIPS[rig])
    by_smpl = {smpl: name for name, smpl in BVH_RIGS[rig].items()}
    index = {name: i for i, name in enumerate(bvh.names)}
    first, last = result.source_frames
    bvh_pos = bvh_forward_kinematics(bvh)[1][first:last + 1]  # Y up: no axis conversion
    errors = {}
    for bone, (a, b) in BONES.items():
        smpl_dir = _unit(smpl_pos[:, JOINT_NAMES.index(b)] - smpl_pos[:, JOINT_NAMES.index(a)])
        bvh_dir = _unit(bvh_pos[:, index[by_smpl[b]]] - bvh_pos[:, index[by_smpl[a]]])
        errors[bone] = np.degrees(np.arccos(np.clip(np.sum(smpl_dir * bvh_dir, axis=-1), -1, 1))).max()
    assert max(errors.values()) < TOL_DEG, errors
    # the units detected: the pelvis travels as far as the hips do, in metres (about 1.2 m in this 1 s walk)
    unit = {"cmu-mb": 0.0254 / 0.45, "cmu-daz": 0.01}[rig]
    hips = bvh_pos[:, 0, [0, 2]] * unit
    travelled = np.linalg.norm(motion.root_position[-1, [0, 2]] - motion.root_position[0, [0, 2]])
    assert travelled == pytest.approx(np.linalg.norm(hips[-1] - hips[0]), abs=1e-4) and 0.8 < travelled < 1.6
    # a walk: the arms hang (CMU's rest is a T-pose, so a T-pose result would fail here)
    shoulder, elbow = JOINT_NAMES.index("left_shoulder"), JOINT_NAMES.index("left_elbow")
    assert np.all(_unit(smpl_pos[:, elbow] - smpl_pos[:, shoulder])[:, 1] < -0.7)


def test_amass_file(tmp_path):
    rng = np.random.default_rng(3)
    frames, rate = 21, 60.0
    poses = rng.normal(0.0, 0.2, size=(frames, 156))
    trans = np.cumsum(rng.normal(0.0, 0.01, size=(frames, 3)), axis=0)
    betas = rng.normal(0.0, 0.5, size=16)
    path = tmp_path / "clip_poses.npz"
    np.savez(path, poses=poses, trans=trans, betas=betas, gender=np.array("female"), mocap_framerate=rate)

    result = import_motion(path, tmp_path / "shot.usda", fps=30.0)
    assert result.rig == "amass" and result.frames == 11 and result.gender == "female"
    assert np.allclose(result.betas, betas[:10])
    char, motion, stage = _read_back(result.output)
    assert char.gender == "female" and np.allclose(char.betas, betas[:10], atol=1e-6)
    # every other file frame; the body joints as AMASS gives them (hands zero), the root turned Z up -> Y up
    expected = np.zeros((11, 72))
    expected[:, :66] = poses[::2, :66]
    z_to_y = Rotation.from_euler("x", -90, degrees=True)
    expected[:, :3] = (z_to_y * Rotation.from_rotvec(expected[:, :3])).as_rotvec()
    got = Rotation.from_rotvec(motion.poses.reshape(-1, 3))
    want = Rotation.from_rotvec(expected.reshape(-1, 3))
    assert np.degrees((got.inv() * want).magnitude()).max() < 0.05
    offset = motion.root_position - motion.root_position[0]
    assert np.allclose(offset, z_to_y.apply(trans[::2] - trans[0]), atol=1e-5)


def test_frames_and_fps(tmp_path):
    result = import_motion(CLIPS["cmu-daz"], tmp_path / "shot.usda", frames="4:19", fps=15.0, start=1.0)
    assert result.source_frames == (4, 19) and result.frames == 8 and result.fps == 15.0
    stage = Usd.Stage.Open(str(result.output))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, 8.0)
    with pytest.raises(ArgumentError, match=r"--frames 4:99: .*cmu_daz_12_01_walk\.bvh has frames 0:29"):
        import_motion(CLIPS["cmu-daz"], tmp_path / "other.usda", frames="4:99")
    with pytest.raises(ArgumentError, match="--frames '9:4'"):
        import_motion(CLIPS["cmu-daz"], tmp_path / "other.usda", frames="9:4")


def test_mixamo_names(tmp_path):
    clip = Path(__file__).parent / "datagen" / "data" / "tpose_26.bvh"  # Mixamo names, cm, 10 frames at 25 fps
    result = import_motion(clip, tmp_path / "shot.usda")
    assert result.rig == "mixamo" and result.source_frames == (0, 9) and result.frames == 11  # 0.36 s at 30 fps


# --------------------------------------------------------------------------- errors
def test_missing_file(tmp_path, capsys):
    with pytest.raises(MotionFileError, match=r"nope\.bvh: no such motion file"):
        import_motion(tmp_path / "nope.bvh", tmp_path / "shot.usda")
    assert main(["import-motion", str(tmp_path / "nope.bvh"), "-o", str(tmp_path / "shot.usda")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope.bvh: no such motion file" in err
    assert not (tmp_path / "shot.usda").exists()


def test_unknown_rig_needs_a_joint_map(tmp_path):
    text = CLIPS["cmu-daz"].read_text()
    renamed = {"hip": "root", "abdomen": "belly", "chest": "ribs", "lShldr": "lUpperArmBone",
               "rShldr": "rUpperArmBone", "lThigh": "lThighBone", "rThigh": "rThighBone"}
    for old, new in renamed.items():
        text = text.replace(f"JOINT {old}\n", f"JOINT {new}\n").replace(f"ROOT {old}\n", f"ROOT {new}\n")
    clip = tmp_path / "custom.bvh"
    clip.write_text(text)
    with pytest.raises(MotionFileError, match=r"custom\.bvh: .*no known BVH rig.*--joint-map"):
        import_motion(clip, tmp_path / "shot.usda")
    daz = BVH_RIGS["cmu-daz"]
    mapping = {renamed.get(k, k): v for k, v in daz.items()}
    map_file = tmp_path / "rig.json"
    map_file.write_text(json.dumps(mapping))
    result = import_motion(clip, tmp_path / "shot.usda", joint_map=map_file)
    assert result.rig == "joint map" and result.frames == 30  # a rig not known as cgspeed's keeps frame 0
    # a map missing a needed joint names it
    del mapping["lUpperArmBone"]
    map_file.write_text(json.dumps(mapping))
    with pytest.raises(MotionFileError, match=r"custom\.bvh: no BVH joint maps to the SMPL joint 'left_shoulder'"):
        import_motion(clip, tmp_path / "shot2.usda", joint_map=map_file)


def test_existing_output_needs_force(tmp_path):
    shot = tmp_path / "shot.usda"
    shot.write_text("#usda 1.0\n")
    with pytest.raises(OutputExistsError, match=r"shot\.usda: already exists; pass --force"):
        import_motion(CLIPS["cmu-mb"], shot)
    assert shot.read_text() == "#usda 1.0\n"
    assert main(["import-motion", str(CLIPS["cmu-mb"]), "-o", str(shot), "--force", "--fps", "10"]) == 0
    assert Usd.Stage.Open(str(shot)).GetPrimAtPath("/Character/Skeleton/Motion")
    assert [p.name for p in tmp_path.iterdir()] == ["shot.usda"]  # no temporary file left


def test_bad_arguments(tmp_path):
    from cloth_usd.motion_import import parse_betas

    with pytest.raises(ArgumentError, match="--betas 'a,b'"):
        parse_betas("a,b")
    with pytest.raises(ArgumentError, match="at most 10"):
        parse_betas(",".join(["0.1"] * 11))
    with pytest.raises(ArgumentError, match=r"clip\.fbx: unknown motion file type"):
        import_motion(tmp_path / "clip.fbx", tmp_path / "shot.usda")
    with pytest.raises(ArgumentError, match=r"--garment .*nothere\.usda: no such file"):
        import_motion(CLIPS["cmu-mb"], tmp_path / "shot.usda", garments=[tmp_path / "nothere.usda"])
    empty = tmp_path / "empty.usda"
    empty.write_text('#usda 1.0\ndef Xform "World"\n{\n}\n')
    with pytest.raises(GarmentError, match=r"--garment .*empty\.usda: holds no garment"):
        import_motion(CLIPS["cmu-mb"], tmp_path / "shot.usda", garments=[empty])
    assert not (tmp_path / "shot.usda").exists()


def test_a_garment_in_another_folder_is_referenced_relatively_without_a_usd_warning(tmp_path, capfd):
    """The shot is authored beside its output, so the relative reference resolves while it is
    made (authored in memory, USD printed "Could not open asset" for every such garment)."""
    import shutil

    out, garments = tmp_path / "shots", tmp_path / "garments"
    out.mkdir()
    garments.mkdir()
    shutil.copy(SAMPLE, garments / "shirt.usda")  # "../garments/shirt.usda" does not resolve from the cwd
    capfd.readouterr()
    import_motion(CLIPS["cmu-mb"], out / "shot.usda", garments=[garments / "shirt.usda"])
    err = capfd.readouterr().err
    assert "Could not open asset" not in err, err
    layer = Sdf.Layer.FindOrOpen(str(out / "shot.usda"))
    refs = layer.GetPrimAtPath(Sdf.Path("/Character/Tshirt")).referenceList.GetAddedOrExplicitItems()
    assert [r.assetPath for r in refs] == ["../garments/shirt.usda"]
    assert not list(out.glob(".*tmp*"))  # no temporary file left
