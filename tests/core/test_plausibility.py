"""Garment size and distance against the rest skeleton: worn, 10x too big, too small, far away."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.plausibility import SIZE_REFUSE, garment_scale, scale_notes


@pytest.fixture(scope="module")
def body():
    verts, joints = shape_body(load_body_model(), np.zeros(10))
    torso = verts[(verts[:, 1] > joints[0, 1] - 0.1) & (verts[:, 1] < joints[12, 1])]  # a body-hugging "shirt"
    return torso, joints


def test_a_worn_garment_has_no_notes_and_the_body_height_is_measured(body):
    torso, joints = body
    scale = garment_scale(torso * 1.02, joints)
    assert scale.body_height == pytest.approx(1.69, abs=0.03)
    assert 0.3 < scale.ratio < 1.2 and scale.distance < 0.15
    assert scale_notes(scale) == []


def test_decimetres_are_ten_times_too_big_and_far(body):
    torso, joints = body
    scale = garment_scale(torso * 10.0, joints)
    assert scale.ratio > SIZE_REFUSE
    notes = scale_notes(scale)
    assert len(notes) == 2 and "units" in notes[0] and "bones" in notes[1]


def test_too_small_and_moved_away(body):
    torso, joints = body
    small = scale_notes(garment_scale(torso * 0.01, joints))
    assert any("too small" in n for n in small)
    away = scale_notes(garment_scale(torso + [2.0, 0.0, 0.0], joints))
    assert len(away) == 1 and "placement" in away[0]
