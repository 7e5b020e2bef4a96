"""Draping a garment on the rest body, and the rest-contact filters that make it hold."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model
from cloth_usd.datagen import TShirtParams, make_tshirt
from cloth_usd.datagen.simulate import SimConfig, _rest_contact_filters, drape, unique_edges

pytest.importorskip("newton", reason="cloth simulation needs newton (pip install newton==1.8.0)")


def test_rest_contact_filters_drop_only_garment_pairs():
    # A fold: two garment strips (in xz planes) 4 mm apart in y; then a body edge nearby.
    x = np.linspace(0.0, 0.05, 6)
    row = lambda y, z: np.stack([x, np.full_like(x, y), np.full_like(x, z)], 1)  # noqa: E731
    strip_a = np.concatenate([row(0.0, 0.0), row(0.0, 0.01)])  # vertices 0..11
    rest = np.concatenate([strip_a, strip_a + [0.0, 0.004, 0.0]])  # 12..23: the facing strip
    band = np.array([[i, i + 1, i + 6] for i in range(5)] + [[i + 1, i + 7, i + 6] for i in range(5)])
    faces = np.concatenate([band, band + 12])
    n = rest.shape[0]
    edges = np.array([[-1, -1, i, i + 1] for i in range(5)] + [[-1, -1, i + 12, i + 13] for i in range(5)]
                     + [[-1, -1, n, n + 1]])  # edge 10 is the body's (vertices >= n)
    maps = _rest_contact_filters(rest, faces, edges, radius=0.006)
    vt = maps["particle_external_vertex_contact_filtering_map"]
    ee = maps["particle_external_edge_contact_filtering_map"]
    assert 0 in vt and set(vt[0]) & set(range(10, 20))  # vertex 0 ignores the facing strip's triangles
    assert max(vt) < n and all(t < len(faces) for ts in vt.values() for t in ts)
    assert 10 not in ee and all(10 not in es for es in ee.values())  # the body edge is never filtered
    assert 5 in ee[0]  # the facing strip's first edge is
    assert _rest_contact_filters(rest, faces, edges, radius=0.0) == {}


def test_drape_settles_the_shirt_on_the_shoulders():
    body = load_body_model()
    betas = np.zeros(10)
    verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=400))
    cfg = SimConfig(substeps=40, iterations=3, collider_faces=2000, device="cpu", drape_frames=3)
    draped, result = drape(body, betas, verts, faces, cfg)
    assert draped.shape == verts.shape and np.all(np.isfinite(draped))
    assert result.is_stable
    drop = (draped - verts)[:, 1]
    # Measured: the shirt settles a few mm onto the shoulders and stays (no free fall:
    # three frames of free fall would be 31 mm).
    assert -0.02 < drop.mean() < 0.0, drop.mean()
    ratio = np.linalg.norm(np.diff(draped[unique_edges(faces)], axis=1)[:, 0], axis=1) / \
        np.linalg.norm(np.diff(verts[unique_edges(faces)], axis=1)[:, 0], axis=1)
    assert ratio.max() < 1.15, ratio.max()


def test_pairs_drape_in_one_batch_like_one_at_a_time(tmp_path, monkeypatch):
    """drape_pairs(batch=2): two garment-body pairs draped as one model, cached like the single path."""
    from cloth_usd.datagen.dataset import Job
    from cloth_usd.datagen.factory import drape_pairs

    body = load_body_model()
    cfg = SimConfig(substeps=4, iterations=2, collider_faces=2000, device="cpu", drape_frames=2)
    jobs = []
    for k, betas in enumerate((np.zeros(10), np.r_[1.0, -0.5, np.zeros(8)])):
        verts, faces = make_tshirt(body, betas, TShirtParams(target_vertices=300))
        jobs.append(Job(name=f"train.shirt{k}.b{k}.walk", garment_vertices=verts, garment_faces=faces, betas=betas,
                        poses=np.zeros((3, 72)), transl=np.zeros((3, 3)), meta={"shirt": k, "body": f"b{k}"}))
    sim = cfg.to_json()
    batched, failed = drape_pairs(jobs, tmp_path / "batched", sim, batch=2, penetration_frames=1)
    alone, _ = drape_pairs(jobs, tmp_path / "alone", sim)
    assert not failed and len(batched) == 2 and len(list((tmp_path / "batched" / "drape").glob("*.npz"))) == 2
    for b, a, job in zip(batched, alone, jobs):
        assert b.garment_vertices.shape == job.garment_vertices.shape
        # Measured 0.45 and 0.62 mm apart: the same drape, the model's colouring ordering the solve differently.
        assert np.abs(b.garment_vertices - a.garment_vertices).max() < 2e-3
    monkeypatch.setattr("cloth_usd.datagen.simulate.simulate_batch", lambda *a, **k: pytest.fail("not cached"))
    again, _ = drape_pairs(jobs, tmp_path / "batched", sim, batch=2)
    for b, job in zip(again, batched):  # cached: nothing simulated again
        np.testing.assert_array_equal(b.garment_vertices, job.garment_vertices)
