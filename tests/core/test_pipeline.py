"""core.pipeline: the body patch a garment reads gives what the whole posed body gives."""

import numpy as np
import pytest

from cloth_usd.core.body import body_model_from_arrays, lbs, load_body_model, shape_body
from cloth_usd.core.features import vertex_normals
from cloth_usd.core.pipeline import body_patch, coarse_model_features, pose_body, prepare_pair
from cloth_usd.datagen import TShirtParams, make_tshirt, walk_cycle
from cloth_usd.runtime.bundle import find_bundle
from tests.conftest import tiny_body_arrays



@pytest.mark.parametrize("posedirs", [False, True], ids=["embedded", "with-posedirs"])
def test_lbs_on_a_vertex_subset_equals_the_full_pose(posedirs):
    body = body_model_from_arrays(tiny_body_arrays(num_vertices=64)) if posedirs else load_body_model()
    v_shaped, joints = shape_body(body, np.linspace(-1, 1, 10))
    poses, transl = walk_cycle(3)
    full, full_joints = lbs(body, v_shaped, joints, poses, transl)
    idx = np.array([0, 17, 40, body.num_vertices - 1])
    sub, sub_joints = lbs(body, v_shaped, joints, poses, transl, vertices=idx)
    np.testing.assert_allclose(sub, full[:, idx], atol=1e-12)
    np.testing.assert_allclose(sub_joints, full_joints)


def test_body_patch_keeps_every_triangle_around_an_associated_vertex():
    faces = np.array([[0, 1, 2], [0, 2, 3], [3, 4, 5], [5, 6, 7]])
    patch = body_patch(faces, np.array([2, 2, 0]))
    np.testing.assert_array_equal(patch.vertices, [0, 1, 2, 3])
    np.testing.assert_array_equal(patch.vertices[patch.faces], faces[:2])
    np.testing.assert_array_equal(patch.vertices[patch.assoc], [2, 2, 0])


def test_posed_patch_matches_the_whole_posed_body():
    body = load_body_model()
    betas = np.zeros(10)
    betas[:2] = (1.5, -1.0)
    rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=600))
    pair = prepare_pair(body, betas, rest, faces, find_bundle("tshirt").fit)  # the shipped fit model
    poses, transl = walk_cycle(4)
    posed = pose_body(body, pair, poses, transl)
    assert len(pair.patch.vertices) < body.num_vertices
    verts, joints = lbs(body, pair.v_shaped, pair.joints, poses, transl)
    normals = vertex_normals(verts, body.faces)
    idx = pair.assoc_vertex
    np.testing.assert_allclose(posed.garment_points, verts[:, idx], atol=1e-12)
    np.testing.assert_allclose(posed.garment_normals, normals[:, idx], atol=1e-12)
    np.testing.assert_allclose(posed.joints, joints)
    feats = coarse_model_features(pair, posed, transl)
    np.testing.assert_allclose(feats[..., :3], normals[:, idx], atol=1e-12)
    np.testing.assert_allclose(feats[..., 3:6], verts[:, idx] - transl[:, None], atol=1e-12)


def test_coarse_base_adds_the_displacement_to_the_body_or_the_skinned_garment():
    """A zero displacement gives I M_b (METHOD.md's base) or exactly the skinning tier."""
    from cloth_usd.core.pipeline import CoarseBase, CoarseForm, run_tiers
    from cloth_usd.core.postprocess import push_out_of_surface
    from cloth_usd.core.skinning import skin_garment

    body = load_body_model()
    betas = np.zeros(10)
    rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=600))
    pair = prepare_pair(body, betas, rest, faces, find_bundle("tshirt").fit)
    poses, transl = walk_cycle(5)

    def zero(feats, graph):
        return np.zeros(feats.shape[:2] + (3,))

    posed = pose_body(body, pair, poses, transl)
    for base, want in ((CoarseBase.BODY, posed.garment_points),
                       ("skinned", skin_garment(pair.binding, poses, transl, body.parents))):
        got, moved = run_tiers(body, pair, poses, transl, zero, batch_size=2, form=CoarseForm(base))
        expect, expect_moved = push_out_of_surface(want, posed.patch_points, posed.patch_normals, pair.patch.faces,
                                                   pair.patch.contact)
        np.testing.assert_allclose(got, expect, atol=1e-12)
        np.testing.assert_array_equal(moved, expect_moved)
        if base is CoarseBase.BODY:  # the body itself lies within the margin: every vertex is pushed
            assert (expect_moved == want.shape[1]).all()
        raw, none = run_tiers(body, pair, poses, transl, zero, batch_size=2, form=CoarseForm(base), postprocess=False)
        np.testing.assert_allclose(raw, want, atol=1e-12)  # the models' garment as they made it
        assert not none.any()
    with pytest.raises(ValueError):
        run_tiers(body, pair, poses, transl, zero, form=CoarseForm("hips"))


def test_contact_features_let_a_model_see_and_undo_what_skinning_puts_into_the_body():
    """The contact features are measured at the coarse base in the body under the garment; a
    model that pushes each vertex out along them leaves fewer vertices inside than skinning.
    With the trees built once, the post-process gives what it gives building its own."""
    from cloth_usd.core.features import contact_features
    from cloth_usd.core.pipeline import CoarseFeatures, CoarseForm, contact_trees, run_tiers
    from cloth_usd.core.postprocess import push_out_of_surface
    from cloth_usd.core.skinning import skin_garment
    from cloth_usd.errors import ArgumentError

    body = load_body_model()
    betas = np.zeros(10)
    rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=600))
    pair = prepare_pair(body, betas, rest, faces, find_bundle("tshirt").fit)
    poses, transl = walk_cycle(4)
    poses[:, 3 * 16 + 2], poses[:, 3 * 17 + 2] = -1.5, 1.5  # arms pressed down into the shirt's sides
    posed = pose_body(body, pair, poses, transl)
    skinned = skin_garment(pair.binding, poses, transl, body.parents)
    feats = coarse_model_features(pair, posed, transl, CoarseFeatures.CONTACT, base=skinned)
    assert feats.shape == (4, pair.num_vertices, 11)
    np.testing.assert_array_equal(feats[..., :7], coarse_model_features(pair, posed, transl))
    cloud = pair.patch.contact
    np.testing.assert_array_equal(feats[..., 7:], contact_features(skinned, posed.patch_points[:, cloud],
                                                                   posed.patch_normals[:, cloud]))
    inside = feats[..., 10] < 0
    assert inside.sum() > 20  # skinning puts the arms into the shirt
    with pytest.raises(ArgumentError, match="need the coarse base"):
        coarse_model_features(pair, posed, transl, "contact")

    def push(f, graph):  # out along the nearest body normal, to 5 mm in front of its plane
        return f[..., 7:10] * np.maximum(0.005 - f[..., 10:11], 0.0)

    raw, _ = run_tiers(body, pair, poses, transl, push, form=CoarseForm("skinned", features="contact"),
                       postprocess=False)
    after = contact_features(raw, posed.patch_points[:, cloud], posed.patch_normals[:, cloud])
    assert (after[..., 3] < 0).sum() < 0.5 * inside.sum()
    got, moved = run_tiers(body, pair, poses, transl, push, form=CoarseForm("skinned", features="contact"))
    want, want_moved = push_out_of_surface(raw, posed.patch_points, posed.patch_normals, pair.patch.faces, cloud,
                                           rings=pair.patch.rings)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(moved, want_moved)
    shared, _ = push_out_of_surface(raw, posed.patch_points, posed.patch_normals, pair.patch.faces, cloud,
                                    trees=contact_trees(pair, posed))
    np.testing.assert_array_equal(shared, want)


def test_the_body_under_a_shirt_includes_the_inner_arms_that_hang_against_it():
    """The post-process looks for the body under a garment among these vertices: a torso's
    garment meets the upper arms only when they hang, so they count with the arms lowered."""
    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.core.pipeline import _arms_down, body_under

    body = load_body_model()
    v, joints = shape_body(body, np.zeros(10))
    owner = np.argmax(body.weights, axis=1)
    torso = np.isin(owner, [3, 6, 9])  # spine1..3
    rest = v[torso] * [1.03, 1.0, 1.03]  # a shirt standing a little off the torso
    upper_arm = np.isin(owner, [16, 17])
    t_pose = body_under(v, rest)
    lowered = body_under(v, rest, arms_down=_arms_down(body, v, joints))
    assert set(t_pose) <= set(lowered)
    assert upper_arm[t_pose].sum() < upper_arm[lowered].sum()
    assert upper_arm[lowered].sum() > 0.1 * upper_arm.sum()


def test_the_body_under_any_garment_includes_the_arms_hands_and_legs():
    """A hand swung before the belly (a run), a knee kicked up into the hem, meet a shirt where
    neither the T-pose nor the lowered arms put them: the post-process searches the arms,
    hands, thighs and shins for every garment."""
    from cloth_usd.core.pipeline import SWINGING_JOINTS, swinging_parts
    from cloth_usd.core.smpl import JOINT_NAMES

    body = load_body_model()
    rest, faces = make_tshirt(body, np.zeros(10), TShirtParams(target_vertices=600))
    pair = prepare_pair(body, np.zeros(10), rest, faces, find_bundle("tshirt").fit)
    owner = np.argmax(body.weights, axis=1)
    hands = np.flatnonzero(np.isin(owner, [JOINT_NAMES.index("left_hand"), JOINT_NAMES.index("right_hand")]))
    shins = np.flatnonzero(np.isin(owner, [JOINT_NAMES.index("left_knee"), JOINT_NAMES.index("right_knee")]))
    contact = pair.patch.vertices[pair.patch.contact]
    assert set(hands) | set(shins) <= set(swinging_parts(body)) <= set(contact)
    assert {JOINT_NAMES[j] for j in owner[swinging_parts(body)]} == set(SWINGING_JOINTS)
    # every triangle around a searched vertex is in the patch, so its normal is the whole body's
    assert (pair.patch.rings[pair.patch.contact] >= 0).sum() == np.isin(
        body.faces, contact).sum()


def test_coarse_form_reads_the_manifest_strings_and_refuses_others():
    from cloth_usd.core.heading import Heading
    from cloth_usd.core.pipeline import CoarseBase, CoarseFeatures, CoarseForm

    form = CoarseForm("skinned", "canonical", "contact")
    assert form == CoarseForm(CoarseBase.SKINNED, Heading.CANONICAL, CoarseFeatures.CONTACT)
    assert CoarseForm() == CoarseForm(CoarseBase.BODY, Heading.WORLD, CoarseFeatures.BODY)  # a bundle without the fields
    for bad in ({"base": "hips"}, {"heading": "north"}, {"features": "colour"}):
        with pytest.raises(ValueError):
            CoarseForm(**bad)


def test_a_fit_far_outside_training_is_clamped_for_the_models():
    """A shirt sewn for a betas 3, 3 body read -18 on the fit's third factor, and the detail
    model tore it; the models read the fit clamped to FIT_LIMIT, the measured one is kept."""
    import dataclasses

    from cloth_usd.core.fit import FIT_LIMIT

    body = load_body_model()
    rest, faces = make_tshirt(body, np.zeros(10), TShirtParams(target_vertices=600))
    fit = find_bundle("tshirt").fit
    far = dataclasses.replace(fit, mean=fit.mean - 0.5)  # every anchor 50 cm nearer than any training garment's
    pair = prepare_pair(body, np.zeros(10), rest, faces, far)
    assert np.abs(pair.alpha_measured).max() > FIT_LIMIT
    np.testing.assert_array_equal(pair.alpha, np.clip(pair.alpha_measured, -FIT_LIMIT, FIT_LIMIT))
    inside = prepare_pair(body, np.zeros(10), rest, faces, fit)  # within the limit: read as measured
    assert np.abs(inside.alpha_measured).max() <= FIT_LIMIT
    np.testing.assert_array_equal(inside.alpha, inside.alpha_measured)


def _walking_shirt():
    """A 600-vertex T-shirt on the default body over three frames of ``walk_cycle``, as the skinning tier
    makes it: ``(body, rest, faces, pair, posed, skinned (3, N, 3))``."""
    from cloth_usd.core.skinning import skin_garment

    body = load_body_model()
    betas = np.zeros(10)
    rest, faces = make_tshirt(body, betas, TShirtParams(target_vertices=600))
    pair = prepare_pair(body, betas, rest, faces, find_bundle("tshirt").fit)
    poses, transl = walk_cycle(3)
    posed = pose_body(body, pair, poses, transl)
    return body, rest, faces, pair, posed, skin_garment(pair.binding, poses, transl, body.parents)


def test_the_post_process_pushes_a_frame_without_the_strain_limit_where_the_limit_would_tear_it():
    """A frame that the strain limit and the push leave more stretched than the models made it
    is pushed without the limit (where the body leaves a garment too little cloth, the limit pulls
    it into the body and the push tears it: trousers in a kick), as is a frame the limit would move
    too far (it slides cloth along the body: a trouser leg off a raised thigh); every other frame
    is limited."""
    from cloth_usd.core.pipeline import post_process
    from cloth_usd.core.postprocess import LIMIT_MOVE_BOUND, StrainLimiter, push_out_of_surface

    body, rest, faces, pair, posed, raw = _walking_shirt()

    def push(m):
        return push_out_of_surface(m, posed.patch_points, posed.patch_normals, pair.patch.faces, pair.patch.contact,
                                   rings=pair.patch.rings)

    centre = raw.mean(axis=1, keepdims=True)
    loose = centre + 1.2 * (raw - centre)  # a model's shirt stretched a fifth: limiting helps, every frame limited
    fits = StrainLimiter(rest, faces)
    got, moved = post_process(pair, posed, loose, limiter=fits)
    want, want_moved = push(fits(loose))
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(moved, want_moved)
    assert (fits.stretch(got) < fits.stretch(loose) - 0.1).all()
    np.testing.assert_allclose(post_process(pair, posed, raw, limiter=fits)[0], push(fits(raw))[0])  # left as it is
    def moves(m, limiter=fits):  # each frame's largest and 99th-percentile move of the limit [m]
        d = np.linalg.norm(limiter(m) - m, axis=-1)
        return d.max(axis=1), np.quantile(d, 0.99, axis=1)

    # stretched by half: the limit would move more than 1% of the vertices past LIMIT_MOVE_BOUND, a region
    looser = centre + 1.5 * (raw - centre)
    assert (moves(looser)[1] > LIMIT_MOVE_BOUND).all()
    got, moved = post_process(pair, posed, looser, limiter=fits)
    want, want_moved = push(looser)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(moved, want_moved)
    spiked = loose.copy()  # and one vertex pulled 30 cm out: the limit pulls it back, a spike, not a region
    spiked[:, 0] += [0.0, 0.0, 0.3]
    assert (moves(spiked)[0] > LIMIT_MOVE_BOUND).all() and (moves(spiked)[1] < LIMIT_MOVE_BOUND).all()
    np.testing.assert_array_equal(post_process(pair, posed, spiked, limiter=fits)[0], push(fits(spiked))[0])
    mixed = np.concatenate([loose[:1], looser[1:2], loose[2:]])  # judged frame by frame
    got = post_process(pair, posed, mixed, limiter=fits)[0]
    np.testing.assert_array_equal(got[[0, 2]], push(fits(loose))[0][[0, 2]])
    np.testing.assert_array_equal(got[1], push(looser)[0][1])
    # a rest 0.8 x the shirt's size: limited to 1.05 of it, the shirt shrinks into the body
    small = StrainLimiter(rest.mean(axis=0) + 0.8 * (rest - rest.mean(axis=0)), faces)
    assert (moves(raw, small)[0] < LIMIT_MOVE_BOUND).all()
    torn, _ = push(small(raw))
    assert (small.stretch(torn) > small.stretch(raw)).all()
    got, moved = post_process(pair, posed, raw, limiter=small)
    want, want_moved = push(raw)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(moved, want_moved)
    assert (small.stretch(got) < small.stretch(torn)).all()
    np.testing.assert_allclose(small.stretch(raw[:1], 0.5), np.quantile(
        np.linalg.norm(raw[0, small.edges[:, 1]] - raw[0, small.edges[:, 0]], axis=1) / small.rest_lengths, 0.5))


def test_the_post_process_solves_the_limit_again_where_it_bared_the_skin(monkeypatch):
    """Where the strain limit pulls a region into the body and the push lays it back on the skin,
    shrunk, skin shows through the lifted garment (tshirt-v6's shoulder in a martial arts kick):
    such a frame is limited again with the edges around the bared skin left as the models made
    them, pushed and lifted; a frame with no more than specks showing is left as it was."""
    import cloth_usd.core.pipeline as pipeline
    from cloth_usd.core.postprocess import BARED_TOLERANCE, StrainLimiter, TriangleLift, push_out_of_surface

    body, rest, faces, pair, posed, raw = _walking_shirt()
    under = pair.patch.vertices[pair.patch.contact]
    normals = vertex_normals(pair.v_shaped, body.faces)
    # the stretch check would push such frames without the limit: out of the way, the second solve alone
    monkeypatch.setattr(pipeline, "LIMIT_CHECK_TOLERANCE", np.inf)

    def post(narrower):  # a rest with sleeves ``narrower`` x the shirt's: limited to it, they pull into the arms
        small = rest.copy()
        for side in (-1, 1):
            sleeve = rest[:, 0] * side > 0.15
            axis = rest[sleeve, 1:].mean(axis=0)
            small[sleeve, 1:] = axis + narrower * (rest[sleeve, 1:] - axis)
        limiter = StrainLimiter(small, faces)
        lift = TriangleLift(faces, small, pair.v_shaped[under], normals[under])
        first = push_out_of_surface(limiter(raw), posed.patch_points, posed.patch_normals, pair.patch.faces,
                                    pair.patch.contact, rings=pair.patch.rings)[0]
        first = lift(first, posed.patch_points, posed.patch_normals, pair.patch.faces, pair.patch.contact,
                     rings=pair.patch.rings)[0]
        got, moved = pipeline.post_process(pair, posed, raw, limiter=limiter, lift=lift)
        shows = [lift.bared(x, posed.patch_points, posed.patch_normals, pair.patch.contact)[0] for x in (first, got)]
        return first, got, moved, *shows

    first, got, moved, before, after = post(0.55)
    assert (before > BARED_TOLERANCE).all() and (2 * after <= before).all() and (after <= BARED_TOLERANCE).all(), \
        (before, after)
    assert (np.abs(got - first).max(axis=(1, 2)) > 0.002).all()  # millimetres, not float noise
    assert moved.shape == (3,) and (moved > 0).all()
    first, got, _, before, _ = post(0.65)  # nothing bared past the tolerance: as the limit, push and lift left it
    assert (before <= BARED_TOLERANCE).all()
    np.testing.assert_array_equal(got, first)


def test_a_garment_models_grain_is_smoothed_and_its_folds_kept():
    """run_garment_model smooths the part of the own model's displacement along the rest garment's normals
    before skinning it: a grain from vertex to vertex goes, a broad fold (a displacement that varies over the
    garment, not from vertex to vertex) keeps its depth, and the displacement across the normals (the
    membrane's) stays as the model gave it."""
    from cloth_usd.core.features import vertex_normals
    from cloth_usd.core.pipeline import OWN_SMOOTHING, run_garment_model
    from cloth_usd.core.skinning import skin_garment

    body, rest, faces, pair, _, skinned = _walking_shirt()
    poses, transl = walk_cycle(3)
    normals = vertex_normals(rest, faces)
    rng = np.random.default_rng(0)
    grain = 0.004 * rng.choice([-1.0, 1.0], size=(len(rest), 1)) * normals
    fold = 0.02 * np.sin(rest[:, 1:2] * 12.0) * normals  # a 50 cm wave down the shirt
    across = np.cross(normals, rng.normal(size=(len(rest), 3))) * 0.003  # in the membrane, at random

    def model(canonical_poses):
        return np.broadcast_to(fold + grain + across, (len(canonical_poses), len(rest), 3))

    def unposed(smoothing):  # the displacement as skinned: the garment less the skinned garment, at rest
        got = run_garment_model(body, pair, np.zeros((1, 72)), np.zeros((1, 3)), model, postprocess=False,
                                smoothing=smoothing)[0][0]
        return got - skin_garment(pair.binding, np.zeros((1, 72)), np.zeros((1, 3)), body.parents)[0]

    np.testing.assert_allclose(unposed(0), fold + grain + across, atol=1e-9)  # none: the model's own displacement
    assert OWN_SMOOTHING > 0
    smooth = unposed(OWN_SMOOTHING)
    np.testing.assert_allclose(smooth - np.einsum("nc,nc->n", smooth, normals)[:, None] * normals, across,
                               atol=1e-9)  # the membrane's part as it was
    height, wave = np.einsum("nc,nc->n", smooth, normals), np.einsum("nc,nc->n", fold, normals)
    assert np.abs(height - wave).mean() < 0.5 * np.abs(np.einsum("nc,nc->n", grain, normals)).mean()  # 0.41 x: 4 passes
    assert np.polyfit(wave, height, 1)[0] > 0.9  # the fold keeps its depth
    moved = run_garment_model(body, pair, poses, transl, model, postprocess=False)[0]
    assert np.isfinite(moved).all() and moved.shape == skinned.shape
