"""T-shirt variants and body shapes of the data set, and the fit attribute over them."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from cloth_usd.core.association import associate
from cloth_usd.core.body import load_body_model, shape_body
from cloth_usd.core.fit import common_anchors, fit_factor_analysis, pair_distances
from cloth_usd.datagen.bodies import BODY_SHAPES, body_shapes
from cloth_usd.datagen.tshirt import make_tshirt, tshirt_variants


@pytest.fixture(scope="module")
def body():
    return load_body_model()


def _boundary_loops(v, f):
    m = trimesh.Trimesh(v, f, process=False)
    rim = m.edges[trimesh.grouping.group_rows(m.edges_sorted, require_count=1)]
    return len(trimesh.graph.connected_components(rim))


def test_nine_variants_differ_in_topology_and_stay_outside_the_body(body):
    params = tshirt_variants(9)
    assert len(params) == 9
    counts = set()
    for p in params[:3]:  # the deterministic extremes: short/tight, long, loose
        v, f = make_tshirt(body, BODY_SHAPES[4].betas, p)
        counts.add(len(v))
        assert 2700 <= len(v) <= 4300
        assert _boundary_loops(v, f) == 4  # hem, neckline, two sleeves
        v_body, _ = shape_body(body, BODY_SHAPES[4].betas)
        assoc = associate(v, v_body, body.faces)
        assert assoc.distance.min() > 0.003  # clearance everywhere
    assert len(counts) == 3
    assert len({(p.hem, p.sleeve, p.target_vertices) for p in params}) == 9


def test_eleven_bodies_span_height_and_girth(body):
    heights = {s.name: np.ptp(shape_body(body, s.betas)[0][:, 1]) for s in BODY_SHAPES}
    assert len(heights) == 11
    assert heights["tall_regular"] - heights["short_regular"] > 0.3
    with pytest.raises(ValueError, match="valid"):
        body_shapes(["giant"])


def test_first_fit_factor_follows_the_ease(body):
    pytest.importorskip("sklearn")
    shirts = tshirt_variants(3)
    shapes = body_shapes(["short_thin", "medium_regular", "tall_fat"])
    pairs = []
    for p in shirts:
        for s in shapes:
            v_b, _ = shape_body(body, s.betas)
            g, _ = make_tshirt(body, s.betas, p)
            pairs.append((p.ease, g, associate(g, v_b, body.faces), v_b))
    anchors = common_anchors([(a, v_b) for _, _, a, v_b in pairs], shape_body(body, np.zeros(10))[0],
                             min(len(p[1]) for p in pairs))
    d = np.stack([pair_distances(g, a, v_b, anchors) for _, g, a, v_b in pairs])
    _, alpha = fit_factor_analysis(d, anchors)
    ease = np.array([p[0] for p in pairs])
    assert np.corrcoef(alpha[:, 0], ease)[0, 1] > 0.95
