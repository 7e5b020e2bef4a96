"""Pattern geometry and triangulation on tiny hand-built panels, and every preset drafted."""

from __future__ import annotations

import numpy as np
import pytest

from cloth_usd.core.body import load_body_model
from cloth_usd.errors import ArgumentError
from cloth_usd.garments import (PRESETS, Panel, Pattern, PatternError, Seam, design_from_params, draft,
                                measure_body, pack_uvs, pattern_spacing, triangulate_pattern)
from cloth_usd.garments.pattern import bezier, line
from cloth_usd.garments.sew import merge_seams, pattern_edge_lengths


def _square(name: str, z: float, outward: float = 1.0, top=None) -> Panel:
    top = line((1, 1), (0, 1)) if top is None else top
    return Panel(name, (("bottom", line((0, 0), (1, 0))), ("right", line((1, 0), (1, 1))), ("top", top),
                        ("left", line((0, 1), (0, 0)))), origin=np.array([0.0, 0.0, z]), outward=outward)


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def test_a_panel_is_a_manifold_sheet_with_its_outline_as_boundary():
    curved = bezier((1, 1), (0.5, 0.6), (0, 1))
    mesh = triangulate_pattern(Pattern("x", (_square("a", 0.0, top=curved),), ()), 0.05)
    _, counts = _edges(mesh.faces)
    assert counts.max() == 2  # manifold
    assert np.count_nonzero(counts == 1) == 20 + 20 + 20 + round(float(np.linalg.norm(np.diff(curved, axis=0),
                                                                                  axis=1).sum()) / 0.05)
    assert set(np.unique(mesh.faces)) == set(range(len(mesh.uv)))  # every vertex used
    d = mesh.uv[mesh.faces]
    u, w = d[:, 1] - d[:, 0], d[:, 2] - d[:, 0]
    area = u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]
    assert np.all(area > 0)  # counter-clockwise
    assert area.sum() / 2 == pytest.approx(1.0 - 0.4 * 2 / 3 * 0.5, rel=0.02)  # the square less the curve's dip
    np.testing.assert_allclose(mesh.placed[:, :2], mesh.uv)


def test_a_seam_pairs_vertices_end_to_end_and_merges_them():
    front, back = _square("front", 0.2), _square("back", -0.2, outward=-1.0)
    pattern = Pattern("x", (front, back), (Seam(("front", "right"), ("back", "right")),
                                           Seam(("front", "left"), ("back", "left"))))
    mesh = triangulate_pattern(pattern, 0.1)
    assert mesh.seams.shape == (22, 2)
    np.testing.assert_allclose(mesh.uv[mesh.seams[:, 0]], mesh.uv[mesh.seams[:, 1]], atol=1e-12)
    d = mesh.placed[mesh.faces[mesh.panel[mesh.faces[:, 0]] == 1]]
    assert np.all(np.cross(d[:, 1] - d[:, 0], d[:, 2] - d[:, 0])[:, 2] < 0)  # a back panel faces -Z
    vertex_of = merge_seams(len(mesh.uv), mesh.seams)
    assert vertex_of.max() + 1 == len(mesh.uv) - 22  # a tube
    faces = vertex_of[mesh.faces]
    _, counts = _edges(faces)
    assert counts.max() == 2
    edges, lengths = pattern_edge_lengths(mesh.uv, faces, mesh.faces)
    assert lengths.min() > 0.04 and lengths.max() < 0.2


def test_malformed_patterns_name_the_panel():
    open_panel = Panel("gap", (("a", line((0, 0), (1, 0))), ("b", line((1, 0.1), (0, 0)))))
    with pytest.raises(PatternError, match="'gap'.*closed"):
        triangulate_pattern(Pattern("x", (open_panel,), ()), 0.1)
    clockwise = Panel("cw", (("a", line((0, 0), (0, 1))), ("b", line((0, 1), (1, 0))), ("c", line((1, 0), (0, 0)))))
    with pytest.raises(PatternError, match="counter-clockwise"):
        triangulate_pattern(Pattern("x", (clockwise,), ()), 0.1)
    with pytest.raises(PatternError, match="no edge 'nope'"):
        triangulate_pattern(Pattern("x", (_square("a", 0),), (Seam(("a", "nope"), ("a", "left")),)), 0.1)


@pytest.fixture(scope="module")
def body():
    return load_body_model()


@pytest.mark.parametrize("betas", [np.zeros(10), np.array([2.0, -1.0, 0.5, 0, 0, 0, 0, 0, 0, 0])])
def test_every_preset_drafts_a_closed_triangulated_pattern(body, betas):
    m = measure_body(body, betas)
    assert 0.8 < m.chest_girth < 1.4 and m.crotch_y < m.hip_y < m.waist_y < m.armpit_y < m.shoulder_y
    for category, presets in PRESETS.items():
        for preset in presets:
            pattern = draft(category, m, design_from_params(category, preset))
            mesh = triangulate_pattern(pattern, pattern_spacing(pattern, 600))
            assert 450 < len(mesh.uv) < 900, (category, preset, len(mesh.uv))
            # Seam sides of (nearly) equal length: sewn cloth is not stretched by its pattern.
            a, b = mesh.uv[mesh.seams[:, 0]], mesh.uv[mesh.seams[:, 1]]
            assert len(mesh.seams) > 20
            st = pack_uvs(mesh, np.array([p.outward for p in pattern.panels]))
            assert st.min() >= 0.0 and st.max() <= 1.0
            boxes = [(st[mesh.panel == p].min(0), st[mesh.panel == p].max(0)) for p in range(len(pattern.panels))]
            for i in range(len(boxes)):  # panels do not overlap in UV space
                for j in range(i):
                    overlap = np.minimum(boxes[i][1], boxes[j][1]) - np.maximum(boxes[i][0], boxes[j][0])
                    assert np.any(overlap <= 0), (category, preset, i, j)
            del a, b


def test_presets_differ_in_cut_and_topology(body):
    m = measure_body(body, np.zeros(10))
    shapes = set()
    for category, presets in PRESETS.items():
        for preset in presets:
            pattern = draft(category, m, design_from_params(category, preset))
            outline = [np.concatenate([e[:-1] for _, e in p.edges]) for p in pattern.panels]
            perimeter = sum(float(np.linalg.norm(r - np.roll(r, 1, axis=0), axis=1).sum()) for r in outline)
            shapes.add((category, len(pattern.panels), len(pattern.seams), round(perimeter, 2)))
    assert len(shapes) == sum(len(p) for p in PRESETS.values())
    assert len(PRESETS["tshirt"]) >= 9 and len(PRESETS["dress"]) >= 6 and len(PRESETS["trousers"]) >= 6


def test_design_parameters_are_checked():
    assert design_from_params("tshirt", "tank", {"ease": "0.2"}).ease == 0.2
    with pytest.raises(ArgumentError, match="valid: tshirt, dress, trousers"):
        design_from_params("skirt")
    with pytest.raises(ArgumentError, match="no such dress"):
        design_from_params("dress", "ballgown")
    with pytest.raises(ArgumentError, match="not a number"):
        design_from_params("trousers", None, {"length": "long"})
    with pytest.raises(ArgumentError, match="neck_shape"):
        design_from_params("tshirt", None, {"neck_shape": "square"})
