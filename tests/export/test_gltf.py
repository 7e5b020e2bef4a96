"""glTF files: what a player shows is the cache (within the chosen error), the body is
posed as defined, and the Khronos validator finds no error."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_usd.export.gltf import animated_garment_gltf, glb_bytes, gltf_bytes, read_accessor, read_glb
from cloth_usd.export.pca import fit_morph_basis
from tests.export.helpers import chain_body, grid_animation, play_gltf, skin_reference, validate


def _glb(anim, basis, body=None) -> tuple[dict, bytes]:
    return read_glb(glb_bytes(*animated_garment_gltf(anim, basis, body=body)))


@pytest.mark.parametrize("mm", [2.0, 0.5])
def test_player_shows_the_cache_within_the_error(patch, mm):
    basis = fit_morph_basis(patch.points, max_error=mm / 1000)
    doc, blob = _glb(patch, basis)
    for frame in (0, 7, patch.points.shape[0] - 1):
        shown = play_gltf(doc, blob, frame)["Patch"]
        assert np.linalg.norm(shown - patch.points[frame], axis=1).max() <= mm / 1000 + 2e-6


def test_animation_is_linear_weights_at_every_frame(patch):
    basis = fit_morph_basis(patch.points, targets=4)
    doc, blob = _glb(patch, basis)
    (anim,) = doc["animations"]
    (sampler,) = anim["samplers"]
    assert sampler["interpolation"] == "LINEAR" and anim["channels"][0]["target"]["path"] == "weights"
    np.testing.assert_allclose(read_accessor(doc, blob, sampler["input"]), patch.times, atol=1e-6)
    np.testing.assert_array_equal(read_accessor(doc, blob, sampler["output"]).reshape(-1, 4), basis.weights)
    assert len(doc["meshes"][0]["primitives"][0]["targets"]) == 4


def test_uvs_are_kept_with_v_flipped(patch):
    doc, blob = _glb(patch, fit_morph_basis(patch.points, targets=2))
    uv = read_accessor(doc, blob, doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"])
    np.testing.assert_allclose(uv[:, 0], patch.uvs[:, 0], atol=1e-7)
    np.testing.assert_allclose(uv[:, 1], 1.0 - patch.uvs[:, 1], atol=1e-7)
    doc, _ = _glb(grid_animation(uvs=False), fit_morph_basis(patch.points, targets=2))
    assert "TEXCOORD_0" not in doc["meshes"][0]["primitives"][0]["attributes"]


def test_skinned_body_is_posed_as_defined(patch):
    body = chain_body(t=patch.points.shape[0])
    doc, blob = _glb(patch, fit_morph_basis(patch.points, targets=3), body)
    for frame in (0, 11, 23):
        shown = play_gltf(doc, blob, frame)["body"]
        np.testing.assert_allclose(shown, skin_reference(body, frame), atol=1e-5)
    assert not np.allclose(skin_reference(body, 23), skin_reference(body, 0), atol=0.05)  # it does move


def test_validator_finds_no_error_in_glb_and_gltf(tmp_path, patch):
    basis = fit_morph_basis(patch.points, max_error=1e-3)
    doc, blob = animated_garment_gltf(patch, basis, body=chain_body(t=patch.points.shape[0]))
    (tmp_path / "a.glb").write_bytes(glb_bytes(doc, blob))
    (tmp_path / "a.gltf").write_bytes(gltf_bytes(doc, blob))
    for report in validate(tmp_path / "a.glb", tmp_path / "a.gltf"):
        assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]


def test_validator_catches_a_broken_file(tmp_path, patch):
    """The validator check can fail: a morph target's bounds that lie are an error."""
    doc, blob = animated_garment_gltf(patch, fit_morph_basis(patch.points, targets=2))
    doc = json.loads(json.dumps(doc))
    doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["max"] = [0.0, 0.0, 0.0]
    (tmp_path / "bad.glb").write_bytes(glb_bytes(doc, blob))
    (report,) = validate(tmp_path / "bad.glb")
    assert report["errors"] > 0
