"""core.guard: a learned frame that is not a garment is named, one reason per frame."""

import numpy as np
import pytest

from cloth_usd.core.guard import GuardLimits, check_frames
from cloth_usd.errors import ArgumentError

# A 3 x 3 grid of 5 cm cells, its 8 triangles' 16 edges.
_GRID = np.array([[x, 0.0, z] for z in (0.0, 0.05, 0.1) for x in (0.0, 0.05, 0.1)])
_FACES = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6], [4, 5, 8], [4, 8, 7]])
_EDGES = np.unique(np.sort(np.concatenate([_FACES[:, [0, 1]], _FACES[:, [1, 2]], _FACES[:, [2, 0]]]), axis=1), axis=0)


def _frames(*frames):
    return np.stack(frames)


def test_a_garment_near_its_skinned_self_passes():
    skinned = _frames(_GRID, _GRID + [0.0, 0.1, 0.0])
    points = skinned + np.random.default_rng(0).normal(0.0, 0.003, skinned.shape)
    faults = check_frames(points, skinned, _GRID, _EDGES)
    assert faults.ok.tolist() == [True, True] and faults.reasons == ("", "")


def test_each_kind_of_fault_is_named():
    skinned = _frames(_GRID, _GRID, _GRID, _GRID)
    nan, far, torn = _GRID.copy(), _GRID.copy(), _GRID.copy()
    nan[3, 1] = np.nan
    far[:] += [0.0, 0.0, 0.2]  # the whole garment 20 cm off
    torn[[2, 5, 8], 0] += 0.2  # one column pulled 20 cm out: its edges stretch 4-5x
    faults = check_frames(_frames(_GRID, nan, far, torn), skinned, _GRID, _EDGES,
                          GuardLimits(max_offset=0.25, median_offset=0.25, stretch_quantile=0.9))
    assert faults.ok.tolist() == [True, False, True, False]  # 20 cm off is within these 25 cm limits
    assert faults.reasons[1] == "not finite"
    assert faults.reasons[3].startswith("edges stretched") and "90th percentile (limit 2x)" in faults.reasons[3]
    tight = check_frames(_frames(far), _frames(_GRID), _GRID, _EDGES, GuardLimits(max_offset=0.15))
    # in mm, to a tenth: a vertex just past the limit does not read as at it
    assert tight.reasons == ("a vertex 200.0 mm from its skinned position (limit 150 mm)",)
    edge = check_frames(_frames(_GRID + [0.0, 0.0, 0.1504]), _frames(_GRID), _GRID, _EDGES,
                        GuardLimits(max_offset=0.15))
    assert edge.reasons == ("a vertex 150.4 mm from its skinned position (limit 150 mm)",)


def test_a_hem_far_from_skinning_passes_a_garment_moved_whole_does_not():
    """Where the hips bend skinning lifts the hem with the thighs and cloth hangs: Newton's own
    shirt goes up to 387 mm from skinning. A garment whose median vertex is far is not a garment."""
    lifted = _GRID.copy()
    lifted[6:, 1] += 0.2  # skinning moves the hem row 20 cm; the learned garment hangs flat
    hem = check_frames(_frames(_GRID), _frames(lifted), _GRID, _EDGES)
    assert hem.ok.tolist() == [True]
    assert not check_frames(_frames(_GRID), _frames(lifted), _GRID, _EDGES, GuardLimits(max_offset=0.15)).ok[0]
    whole = check_frames(_frames(_GRID + [0.0, 0.12, 0.0]), _frames(_GRID), _GRID, _EDGES)
    assert whole.reasons == ("half its vertices over 120.0 mm from their skinned positions (limit 100 mm)",)
    thrown = _GRID.copy()
    thrown[8] += [0.0, 0.6, 0.0]  # one vertex 60 cm off
    spike = check_frames(_frames(thrown), _frames(_GRID), _GRID, _EDGES, GuardLimits(stretch=100.0))
    assert spike.reasons == ("a vertex 600.0 mm from its skinned position (limit 500 mm)",)


def test_stretch_is_measured_against_the_skinned_edge_where_skinning_stretches():
    """Skinning itself stretches edges at joints; the learned tier is held to that, not to rest."""
    skinned = _GRID * [3.0, 1.0, 1.0]  # every x edge 3x its rest length
    faults = check_frames(_frames(skinned), _frames(skinned), _GRID, _EDGES, GuardLimits(max_offset=1.0))
    assert faults.ok.tolist() == [True]
    assert not check_frames(_frames(skinned), _frames(_GRID), _GRID, _EDGES, GuardLimits(max_offset=1.0)).ok[0]


def test_millimetre_edges_are_measured_against_the_floor():
    tiny = _GRID * 0.01  # 0.5 mm cells
    moved = tiny + np.random.default_rng(1).normal(0.0, 0.0005, tiny.shape)
    assert check_frames(_frames(moved), _frames(tiny), tiny, _EDGES).ok.tolist() == [True]
    assert not check_frames(_frames(moved), _frames(tiny), tiny, _EDGES, GuardLimits(min_edge=1e-4)).ok[0]


def test_bad_limits_and_shapes_are_refused():
    with pytest.raises(ArgumentError, match="GuardLimits: need"):
        GuardLimits(stretch=0.9)
    with pytest.raises(ArgumentError, match=r"must be \(T, N, 3\)"):
        check_frames(np.zeros((2, 4, 3)), np.zeros((2, 5, 3)), np.zeros((4, 3)), _EDGES)


def test_a_dress_may_swing_further_from_skinning_than_a_shirt():
    """guard_limits: a skirt swung 15 cm from the legs skinning binds it to, its median vertex
    with it (as Newton's sample dress does in 3% of its frames), is a dress's frame, not a shirt's."""
    from cloth_usd.core.guard import DRESS_LIMITS, guard_limits

    assert guard_limits("dress") == DRESS_LIMITS and guard_limits("tshirt") == GuardLimits() == guard_limits("trousers")
    swung = _GRID + [0.0, 0.0, 0.15]
    assert check_frames(_frames(swung), _frames(_GRID), _GRID, _EDGES, guard_limits("dress")).ok.tolist() == [True]
    shirt = check_frames(_frames(swung), _frames(_GRID), _GRID, _EDGES, guard_limits("tshirt"))
    assert not shirt.ok[0] and shirt.reasons[0].startswith("half its vertices over 150.0 mm")
    with pytest.raises(ValueError):
        guard_limits("hat")
