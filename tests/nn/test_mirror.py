"""nn.mirror: a sequence mirrored left for right is another valid sequence of the same garment."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model
from cloth_usd.core.skinning import bind_garment, skin_garment
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.errors import ArgumentError
from cloth_usd.nn.mirror import MIRROR_JOINTS, mirror_map, mirror_poses

FLIP = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def shirt():
    body = load_body_model()
    betas = np.zeros(10)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=600))
    return body, betas, verts, faces


def test_mirroring_twice_is_the_identity(shirt):
    body, _, verts, faces = shirt
    poses = np.random.default_rng(0).normal(0.0, 0.4, (3, 72))
    np.testing.assert_allclose(mirror_poses(mirror_poses(poses)), poses, atol=1e-12)
    assert sorted(MIRROR_JOINTS) == list(range(24))
    m = mirror_map(verts, faces)
    assert np.median(m.distance) < 1e-3
    points = verts + np.random.default_rng(1).normal(0.0, 0.01, verts.shape)
    twice = m.apply(m.apply(points))
    # near exact where the mirror image is (nearly) a vertex, a blend of neighbours elsewhere; 10 mm of noise
    off = np.linalg.norm(twice - points, axis=1)
    assert np.median(off) < 1e-4 and off.mean() < 2e-3, (np.median(off), off.mean())


def test_the_mirrored_pose_skins_the_mirrored_garment(shirt):
    """What mirrored training rests on: skinning the mirrored pose and root path gives, vertex
    for vertex, the mirror image of the garment skinning the pose gives."""
    body, betas, verts, faces = shirt
    rng = np.random.default_rng(2)
    poses = rng.normal(0.0, 0.3, (4, 72))
    poses[:, 16 * 3 + 2] = -1.2  # the left arm raised: the right one must rise in the mirror
    transl = rng.normal(0.0, 0.3, (4, 3))
    binding = bind_garment(body, betas, verts)
    m = mirror_map(verts, faces)
    expected = m.apply(skin_garment(binding, poses, transl, body.parents))
    got = skin_garment(binding, mirror_poses(poses), transl * FLIP, body.parents)
    err = np.linalg.norm(got - expected, axis=-1)
    moved = np.linalg.norm(got - skin_garment(binding, poses, transl, body.parents), axis=-1)
    # 0.01 mm at the median vertex here (a wrong sign of the rotations: 142 mm)
    assert np.median(err) < 1e-4 and np.percentile(err, 99) < 1e-2 and np.median(moved) > 0.05


def test_a_garment_that_is_not_symmetric_is_refused(shirt):
    _, _, verts, faces = shirt
    lopsided = verts.copy()
    lopsided[verts[:, 0] > 0.15, 1] -= 0.05  # one sleeve 5 cm lower
    with pytest.raises(ArgumentError, match=r"^the shirt is not symmetric left for right: vertex \d+'s mirror "
                                            r"image is \d+\.\d mm from it \(limit 20 mm\)"):
        mirror_map(lopsided, faces, name="the shirt")
