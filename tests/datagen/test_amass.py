"""AMASS .npz loading: layouts, Z-up -> Y-up, resampling, rest blend and errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cloth_usd.datagen.amass import Z_UP_TO_Y_UP, AmassError, load_amass, load_amass_betas
from cloth_usd.errors import ArgumentError, ClothUsdError

#: AMASS's usual root orientation for a person standing upright in its Z-up world.
UPRIGHT = np.array([np.pi / 2, 0.0, 0.0])


def _write(path, *, frames=6, width=156, rate_key="mocap_framerate", rate=60.0, drop=(), **override):
    rng = np.random.default_rng(0)
    poses = rng.normal(0.0, 0.2, size=(frames, width))
    poses[:, :3] = UPRIGHT
    data = {"poses": poses, "trans": rng.normal(0.0, 1.0, size=(frames, 3)), "betas": np.arange(16) * 0.1,
            rate_key: np.array(rate), "gender": np.array("female")}
    data.update(override)
    for key in drop:
        del data[key]
    np.savez(path, **data)
    return data


def test_upright_root_becomes_the_rest_orientation(tmp_path):
    path = tmp_path / "seq.npz"
    data = _write(path, width=156)
    poses, root = load_amass(path, blend_seconds=0)
    assert poses.shape == (6, 72) and root.shape == (6, 3)
    assert np.allclose(poses[:, :3], 0.0, atol=1e-9)
    assert np.allclose(poses[:, 3:66], data["poses"][:, 3:66])
    assert np.all(poses[:, 66:] == 0.0)  # SMPL-H's finger values are not SMPL's hand joints


def test_z_up_turn_becomes_a_y_up_turn_and_translation_is_converted(tmp_path):
    path = tmp_path / "seq.npz"
    yaw = 0.7
    root_orient = (Rotation.from_rotvec([0, 0, yaw]) * Rotation.from_rotvec(UPRIGHT)).as_rotvec()
    poses = np.zeros((3, 156))
    poses[:, :3] = root_orient
    trans = np.array([[5.0, 5.0, 1.0], [6.0, 5.0, 1.0], [5.0, 7.0, 3.0]])  # metres, Z up
    _write(path, poses=poses, trans=trans)
    out, root = load_amass(path, blend_seconds=0)
    assert np.allclose(out[:, :3], [0.0, yaw, 0.0])  # a turn about SMPL's up axis
    # Z-up (x, y, z) -> Y-up (x, z, -y), relative to frame 0
    assert np.allclose(root, [[0, 0, 0], [1, 0, 0], [0, 2, -2]])
    assert np.allclose(Z_UP_TO_Y_UP @ [0, 0, 1], [0, 1, 0])


def test_smpl_layout_keeps_all_72(tmp_path):
    path = tmp_path / "smpl.npz"
    data = _write(path, width=72)
    poses, _ = load_amass(path, blend_seconds=0)
    assert np.allclose(poses[:, 3:], data["poses"][:, 3:])


def test_resample_and_rate_key_variants(tmp_path):
    path = tmp_path / "seq.npz"
    _write(path, frames=13, rate_key="mocap_frame_rate", rate=120.0)
    poses, root = load_amass(path, fps=30.0)
    assert poses.shape == (4, 72) and root.shape == (4, 3)  # 0.1 s at 120 fps -> 4 frames at 30
    assert np.all(np.isfinite(poses))
    assert np.allclose(poses[0], 0.0)  # blend from rest is on by default


def test_betas(tmp_path):
    path = tmp_path / "seq.npz"
    _write(path)
    assert np.allclose(load_amass_betas(path), np.arange(10) * 0.1)
    assert load_amass_betas(path, num_betas=20)[16:].tolist() == [0.0] * 4


@pytest.mark.parametrize("kwargs, match", [
    ({"drop": ("poses",)}, "missing key 'poses'"),
    ({"drop": ("trans",)}, "missing key 'trans'"),
    ({"drop": ("mocap_framerate",)}, "mocap_framerate, mocap_frame_rate"),
    ({"width": 30}, "key 'poses' has shape"),
    ({"trans": np.zeros((2, 3))}, "key 'trans' has shape"),
    ({"rate": 0.0}, "must be > 0"),
    ({"poses": np.full((6, 156), np.nan)}, "non-finite"),
])
def test_errors_name_file_and_key(tmp_path, kwargs, match):
    path = tmp_path / "broken.npz"
    _write(path, **kwargs)
    with pytest.raises(AmassError, match=match) as info:
        load_amass(path)
    assert "broken.npz" in str(info.value) and isinstance(info.value, ClothUsdError)


def test_pickled_and_missing_files_are_refused(tmp_path):
    path = tmp_path / "pickled.npz"
    _write(path, poses=np.array([{"a": 1}], dtype=object))
    with pytest.raises(AmassError, match="pickled.npz"):
        load_amass(path)
    with pytest.raises(AmassError, match="nothere.npz"):
        load_amass(tmp_path / "nothere.npz")
    with pytest.raises(ArgumentError, match="fps"):
        load_amass(path, fps=0.0)
