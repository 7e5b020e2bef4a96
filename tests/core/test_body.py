import os
import pickle
import sys
import types

import numpy as np
import pytest
import scipy.sparse

from cloth_usd.core.body import (body_model_from_arrays, default_body_model_path, load_body_model,
                                 posed_vertices, shape_body)
from cloth_usd.errors import BodyModelError
from tests.conftest import tiny_body_arrays


def test_npz_round_trip(tmp_path):
    arrays = tiny_body_arrays()
    path = tmp_path / "SMPL_NEUTRAL.npz"
    np.savez(path, **arrays)
    body = load_body_model(tmp_path)  # a folder picks SMPL_<GENDER>
    assert body.num_vertices == 64 and body.num_betas == 10
    np.testing.assert_allclose(body.v_template, arrays["v_template"])
    assert body.parents[0] == -1 and len(body.sha256) == 64


@pytest.mark.parametrize("key", ["v_template", "weights", "J_regressor", "f", "kintree_table"])
def test_missing_key_names_file_and_key(tmp_path, key):
    arrays = tiny_body_arrays()
    del arrays[key]
    path = tmp_path / "broken.npz"
    np.savez(path, **arrays)
    with pytest.raises(BodyModelError, match=f"broken.npz.*{key}"):
        load_body_model(path)


def test_wrong_tree_and_bad_weights_are_named(tmp_path):
    arrays = tiny_body_arrays()
    arrays["kintree_table"] = arrays["kintree_table"].copy()
    arrays["kintree_table"][0, 5] = 3
    with pytest.raises(BodyModelError, match="kintree_table"):
        body_model_from_arrays(arrays, source="x.npz")
    arrays = tiny_body_arrays()
    arrays["weights"] = arrays["weights"] * 2
    with pytest.raises(BodyModelError, match="weights"):
        body_model_from_arrays(arrays, source="x.npz")
    arrays = tiny_body_arrays()
    arrays["v_template"][3, 1] = np.nan
    with pytest.raises(BodyModelError, match="NaN"):
        body_model_from_arrays(arrays, source="x.npz")


def test_unreadable_and_unknown_files(tmp_path):
    with pytest.raises(BodyModelError, match="not found"):
        load_body_model(tmp_path / "nope.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(BodyModelError, match="junk.npz"):
        load_body_model(junk)
    other = tmp_path / "model.obj"
    other.write_text("v 0 0 0\n")
    with pytest.raises(BodyModelError, match="unknown body model format"):
        load_body_model(other)
    with pytest.raises(BodyModelError, match="gender"):
        load_body_model(None, gender="robot")


def _official_layout_pickle(path, arrays):
    """Write a pickle with the official SMPL key layout: chumpy Ch objects and a scipy CSC
    regressor, without chumpy installed (a stand-in class that claims chumpy's module)."""
    chumpy = types.ModuleType("chumpy")
    ch_mod = types.ModuleType("chumpy.ch")

    class Ch:
        def __init__(self, x):
            self.x = x

        def __getstate__(self):
            return {"x": self.x, "_dirty_vars": set()}

    Ch.__module__ = "chumpy.ch"
    Ch.__qualname__ = "Ch"
    ch_mod.Ch = Ch
    sys.modules["chumpy"], sys.modules["chumpy.ch"] = chumpy, ch_mod
    try:
        data = {
            "J_regressor_prior": scipy.sparse.csc_matrix(arrays["J_regressor"]),
            "f": arrays["f"].astype(np.uint32),
            "J_regressor": scipy.sparse.csc_matrix(arrays["J_regressor"]),
            "kintree_table": arrays["kintree_table"].astype(np.int64),
            "J": Ch(arrays["J_regressor"] @ arrays["v_template"]),
            "weights_prior": arrays["weights"],
            "weights": Ch(arrays["weights"]),
            "vert_sym_idxs": np.arange(arrays["v_template"].shape[0]),
            "posedirs": Ch(arrays["posedirs"]),
            "pose_training_info": {"num_training_poses": 0},
            "bs_style": "lbs",
            "v_template": Ch(arrays["v_template"]),
            "shapedirs": Ch(arrays["shapedirs"]),
            "bs_type": "lrotmin",
        }
        with open(path, "wb") as fh:
            pickle.dump(data, fh, protocol=2)
    finally:
        del sys.modules["chumpy"], sys.modules["chumpy.ch"]


def test_official_pkl_layout_loads_without_chumpy(tmp_path):
    arrays = tiny_body_arrays()
    path = tmp_path / "basicmodel_neutral.pkl"
    _official_layout_pickle(path, arrays)
    assert "chumpy" not in sys.modules
    body = load_body_model(path)
    assert "chumpy" not in sys.modules
    np.testing.assert_allclose(body.J_regressor, arrays["J_regressor"])
    np.testing.assert_allclose(body.shapedirs, arrays["shapedirs"])
    np.testing.assert_allclose(body.posedirs, arrays["posedirs"])


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_pickle_with_code_is_refused_and_not_run(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "evil.pkl"
    with open(path, "wb") as fh:
        pickle.dump({"v_template": _Evil(marker)}, fh)
    with pytest.raises(BodyModelError, match="evil.pkl.*not allowed"):
        load_body_model(path)
    assert not marker.exists()


def test_numpy_lbs_matches_smplx(tiny_body):
    torch = pytest.importorskip("torch")
    pytest.importorskip("smplx")
    from cloth_usd.body_torch import to_smplx

    rng = np.random.default_rng(3)
    betas, pose, transl = rng.normal(size=10), rng.normal(0, 0.6, size=(2, 72)), rng.normal(size=(2, 3))
    model = to_smplx(tiny_body, batch_size=2)
    def f32(a):
        return torch.tensor(a, dtype=torch.float32)

    with torch.no_grad():
        out = model(betas=f32(np.repeat(betas[None], 2, 0)), global_orient=f32(pose[:, :3]),
                    body_pose=f32(pose[:, 3:]), transl=f32(transl))
    ours = posed_vertices(tiny_body, betas, pose, transl)
    np.testing.assert_allclose(out.vertices.numpy(), ours, atol=2e-5)
    _, joints = shape_body(tiny_body, betas)
    np.testing.assert_allclose(out.joints[0, :24].numpy() - transl[0], _posed_joints(tiny_body, betas, pose)[0],
                               atol=2e-5)


def _posed_joints(body, betas, pose):
    from cloth_usd.core.body import joint_transforms
    from cloth_usd.core.rotations import axis_angle_to_matrix

    _, joints = shape_body(body, betas)
    posed, _ = joint_transforms(axis_angle_to_matrix(pose.reshape(-1, 24, 3)), joints)
    return posed


def test_embedded_body_model_is_shipped_and_valid():
    path = default_body_model_path()
    assert path.exists(), f"embedded body model missing at {path}"
    body = load_body_model()
    v, joints = shape_body(body, np.zeros(10))
    assert 1.5 < np.ptp(v[:, 1]) < 2.0  # an adult, Y-up metres
    assert joints[16, 0] > 0 > joints[17, 0]  # body's left at +X
