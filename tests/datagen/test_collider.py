"""The body collider: contact friction must see the body move and carry the garment with it.

The physics tests drape the test shirt of ``test_simulate.py``'s size (``target_vertices=400``
gives 1789 vertices) on a 2000-face collider at 40 x 3 substeps x iterations, then move the
rest-pose body: a turn about +Y, and a start from rest along +Z. About 80 s warm on 2 busy
CPU cores.
"""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model, posed_vertices, shape_body
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.datagen.simulate import ColliderKind, SimConfig, SimulationError, drape, simulate

needs_newton = pytest.mark.skipif(importlib.util.find_spec("newton") is None,
                                  reason="cloth simulation needs newton (pip install newton==1.8.0)")
COLLIDER_FACES = 2000 if importlib.util.find_spec("fast_simplification") else None  # None: full body, slower
CFG = SimConfig(substeps=40, iterations=3, collider_faces=COLLIDER_FACES, device="cpu", drape_frames=4)


def yaw_deg(points: np.ndarray, rest: np.ndarray, pivot: np.ndarray) -> float:
    """Least-squares turn [deg] about +Y through ``pivot`` that takes (N, 3) ``rest`` to ``points``."""
    a, b = (rest - pivot)[:, [0, 2]], (points - pivot)[:, [0, 2]]
    cos = np.sum(a * b)
    sin = np.sum(a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1])  # a +Y turn maps (x, z) to (x c + z s, z c - x s)
    return float(np.degrees(np.arctan2(sin, cos)))


def test_yaw_deg_of_a_known_turn():
    rng = np.random.default_rng(0)
    rest = rng.normal(size=(50, 3))
    t = np.radians(30.0)
    turn = np.array([[np.cos(t), 0.0, np.sin(t)], [0.0, 1.0, 0.0], [-np.sin(t), 0.0, np.cos(t)]])
    assert yaw_deg(rest @ turn.T, rest, np.zeros(3)) == pytest.approx(30.0)


def test_collider_kind_in_config():
    assert SimConfig().collider is ColliderKind.MESH_SHAPE
    cfg = SimConfig(collider="cloth")
    assert cfg.collider is ColliderKind.CLOTH
    assert cfg.to_json()["collider"] == "cloth"
    assert SimConfig(**cfg.to_json()) == cfg  # manifests round-trip
    with pytest.raises(SimulationError, match="mesh_shape"):
        SimConfig(collider="capsules")


@pytest.fixture(scope="module")
def worn():
    """``(body, betas, shirt (N, 3) [m] draped by the default collider, its faces, root joint (3,) [m])``."""
    body = load_body_model()
    betas = np.zeros(10)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=400))
    draped, _ = drape(body, betas, verts, faces, CFG)
    return body, betas, draped, faces, shape_body(body, betas)[1][0]


@needs_newton
@pytest.mark.slow
def test_friction_turns_the_shirt_with_the_body(worn):
    body, betas, draped, faces, pivot = worn
    # Rest pose; the root turns 30 deg about +Y in 10 frames, easing in over the first 3.
    rate = np.minimum(np.arange(10) / 3.0, 1.0)
    yaw = np.concatenate([[0.0], np.cumsum(rate[1:])]) * np.radians(30.0) / np.sum(rate[1:])
    poses = np.zeros((10, 72))
    poses[:, 1] = yaw
    body_turn = yaw_deg(posed_vertices(body, betas, poses[-1:])[0], posed_vertices(body, betas, poses[:1])[0],
                        pivot)
    assert body_turn == pytest.approx(30.0, abs=1e-6)
    turn = {}
    for mu in (0.0, 0.8):
        r = simulate(body, betas, draped, faces, poses, None, dataclasses.replace(CFG, friction=mu))
        assert r.is_stable, r.failure
        turn[mu] = yaw_deg(r.positions[-1], draped, pivot)
    # Measured: 30.43 deg at mu 0 (a frictionless shirt swings past the body) and 29.42 at
    # mu 0.8, 0.58 behind the body. The cloth collider, whose friction holds the shirt back
    # in the world: 29.95 and 21.14.
    assert turn[0.8] >= turn[0.0] - 1.5, turn
    assert abs(turn[0.8] - body_turn) < 1.5, turn


@needs_newton
@pytest.mark.slow
def test_the_shirt_starts_forward_with_the_body(worn):
    body, betas, draped, faces, _ = worn
    # Rest pose; the root accelerates from rest along +Z at 2 m/s^2 (85 mm in 7 frames).
    frames = 8
    transl = np.zeros((frames, 3))
    transl[:, 2] = 0.5 * 2.0 * (np.arange(frames) / CFG.fps) ** 2
    r = simulate(body, betas, draped, faces, np.zeros((frames, 72)), transl, dataclasses.replace(CFG, friction=0.8))
    assert r.is_stable, r.failure
    move = (r.positions.astype(np.float64) - draped).mean(axis=1)  # (T, 3) mean displacement [m]
    # Measured: 80.3 mm forward (the body 85.1); 3.2 mm lower, of which 3.6 mm in frame 1 (a
    # 4-frame drape ends mid-bounce), then +0.4 mm. The cloth collider: 80.8 mm forward, and
    # the shirt rode 8.8 mm up the body after frame 1 as friction held it in the world.
    assert move[-1, 2] == pytest.approx(transl[-1, 2], rel=0.1), move[-1]
    assert move[-1, 1] > -5e-3, move[:, 1]
    assert abs(move[-1, 1] - move[1, 1]) < 2e-3, move[:, 1]
    assert r.penetration[-1] < 0.08, r.penetration  # measured 0.044 (inside the full body, 2000-face collider)


@needs_newton
def test_cloth_collider_still_runs():
    body = load_body_model()
    betas = np.zeros(10)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=400))
    cfg = SimConfig(substeps=2, iterations=3, collider_faces=COLLIDER_FACES, device="cpu", collider="cloth")
    r = simulate(body, betas, verts, faces, np.zeros((2, 72)), None, cfg)
    assert r.is_stable and np.all(np.isfinite(r.positions)), r.failure
