"""core.heading: the learned tiers see every heading as facing +Z, and give the same local garment."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cloth_usd.core.body import lbs, load_body_model
from cloth_usd.core.heading import Heading, heading_frame, root_yaw, yaw_matrices
from cloth_usd.core.pipeline import CoarseBase, CoarseFeatures, CoarseForm, prepare_pair, run_tiers
from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
from cloth_usd.errors import ArgumentError
from cloth_usd.runtime.bundle import find_bundle


def _turned(poses, transl, root_joint, deg):
    """The same motion with the whole character turned by ``deg`` about +Y through the origin."""
    turn = Rotation.from_euler("y", deg, degrees=True)
    out = np.array(poses, dtype=np.float64)
    out[:, :3] = (turn * Rotation.from_rotvec(out[:, :3])).as_rotvec()
    return out, turn.apply(transl + root_joint) - root_joint, turn


@pytest.fixture(scope="module")
def shirt():
    body = load_body_model()
    betas = np.zeros(10)
    betas[:2] = (0.5, 1.0)
    rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=500))
    pair = prepare_pair(body, betas, rest, faces, find_bundle("tshirt").fit)
    poses, transl = walk_cycle(5)
    poses[:, :3] += [0.3, 0.8, -0.2]  # a leaning, already turned root
    return body, pair, poses, transl + [0.4, 0.0, 1.5]


def test_root_yaw_reads_a_turn_about_up_exactly():
    rng = np.random.default_rng(1)
    poses = rng.normal(0.0, 0.5, (6, 72))
    yaw = root_yaw(poses)
    for deg in (30.0, 137.0, -100.0):
        turned, _, _ = _turned(poses, np.zeros((6, 3)), np.zeros(3), deg)
        diff = np.angle(np.exp(1j * (root_yaw(turned) - yaw - np.radians(deg))))
        np.testing.assert_allclose(diff, 0.0, atol=1e-12)


def test_yaw_of_a_pure_turn_and_of_the_rest_pose():
    poses = np.zeros((3, 72))
    poses[1, 1] = 0.7
    poses[2, :3] = [np.pi, 0.0, 0.0]  # upside down about a horizontal axis: no twist, read as 0
    np.testing.assert_allclose(root_yaw(poses), [0.0, 0.7, 0.0], atol=1e-12)
    np.testing.assert_allclose(yaw_matrices(np.array([np.pi / 2])) @ [0, 0, 1], [[1, 0, 0]], atol=1e-12)
    with pytest.raises(ArgumentError, match=r"poses must be \(T, 72\)"):
        root_yaw(np.zeros((2, 3)))


def test_the_canonical_body_is_the_world_body_turned_about_the_pelvis(shirt):
    body, pair, poses, transl = shirt
    frame = heading_frame(poses, transl, pair.joints[0])
    canonical = frame.canonical_poses(poses)
    np.testing.assert_allclose(root_yaw(canonical), 0.0, atol=1e-12)
    np.testing.assert_allclose(canonical[:, 3:], poses[:, 3:])  # only the root changes
    world, _ = lbs(body, pair.v_shaped, pair.joints, poses, transl)
    turned, _ = lbs(body, pair.v_shaped, pair.joints, canonical, transl)
    np.testing.assert_allclose(frame.to_world(turned), world, atol=1e-9)
    np.testing.assert_allclose(frame.to_canonical(world), turned, atol=1e-9)


def test_the_turn_is_the_yaw_matrices_about_the_pelvis():
    """HeadingFrame turns points component by component: the same values as ``yaw_matrices`` applied
    about each frame's pivot."""
    rng = np.random.default_rng(3)
    frame = heading_frame(rng.normal(0.0, 0.8, (4, 72)), rng.normal(0.0, 1.0, (4, 3)), np.array([0.0, 0.9, 0.1]))
    points = rng.normal(0.0, 1.0, (4, 9, 3))
    for turned, yaw in ((frame.to_world(points), frame.yaw), (frame.to_canonical(points), -frame.yaw)):
        pivot = frame.pivot[:, None, :]
        np.testing.assert_allclose(turned, np.einsum("tab,tnb->tna", yaw_matrices(yaw), points - pivot) + pivot,
                                   rtol=0, atol=1e-15)


def _wavy_coarse(feats, graph):
    """A stand-in model that reads absolute directions: body normal and position (and, with
    the contact features, the nearest body normal and the distance to it)."""
    out = 0.01 * np.tanh(feats[..., 0:3] * 3.0 + feats[..., 3:6] * 5.0)
    if feats.shape[-1] == 11:
        out += feats[..., 7:10] * np.maximum(0.01 - feats[..., 10:11], 0.0)
    return out


def _wavy_detail(feats, attrs, graph):
    return 0.004 * np.sin(feats[..., 3:6] * 20.0) * np.tanh(attrs[:, None, :3].sum(-1, keepdims=True) + 1.0)


@pytest.mark.parametrize("features", list(CoarseFeatures))
@pytest.mark.parametrize("base", list(CoarseBase))
def test_learned_tiers_give_the_same_local_garment_at_any_heading(shirt, base, features):
    body, pair, poses, transl = shirt
    ref, _ = run_tiers(body, pair, poses, transl, _wavy_coarse, _wavy_detail,
                       form=CoarseForm(base, Heading.CANONICAL, features))
    for deg in (0.0, 30.0, 137.0, 180.0):
        p, t, turn = _turned(poses, transl, pair.joints[0], deg)
        got, _ = run_tiers(body, pair, p, t, _wavy_coarse, _wavy_detail,
                           form=CoarseForm(base, Heading.CANONICAL, features))
        local = turn.inv().apply(got.reshape(-1, 3)).reshape(got.shape)
        assert np.abs(local - ref).max() < 1e-5  # 1e-2 mm


def test_without_the_canonical_heading_the_same_models_depend_on_it(shirt):
    """The test above is not vacuous: a world-frame run of the same models changes with heading."""
    body, pair, poses, transl = shirt
    ref, _ = run_tiers(body, pair, poses, transl, _wavy_coarse, _wavy_detail, form=CoarseForm(heading=Heading.WORLD))
    p, t, turn = _turned(poses, transl, pair.joints[0], 137.0)
    got, _ = run_tiers(body, pair, p, t, _wavy_coarse, _wavy_detail, form=CoarseForm(heading=Heading.WORLD))
    local = turn.inv().apply(got.reshape(-1, 3)).reshape(got.shape)
    assert np.abs(local - ref).max() > 2e-3


@pytest.mark.parametrize("heading", list(Heading))
@pytest.mark.parametrize("base", list(CoarseBase))
def test_precomputed_world_skinning_is_the_skinned_base_in_either_heading(shirt, heading, base):
    """The baker skins each frame once and hands the world-frame result to run_tiers."""
    from cloth_usd.core.skinning import skin_garment

    body, pair, poses, transl = shirt
    ref, ref_moved = run_tiers(body, pair, poses, transl, _wavy_coarse, _wavy_detail,
                               form=CoarseForm(base, heading), batch_size=2)
    skinned = skin_garment(pair.binding, poses, transl, body.parents)
    got, moved = run_tiers(body, pair, poses, transl, _wavy_coarse, _wavy_detail,
                           form=CoarseForm(base, heading), batch_size=2, skinned=skinned)
    if heading is Heading.WORLD:  # the same numbers, not merely close ones
        np.testing.assert_array_equal(got, ref)
    else:  # skinned in the world and turned, or skinned turned: round-off apart
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(moved, ref_moved)
    with pytest.raises(ArgumentError, match=r"skinned: expected \(5, \d+, 3\)"):
        run_tiers(body, pair, poses, transl, _wavy_coarse, form=CoarseForm(CoarseBase.SKINNED), skinned=skinned[:4])


def _pose_reading_model(canonical_poses):
    """A stand-in garment model that reads every joint's rotation, the root's among them."""
    from cloth_usd.core.garment_inputs import pose_features

    feats = pose_features(canonical_poses)
    weights = np.random.default_rng(3).normal(size=(feats.shape[1], 3))
    return 0.01 * np.tanh(feats @ weights)[:, None, :] * np.ones((1, _pose_reading_model.n, 1))


def test_a_garment_model_gives_the_same_local_garment_at_any_heading(shirt):
    from cloth_usd.core.pipeline import run_garment_model

    body, pair, poses, transl = shirt
    _pose_reading_model.n = pair.num_vertices
    ref, _ = run_garment_model(body, pair, poses, transl, _pose_reading_model)
    for deg in (0.0, 30.0, 137.0, 180.0):
        p, t, turn = _turned(poses, transl, pair.joints[0], deg)
        got, _ = run_garment_model(body, pair, p, t, _pose_reading_model)
        local = turn.inv().apply(got.reshape(-1, 3)).reshape(got.shape)
        assert np.abs(local - ref).max() < 1e-5  # 1e-2 mm
    # not vacuous: the stand-in reads the root, so world poses would change its displacement
    p, _, _ = _turned(poses, transl, pair.joints[0], 137.0)
    assert np.abs(_pose_reading_model(p) - _pose_reading_model(poses)).max() > 2e-3
