"""Shared fixtures: tiny hand-built bodies and stages, built in memory."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.body import BodyModel, body_model_from_arrays
from cloth_usd.core.smpl import PARENTS


#: smplx's extra-joint landmarks (nose, eyes, ears, feet, finger tips).
LANDMARKS = ("nose", "reye", "leye", "rear", "lear", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
             "RSmallToe", "RHeel", "lthumb", "lindex", "lmiddle", "lring", "lpinky", "rthumb",
             "rindex", "rmiddle", "rring", "rpinky")


def tiny_body_arrays(seed: int = 0, num_vertices: int = 64, posedirs: bool = True) -> dict:
    """A random SMPL-layout body: geometry is meaningless, the layout is SMPL's."""
    rng = np.random.default_rng(seed)
    v = rng.normal(0.0, 0.3, size=(num_vertices, 3))
    faces = np.stack([rng.choice(num_vertices, 3, replace=False) for _ in range(2 * num_vertices)])
    weights = rng.random((num_vertices, 24)) ** 4
    weights /= weights.sum(axis=1, keepdims=True)
    reg = rng.random((24, num_vertices)) * (rng.random((24, num_vertices)) < 0.2)
    reg[:, 0] += 1e-3
    reg /= reg.sum(axis=1, keepdims=True)
    return {
        "v_template": v,
        "shapedirs": rng.normal(0.0, 0.01, size=(num_vertices, 3, 10)),
        "posedirs": rng.normal(0.0, 0.01, size=(num_vertices, 3, 207)) if posedirs
        else np.zeros((num_vertices, 3, 207)),
        "J_regressor": reg,
        "weights": weights,
        "kintree_table": np.stack([np.where(PARENTS < 0, 4294967295, PARENTS), np.arange(24)]),
        "f": faces,
        "vertex_ids_names": np.array(LANDMARKS),
        "vertex_ids": rng.choice(num_vertices, len(LANDMARKS), replace=False),
    }


@pytest.fixture
def tiny_body() -> BodyModel:
    return body_model_from_arrays(tiny_body_arrays(), source="tiny")
