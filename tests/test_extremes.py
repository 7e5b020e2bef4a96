"""Reliability at the extremes: poses at +-pi and past the joint limits, betas at +-5, tiny
and huge garments, broken garment topology, a garment far from its body, every unit and up
axis, a 10,000-frame shot in bounded memory; with the skinning tier and a learned tier run
by a hand-made ONNX bundle (no torch). No NaN or Inf is ever written, displacements stay
bounded, and inputs outside the trained range are warned about by garment and frame."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd

from cloth_usd.baking import bake
from cloth_usd.core.guard import GuardLimits
from cloth_usd.errors import GarmentError
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.limits import JOINT_LIMITS, betas_range_record, pose_outliers, pose_range, pose_range_record
from cloth_usd.datagen import walk_cycle
from cloth_usd.datagen.motion import JOINT_LIMITS as DATAGEN_LIMITS
from cloth_usd.datagen.motion import euler_to_poses
from cloth_usd.inspection import inspect_stage
from cloth_usd.usd.author import author_garment, author_skeleton, set_stage_metadata

from test_batch import tube

PRIM = "/Char/Tube"
MAX_OFFSET = GuardLimits().max_offset


@pytest.fixture(scope="module")
def body():
    return load_body_model()


def extreme_poses(seed: int = 0) -> np.ndarray:
    """(7, 72): rest; every joint at +pi about x, -pi about y, pi about z; every joint at the
    top of its limits; hyperextended knees, backward elbows, a hip at 166 deg; random
    rotations of 2.5..pi rad on every joint."""
    poses = np.zeros((7, 24, 3))
    poses[1, :, 0], poses[2, :, 1], poses[3, :, 2] = np.pi, -np.pi, np.pi
    poses[4] = euler_to_poses(JOINT_LIMITS[None, ..., 1]).reshape(24, 3)
    poses[5, 4] = poses[5, 5] = [-1.0, 0.0, 0.0]
    poses[5, 18], poses[5, 19], poses[5, 1] = [0.0, 1.6, 0.0], [0.0, -1.6, 0.0], [0.0, 0.0, 2.9]
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(24, 3))
    poses[6] = axes / np.linalg.norm(axes, axis=1, keepdims=True) * rng.uniform(2.5, np.pi, (24, 1))
    return poses.reshape(7, 72)


def write_stage(path: Path, body, *, betas=(), poses=None, up="Y", mpu=1.0, garment=None, frames=None) -> Path:
    """A character (walking, or ``poses`` at its rest place) wearing one garment at PRIM.

    ``garment``: a function of the character's joints giving (points [m], faces), default a tube.
    """
    betas = np.pad(np.asarray(betas, dtype=np.float64), (0, 10 - len(betas)))
    _, joints = shape_body(body, betas)
    if poses is None:
        poses, offset = walk_cycle(frames or 6)
        root = joints[0] + offset
    else:
        root = np.tile(joints[0], (len(poses), 1))
    count = len(poses)
    stage = Usd.Stage.CreateNew(str(path))
    set_stage_metadata(stage, up_axis=up, meters_per_unit=mpu, start=1, end=count)
    skel = author_skeleton(stage, "/Char/Skel", joint_positions=joints, betas=betas, poses=poses,
                           root_positions=root, times=np.arange(1.0, count + 1))
    points, faces = (garment or tube)(joints)
    author_garment(stage, PRIM, points=points, faces=faces, body_path=skel)
    stage.GetRootLayer().Save()
    return path


def read_points(cache: Path, prim: str = PRIM) -> np.ndarray:
    layer = Sdf.Layer.OpenAsAnonymous(str(cache))
    attr = f"{prim}.points"
    return np.stack([np.array(layer.QueryTimeSample(attr, t)) for t in layer.ListTimeSamplesForPath(attr)])


def fake_bundle(folder: Path, scale: float, poses: np.ndarray | None = None, far_fit: bool = False,
                bodies: np.ndarray | None = None) -> Path:
    """A coarse-tier bundle whose "model" moves each vertex by ``scale`` [m] along the body
    normal (an ONNX graph made by hand: Slice(features, 0:3) * scale); with ``poses`` (T, 72)
    it records their range as the poses it was trained on, else none. ``far_fit``: its fit
    model's garments lay a metre off the anchors, so any garment's fit attribute is far out.
    ``bodies`` (K, 10): the betas of the bodies it records it was trained on, else none."""
    onnx = pytest.importorskip("onnx", reason="building a test bundle needs onnx")
    pytest.importorskip("onnxruntime", reason="the learned tiers need onnxruntime")
    from onnx import TensorProto, helper, numpy_helper

    from cloth_usd.core.fit import FitModel
    from cloth_usd.runtime.bundle import write_bundle

    folder.mkdir(parents=True, exist_ok=True)
    inputs = [helper.make_tensor_value_info("features", TensorProto.FLOAT, ["B", "N", 7]),
              helper.make_tensor_value_info("nbr", TensorProto.INT64, ["N", "K"]),
              helper.make_tensor_value_info("nbr_mask", TensorProto.BOOL, ["N", "K"])]
    output = helper.make_tensor_value_info("delta", TensorProto.FLOAT, ["B", "N", 3])
    consts = {"lo": np.array([0]), "hi": np.array([3]), "axis": np.array([2]), "scale": np.float32(scale)}
    graph = helper.make_graph([helper.make_node("Slice", ["features", "lo", "hi", "axis"], ["normal"]),
                               helper.make_node("Mul", ["normal", "scale"], ["delta"])], "fake_coarse",
                              inputs, [output], [numpy_helper.from_array(np.asarray(v), k) for k, v in consts.items()])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)], ir_version=9),
              folder / "coarse_src.onnx")
    rng = np.random.default_rng(0)
    FitModel(anchors=np.array([412, 1290, 3021, 3500, 4200, 6540]), mean=np.full(6, -1.0 if far_fit else 0.02),
             loadings=rng.normal(0, 0.01, (6, 3)),
             noise_variance=np.full(6, 1e-6 if far_fit else 1.0)).save(folder / "fit_src.npz")
    training = {"manifest_sha256": "0" * 64, "description": "tests only"}
    if poses is not None:
        training["poses"] = pose_range_record(poses)
    if bodies is not None:
        training["bodies"] = betas_range_record(bodies)
    return write_bundle(folder / "bundle", name=f"fake-{scale}", category="tshirt",
                        coarse_onnx=folder / "coarse_src.onnx", detail_onnx=None, fit_npz=folder / "fit_src.npz",
                        configs={}, training_data=training, metrics={}, opset=18)


@pytest.fixture(scope="module")
def posed_stage(tmp_path_factory, body) -> Path:
    return write_stage(tmp_path_factory.mktemp("poses") / "poses.usda", body, poses=extreme_poses())


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and r.name.startswith("cloth_usd.baking")]


def test_limits_match_the_data_factory():
    assert JOINT_LIMITS is DATAGEN_LIMITS  # one table, re-exported by datagen
    assert pose_outliers(walk_cycle(96)[0]) is None


def test_poses_at_pi_and_past_the_limits_bake_finite_and_bounded(posed_stage, body, tmp_path, caplog):
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "c.usdc")
    pts = read_points(tmp_path / "c.usdc")
    assert pts.shape == (7, 192, 3) and np.isfinite(pts).all()
    # Skinning blends rigid joint motions: the tube (within 0.3 m of the pelvis at rest)
    # stays near the pelvis, which this character keeps at its rest place.
    _, joints = shape_body(body, np.zeros(10))
    assert np.linalg.norm(pts - joints[0], axis=-1).max() < 0.6
    g = result.garments[0]
    assert 0.0 < g.max_displacement_mm < 1000.0
    # skinning follows any pose and was trained on none: nothing to warn about the poses
    assert _warnings(caplog) == [] and g.warnings == ()


def test_learned_tier_at_extreme_poses_stays_finite_bounded_and_warns(posed_stage, tmp_path, caplog):
    bundle = fake_bundle(tmp_path / "plausible", 0.005)  # records no training poses: JOINT_LIMITS stand in
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=bundle)
    pts = read_points(tmp_path / "c.usdc")
    assert np.isfinite(pts).all()
    g = result.garments[0]
    assert g.bundle == "fake-0.005" and 0.0 < g.max_offset_mm < 150.0
    (message,) = [m for m in _warnings(caplog) if "posed outside" in m]
    assert f"<{PRIM}>" in message and "outside the trained joint limits at frame 2 " in message
    assert "and at 4 other of 7 frames" in message  # frame 5 (at the limits) is inside
    assert message in g.warnings


def test_a_bundle_that_records_its_training_poses_is_checked_against_them(posed_stage, tmp_path, caplog):
    """Real motion capture leaves JOINT_LIMITS in most frames (the CMU clips at the elbows,
    hands and ankles): a bundle trained on it warns against the angles it saw, not those."""
    extremes = extreme_poses()
    # trained on these very poses (and their negatives: a turn by pi reads back from USD as one by -pi)
    seen = fake_bundle(tmp_path / "seen", 0.005, poses=np.concatenate([extremes, -extremes]))
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=seen)
    assert not [m for m in _warnings(caplog) if "posed outside" in m]
    assert not [m for m in result.garments[0].warnings if "posed outside" in m]
    caplog.clear()
    walked = fake_bundle(tmp_path / "walked", 0.005, poses=walk_cycle(96)[0])  # trained on a walk only
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "w.usdc", tier="coarse", models=walked)
    expected = pose_outliers(extremes, limits=pose_range(walk_cycle(96)[0]))
    (message,) = [m for m in _warnings(caplog) if "posed outside" in m]
    assert (f"<{PRIM}>: body </Char/Skel> is posed outside the joint angles bundle 'fake-0.005' was trained on at "
            f"frame {expected.frames[0] + 1} ({expected.joint} ") in message
    assert f"and at {expected.frames.size - 1} other of 7 frames" in message and message in result.garments[0].warnings


@pytest.mark.parametrize("scale, why", [(5.0, "a vertex 50"), (float("nan"), "not finite")])
def test_a_wild_model_output_is_replaced_by_skinning_frame_by_frame(posed_stage, tmp_path, caplog, scale, why):
    bundle = fake_bundle(tmp_path / "wild", scale)
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=bundle, frames="1:3")
    pts = read_points(tmp_path / "c.usdc")
    bake(posed_stage, tmp_path / "s.usdc", frames="1:3")
    np.testing.assert_allclose(pts, read_points(tmp_path / "s.usdc"), atol=1e-6)  # whole frames, skinned
    (message,) = [m for m in _warnings(caplog) if "not a garment" in m]
    assert (f"<{PRIM}>: 3 of 3 frames of the coarse tier are not a garment and were replaced by the skinning "
            f"tier, first at frame 1 ({why}") in message
    g = result.garments[0]
    assert (g.fallback_skinning, g.fallback_coarse, g.max_offset_mm) == (3, 0, 0.0)
    prov = Sdf.Layer.FindOrOpen(str(tmp_path / "c.usdc")).customLayerData["cloth_usd"]["garments"][PRIM]
    assert (prov["fallback_skinning"], prov["fallback_coarse"]) == (3, 0)


def test_strict_refuses_a_frame_that_is_not_a_garment_and_writes_nothing(posed_stage, tmp_path):
    bundle = fake_bundle(tmp_path / "wild", 5.0)
    with pytest.raises(GarmentError, match=rf"<{PRIM}>: the coarse tier's frame 1 is not a garment \(a vertex "
                                           r"50\d\d\.\d mm .*--strict refuses it and nothing was written"):
        bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=bundle, frames="1:3", strict=True)
    assert not list(tmp_path.glob("*.usdc")) and not list(tmp_path.glob(".*tmp*"))
    plausible = fake_bundle(tmp_path / "plausible", 0.005)
    result = bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=plausible, frames="1:3", strict=True)
    assert result.garments[0].fallback_skinning == 0


def test_betas_at_plus_minus_5_warn_and_stay_finite(body, tmp_path, caplog):
    betas = [5.0, -5.0, 5.0, -5.0, 5.0, -5.0, 5.0, -5.0, 5.0, -5.0]
    scene = write_stage(tmp_path / "s.usda", body, betas=betas)
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(scene, tmp_path / "c.usdc")
    assert np.isfinite(read_points(tmp_path / "c.usdc")).all()
    (message,) = [m for m in _warnings(caplog) if "beta[0]" in m]  # (the tmp path names betas too)
    assert f"<{PRIM}>" in message and "beta[0] = 5, beta[1] = -5" in message and "|beta| <= 3" in message
    assert result.garments[0].max_displacement_mm < 1000.0


def test_a_garment_inside_its_body_at_rest_is_warned_about(body, tmp_path, caplog):
    """A shirt made for one body and worn by a larger one (the sample's shirt imported onto a
    body of betas 3, 3: 94% of its vertices inside, up to 76 mm) baked with no sign of it:
    every tier starts from a garment in the body. ``inspect`` says so before the bake, in
    the bake's words; a body model it cannot load is a problem there, as in a bake."""
    def narrow(joints):  # the tube at half its width and depth: in the torso
        points, faces = tube(joints)
        centre = np.array([joints[0, 0], 0.0, joints[0, 2]])
        return (points - centre) * [0.5, 1.0, 0.5] + centre, faces

    scene = write_stage(tmp_path / "s.usda", body, garment=narrow)
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(scene, tmp_path / "c.usdc")
    (message,) = [m for m in _warnings(caplog) if "inside the body" in m]
    assert f"<{PRIM}>: " in message and "lie more than 2 mm inside the body </Char/Skel> at rest" in message
    assert message in result.garments[0].warnings
    report = inspect_stage(scene)
    assert report.warnings == (f"{PRIM}: {message.split(f'<{PRIM}>: ')[1]}",) and not report.problems
    assert not inspect_stage(write_stage(tmp_path / "worn.usda", body)).warnings
    missing = inspect_stage(scene, body_model=tmp_path / "none.npz")
    assert not missing.warnings and missing.problems == (f"</Char/Skel>: {tmp_path / 'none.npz'}: body model "
                                                         "file not found",)


def test_a_body_past_the_bodies_a_bundle_was_trained_on_is_warned_about(body, tmp_path, caplog):
    """A body of betas 3, 3 lies past every body the T-shirt bundle saw (within +-2) but inside
    |beta| <= 3: the shape warning now measures against the bundle's own bodies."""
    scene = write_stage(tmp_path / "s.usda", body, betas=[3.0, 3.0])
    trained = np.zeros((2, 10))
    trained[:, :2] = [[-2.0, 2.0], [2.0, -2.0]]
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(scene, tmp_path / "c.usdc", tier="coarse",
                      models=fake_bundle(tmp_path / "b", 0.005, bodies=trained))
    (message,) = [m for m in _warnings(caplog) if "beta[0]" in m]
    assert ("has beta[0] = 3, beta[1] = 3, outside the bodies bundle 'fake-0.005' was trained on (beta[0] -2..2, "
            "beta[1] -2..2, by more than 0.5)") in message and message in result.garments[0].warnings
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        bake(scene, tmp_path / "k.usdc")  # the skinning tier: |beta| <= 3 holds, nothing to say
    assert not [m for m in _warnings(caplog) if "beta[0]" in m]


def test_a_fit_past_the_limit_is_clamped_and_warned_about(posed_stage, tmp_path, caplog):
    from cloth_usd.core.fit import FIT_LIMIT

    bundle = fake_bundle(tmp_path / "far", 0.005, far_fit=True)
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(posed_stage, tmp_path / "c.usdc", tier="coarse", models=bundle)
    (message,) = [m for m in _warnings(caplog) if "fit attribute" in m]
    assert f"<{PRIM}>: its fit on the body </Char/Skel>" in message
    assert f"the coarse tier reads it clamped to +-{FIT_LIMIT:g} (a bundle of its own: cloth-usd train-garment)" in message
    g = result.garments[0]
    assert message in g.warnings and max(abs(a) for a in g.fit) == pytest.approx(FIT_LIMIT)


def _suit(joints):
    """The torso tube with two leg tubes hung from it (a suit in one piece), down to below the knees."""
    points, faces = tube(joints)
    parts = [points]
    for side in (-1.0, 1.0):
        hip = joints[2 if side < 0 else 1]
        angles = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
        ring = np.stack([0.07 * np.cos(angles), np.zeros(12), 0.07 * np.sin(angles)], axis=1)
        heights = np.linspace(joints[0, 1] - 0.1, joints[0, 1] - 0.6, 8)
        leg = np.concatenate([ring + [hip[0], h, hip[2]] for h in heights])
        base = sum(len(p) for p in parts)
        quads = [[base + r * 12 + a, base + r * 12 + (a + 1) % 12, base + (r + 1) * 12 + a] for r in range(7)
                 for a in range(12)]
        quads += [[base + r * 12 + (a + 1) % 12, base + (r + 1) * 12 + (a + 1) % 12, base + (r + 1) * 12 + a]
                  for r in range(7) for a in range(12)]
        faces = np.concatenate([faces, quads, [[0, base, base + 1]]])  # hung from the tube's lowest ring
        parts.append(leg)
    return np.concatenate(parts), faces


def test_a_garment_with_legs_is_warned_about_for_a_category_bundle(body, tmp_path, caplog):
    """A suit in one piece, in a T-shirt's place: the T-shirt bundle's models were trained on no such
    garment, and a learned bake says so; the skinning tier and a plain tube say nothing."""
    scene = write_stage(tmp_path / "s.usda", body, garment=_suit)
    bundle = fake_bundle(tmp_path / "b", 0.005)
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(scene, tmp_path / "c.usdc", tier="coarse", models=bundle)
    (message,) = [m for m in _warnings(caplog) if "it has legs" in m]
    assert f"<{PRIM}>: it has legs" in message and "which no tshirt the bundle 'fake-0.005' was trained on" in message
    assert "its coarse tier reads it as one (models of its own: cloth-usd train-garment)" in message
    assert message in result.garments[0].warnings
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        bake(scene, tmp_path / "k.usdc")  # skinning: no model to mislead
        bake(write_stage(tmp_path / "t.usda", body), tmp_path / "t.usdc", tier="coarse", models=bundle)
    assert not [m for m in _warnings(caplog) if "it has legs" in m]


def _degenerate(joints):
    points, faces = tube(joints)
    return points, np.concatenate([faces, [[0, 0, 1], [5, 5, 5], [0, 16, 32]]])  # 2 zero-area, 1 sliver


def _duplicates(joints):
    points, faces = tube(joints)
    faces = faces.copy()
    faces[:20] = np.where(faces[:20] < 40, faces[:20] + len(points), faces[:20])  # use the copies
    return np.concatenate([points, points[:40]]), faces


def _non_manifold(joints):
    points, faces = tube(joints)
    fins = points[:3] + [0.0, 0.0, -0.05]
    n = len(points)
    return np.concatenate([points, fins]), np.concatenate([faces, [[0, 1, n], [0, 1, n + 1], [1, 0, n + 2]]])


def _pieces(joints):
    a, fa = tube(joints)
    b, fb = tube(joints, around=8, rows=3, shift=(0.0, 0.45, 0.0))
    return np.concatenate([a, b, [[5.0, 5.0, 5.0]]]), np.concatenate([fa, fb + len(a)])  # and an unused vertex


def _polygons(joints):
    points, _ = tube(joints, around=16, rows=12)
    quads = [[r * 16 + a, r * 16 + (a + 1) % 16, (r + 1) * 16 + (a + 1) % 16, (r + 1) * 16 + a]
             for r in range(11) for a in range(16)]
    return points, quads + [list(range(16))[::-1]]  # quads and a 16-gon cap


def _tiny(joints):
    return tube(joints, around=12, rows=17)  # 204 vertices


def _far(joints):
    return tube(joints, shift=(3.0, 0.0, 0.0))


GARMENTS = {"degenerate_faces": _degenerate, "duplicate_vertices": _duplicates, "non_manifold": _non_manifold,
            "disconnected_pieces": _pieces, "polygons": _polygons, "tiny": _tiny, "far_from_body": _far}


@pytest.fixture(scope="module")
def odd_bundle(tmp_path_factory) -> Path:
    return fake_bundle(tmp_path_factory.mktemp("odd"), 0.005)


@pytest.mark.parametrize("name", GARMENTS)
@pytest.mark.parametrize("tier", ["skinning", "coarse"])
def test_odd_garments_bake_finite(body, tmp_path, caplog, name, tier, odd_bundle):
    scene = write_stage(tmp_path / "s.usda", body, garment=GARMENTS[name], frames=4)
    models = odd_bundle if tier == "coarse" else None
    with caplog.at_level(logging.WARNING, logger="cloth_usd.baking"):
        result = bake(scene, tmp_path / "c.usdc", tier=tier, models=models)
    pts = read_points(tmp_path / "c.usdc")
    n = len(GARMENTS[name](shape_body(body, np.zeros(10))[1])[0])
    assert pts.shape == (4, n, 3) and np.isfinite(pts).all()
    g = result.garments[0]
    assert g.vertices == n and np.isfinite(g.max_displacement_mm) and g.max_offset_mm <= MAX_OFFSET * 1000
    far = [m for m in _warnings(caplog) if "from the body" in m]
    if name == "far_from_body":
        assert len(far) == 1 and f"<{PRIM}>: the garment lies 2." in far[0] and "check its cloth:body" in far[0]
    else:
        assert not far, far
    # The fake model puts garments on the body (I M_b plus 5 mm): vertices metres away (the far
    # garment, the stray vertex among the pieces) would jump there, and the tiny tube, whose
    # neighbours map to body vertices far apart, has its edges stretched past 2x; those frames
    # are skinned, with a warning.
    replaced = [m for m in _warnings(caplog) if "not a garment and were replaced by the skinning tier" in m]
    assert len(replaced) == (tier == "coarse" and name in ("far_from_body", "disconnected_pieces", "tiny")), replaced
    assert not [m for m in _warnings(caplog) if "was not finite" in m]


def test_a_huge_garment_bakes(body, tmp_path):
    scene = write_stage(tmp_path / "s.usdc", body, garment=lambda j: tube(j, around=256, rows=200), frames=2)
    result = bake(scene, tmp_path / "c.usdc")
    pts = read_points(tmp_path / "c.usdc")
    assert result.garments[0].vertices == 51200 and pts.shape == (2, 51200, 3) and np.isfinite(pts).all()


def test_every_unit_and_up_axis_bakes_the_same_garment(body, tmp_path):
    """Points come back in each stage's units and axes; converted to metres, Y-up, they agree."""
    to_y_up = {"Y": np.eye(3), "Z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])}
    baked = {}
    for up in ("Y", "Z"):
        for mpu in (1.0, 0.01, 0.001):
            scene = write_stage(tmp_path / f"{up}{mpu}.usda", body, up=up, mpu=mpu, frames=3)
            bake(scene, tmp_path / f"{up}{mpu}.usdc")
            baked[up, mpu] = read_points(tmp_path / f"{up}{mpu}.usdc") * mpu @ to_y_up[up].T
    reference = baked["Y", 1.0]
    for key, pts in baked.items():
        np.testing.assert_allclose(pts, reference, atol=1e-4, err_msg=str(key))  # 0.1 mm: float32 in mm
    assert np.abs(reference[-1] - reference[0]).max() > 0.01  # it moved


LONG_SHOT = """
import json, resource, sys
from cloth_usd.baking import bake
rss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
bake(sys.argv[1], sys.argv[2], frames="1:100")
short = rss()
bake(sys.argv[1], sys.argv[3])
print(json.dumps({"short": short, "long": rss()}))
"""


def test_a_10000_frame_shot_streams_in_bounded_memory(body, tmp_path):
    """Peak RSS of a 10k-frame bake exceeds a 100-frame bake's by about the cache it writes,
    not by the frames' float64 intermediates (the bake hands frames to the writer a batch at a time)."""
    scene = write_stage(tmp_path / "long.usdc", body, frames=10000)
    cache = tmp_path / "long_cache.usdc"
    out = subprocess.run([sys.executable, "-c", LONG_SHOT, str(scene), str(tmp_path / "short.usdc"), str(cache)],
                         capture_output=True, text=True, check=True)
    rss = json.loads(out.stdout.strip().splitlines()[-1])
    points = read_points(cache)
    assert points.shape == (10000, 192, 3) and np.isfinite(points).all()
    cache_mib = cache.stat().st_size / 2**20
    growth = rss["long"] - rss["short"]
    print(f"10,000 frames x 192 vertices: peak RSS {rss['long']:.0f} MiB, +{growth:.0f} MiB over 100 frames; "
          f"cache {cache_mib:.0f} MiB")
    assert growth < 2.0 * cache_mib + 16.0


def test_strict_from_the_command_line_is_one_line_and_exit_2(posed_stage, tmp_path, capsys):
    from cloth_usd.cli import main

    bundle = fake_bundle(tmp_path / "wild", 5.0)
    args = ["bake", str(posed_stage), "-o", str(tmp_path / "c.usdc"), "--tier", "coarse", "--models", str(bundle),
            "--frames", "1:3", "--no-progress"]
    assert main(args + ["--strict"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the coarse tier's frame 1 is not a garment" in err[0] and "--strict" in err[0]
    assert not (tmp_path / "c.usdc").exists()
    assert main(args) == 0
    assert "guard replaced 0 frames by coarse and 3 by skinning" in capsys.readouterr().out
