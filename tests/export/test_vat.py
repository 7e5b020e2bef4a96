"""VAT 3.0 soft-body files: the stock shader's decode (re-implemented in decode_vat from
the published material) gives back the cache; layout, bounds flags and normals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cloth_usd.errors import OutputExistsError
from cloth_usd.export.convert import vat_errors
from cloth_usd.export.gltf import read_accessor, read_glb
from cloth_usd.export.vat import (Engine, TextureFormat, _snapped_bounds, decode_normals, decode_vat, encode_normals,
                                  read_png16, vat_layout, write_vat)
from tests.export.helpers import grid_animation, validate


def _needs(fmt: TextureFormat) -> None:
    if fmt is TextureFormat.EXR:
        pytest.importorskip("OpenEXR", reason="EXR textures need the game extra: pip install 'cloth-usd[game]'")


@pytest.mark.parametrize("engine", list(Engine))
@pytest.mark.parametrize("fmt, tolerance", [(TextureFormat.EXR, 1e-3), (TextureFormat.PNG16, 2e-5)])
def test_decoded_textures_give_back_the_cache(tmp_path, patch, engine, fmt, tolerance):
    """EXR: half floats of offsets below 0.5 m (2^-11 relative); PNG: 1/65535 of the bounds."""
    _needs(fmt)
    result = write_vat(patch, tmp_path / "vat", engine=engine, fmt=fmt, max_width=7)
    err = vat_errors(result, patch)
    assert err.max() < tolerance
    assert result.layout.rows_per_frame == 6  # 36 vertices, 7 wide
    assert err.shape == patch.points.shape[:2]


def test_layout_wraps_rows_and_uv_addresses_texel_centres():
    layout = vat_layout(10, 3, max_width=4)
    assert (layout.width, layout.rows_per_frame, layout.height) == (4, 3, 9)
    uv = layout.uv(10)
    np.testing.assert_allclose(uv[5], [1.5 / 4, 1.5 / 9])
    assert vat_layout(10, 3).width == 10 and vat_layout(10, 3).rows_per_frame == 1


def test_files_mesh_and_json(tmp_path, patch):
    result = write_vat(patch, tmp_path / "vat", fmt=TextureFormat.PNG16)
    names = sorted(p.name for p in (tmp_path / "vat").iterdir())
    assert names == ["Patch_data.json", "Patch_mesh.glb", "Patch_pos.png", "Patch_rot.png"]
    data = json.loads((tmp_path / "vat" / "Patch_data.json").read_text())
    assert data["material"]["Frame Count"] == 24 and data["material"]["Houdini FPS"] == 24.0
    assert data["texture"] == {**data["texture"], "width": 36, "height": 24, "rows_per_frame": 1}
    assert read_png16(tmp_path / "vat" / "Patch_pos.png").shape == (24, 36, 4)
    doc, blob = read_glb((tmp_path / "vat" / "Patch_mesh.glb").read_bytes())
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    np.testing.assert_allclose(read_accessor(doc, blob, attrs["POSITION"]), patch.points[0], atol=1e-6)
    np.testing.assert_allclose(read_accessor(doc, blob, attrs["TEXCOORD_1"]), result.layout.uv(36), atol=1e-7)
    (report,) = validate(tmp_path / "vat" / "Patch_mesh.glb")
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]


@pytest.mark.parametrize("scale", [1.0, 100.0])
@pytest.mark.parametrize("hdr, rows", [(True, 1), (False, 3), (True, 250)])
def test_bounds_flags_read_back_in_float32(scale, hdr, rows):
    """What the shader reads from the bounds: raw or normalised data, the whole texture used."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        lo = rng.uniform(-5, 0, 3) * scale
        hi = lo + rng.uniform(0, 5, 3) * scale
        bmin, bmax = _snapped_bounds(lo, hi, scale, hdr=hdr, rows=rows)
        assert np.all(bmin <= lo) and np.all(bmax >= hi - 1e-4 * scale)
        f32 = np.float32
        bmin10, bmax10 = bmin.astype(f32) * f32(10 / scale), bmax.astype(f32) * f32(10 / scale)
        assert ((bmax10[2] - np.floor(bmax10[2])) >= 0.5) == hdr
        assert 1 - (np.ceil(bmin10[2]) - bmin10[2]) > 1 - 1e-3  # used width: all of it
        assert 1 - ((-bmax10[0]) - np.floor(-bmax10[0])) > 1 - 1e-3  # used height: all of it
        assert int(np.rint(100 * (np.ceil(bmin10[1]) - bmin10[1]))) == rows % 100


def test_compressed_normals_within_the_5_bit_quantisation():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(2000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.concatenate([n, [[0, 1, 0], [1, 0, 0], [0, 0, -1], [0, -0.9999, 0.01]]])
    codes = encode_normals(n)
    assert codes.min() >= 0 and codes.max() <= 1023
    back = decode_normals(codes / 1024.0)
    angle = np.degrees(np.arccos(np.clip(np.sum(back * n, axis=1), -1, 1)))
    # 32 x 32 codes: about 3 degrees typical; coarser towards -Y, where the sphere map squeezes
    assert np.median(angle) < 4.0 and np.percentile(angle, 95) < 7.0
    assert angle[n[:, 1] > -0.5].max() < 8.0 and angle[-4:-1].max() < 8.0


@pytest.mark.parametrize("fmt, degrees", [(TextureFormat.EXR, 0.05), (TextureFormat.PNG16, 0.01)])
def test_decoded_normals_are_the_surface_normals(tmp_path, fmt, degrees):
    """From the rotation texture, to the precision of the format; compressed (position
    alpha), to 5 bits a code. The patch waves, so its normals change over time."""
    _needs(fmt)
    from cloth_usd.export.gltf import _vertex_normals
    from cloth_usd.export.vat import read_exr

    patch = grid_animation(t=12)
    result = write_vat(patch, tmp_path / "vat", engine=Engine.UNREAL, fmt=fmt)
    doc, blob = read_glb(result.files[0].read_bytes())
    uv1 = read_accessor(doc, blob, doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"])

    def load(path):
        return read_exr(path) if fmt is TextureFormat.EXR else read_png16(path) / 65535.0

    position, rotation = load(result.files[1]), load(result.files[2])
    for frame in (0, 5, 11):
        want = _vertex_normals(patch.points[frame], patch.triangles)
        _, exact = decode_vat(position, uv1, patch.points[0], result.data, frame, rotation=rotation)
        _, packed = decode_vat(position, uv1, patch.points[0], result.data, frame)
        angle = np.degrees(np.arccos(np.clip(np.sum(exact * want, axis=1), -1, 1)))
        assert angle.max() < degrees
        angle = np.degrees(np.arccos(np.clip(np.sum(packed * want, axis=1), -1, 1)))
        assert angle.max() < 6.0


def test_existing_files_need_force(tmp_path, patch):
    write_vat(patch, tmp_path / "vat", fmt=TextureFormat.PNG16)
    with pytest.raises(OutputExistsError, match="--force"):
        write_vat(patch, tmp_path / "vat", fmt=TextureFormat.PNG16)
    write_vat(patch, tmp_path / "vat", fmt=TextureFormat.PNG16, force=True)
    assert not [p for p in (tmp_path / "vat").iterdir() if p.name.startswith(".")]
