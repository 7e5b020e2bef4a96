"""The preview page: self-contained, loads in headless chromium without a console error,
and draws the garment; its player bundle is what scripts/build_preview_bundle.sh builds."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from cloth_usd.export.convert import garment_glb
from cloth_usd.export.pca import fit_morph_basis
from cloth_usd.export.preview import preview_html
from tests.export.helpers import ROOT, WEB, chain_body, chromium, console_lines, grid_animation, pixel_fractions


def _page(tmp_path, *, glb: bytes | None = None):
    anim = grid_animation(t=48)
    if glb is None:
        glb = garment_glb(anim, fit_morph_basis(anim.points, max_error=1e-3), chain_body(t=48), "test")
    page = tmp_path / "preview.html"
    page.write_text(preview_html(glb, title="patch", times=anim.times, time_codes=anim.time_codes,
                                 track=anim.points.mean(axis=1), floor=0.0), encoding="utf-8")
    return page


def test_page_is_self_contained(tmp_path):
    text = _page(tmp_path).read_text(encoding="utf-8")
    assert "<script src" not in text and "<link" not in text and "import(" not in text
    assert not re.search(r"""(src|href)\s*=\s*["']?https?:""", text)
    assert text.count("</script>") == 2  # the data and the player; the bundle cannot end a script early
    assert "three.js" in text and "SPDX-License-Identifier: MIT" in text


@pytest.mark.slow
def test_page_loads_without_errors_and_shows_the_garment(tmp_path):
    page = _page(tmp_path)
    dom = chromium(page, tmp_path)
    assert 'data-state="ready"' in dom.stdout, (dom.stdout[-2000:], console_lines(dom.stderr))
    assert '<pre id="errors" hidden=""></pre>' in dom.stdout
    logged = console_lines(dom.stderr)
    assert any("cloth-usd preview: ready" in line for line in logged)
    assert not [line for line in logged if re.search(r"error|warn|deprecat|uncaught", line, re.I)
                and "GPU stall due to ReadPixels" not in line], logged
    shot = tmp_path / "shot.png"
    chromium(page, tmp_path, screenshot=shot)
    assert pixel_fractions(shot)[0] > 0.01  # the garment is drawn, not a blank canvas


@pytest.mark.slow
def test_a_broken_glb_is_reported_on_the_page(tmp_path):
    """The checks above can fail: a page whose glTF does not parse says so and is not ready."""
    page = _page(tmp_path, glb=b"glTF" + bytes(40))
    dom = chromium(page, tmp_path)
    assert 'data-state="error"' in dom.stdout and "cannot read the embedded glTF" in dom.stdout
    shot = tmp_path / "shot.png"
    chromium(page, tmp_path, screenshot=shot)
    assert pixel_fractions(shot)[0] < 0.001


def test_bundle_is_reproducible(tmp_path):
    """The committed player is what the build script makes from web/ (same npm versions)."""
    if shutil.which("node") is None or not (WEB / "node_modules" / "esbuild").is_dir():
        pytest.skip("web/node_modules is not installed (bash scripts/setup_web.sh)")
    out = tmp_path / "bundle.js"
    subprocess.run(["bash", str(ROOT / "scripts" / "build_preview_bundle.sh"), str(out)], check=True, timeout=300,
                   capture_output=True)
    committed = ROOT / "cloth_usd" / "export" / "assets" / "preview.bundle.js"
    assert out.read_bytes() == committed.read_bytes(), "run bash scripts/build_preview_bundle.sh and commit"
