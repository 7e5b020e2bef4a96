"""``cloth-usd preview``: one self-contained HTML page that plays a baked shot.

The page holds the .glb (base64) that ``convert --with-body`` would write and the player,
``assets/preview.bundle.js`` (web/preview.js bundled with three.js by
scripts/build_preview_bundle.sh). It needs no server and no network: open the file.
"""

from __future__ import annotations

import base64
import html
import json
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from .convert import compress, garment_glb, read_baked
from .files import check_output_file, write_atomic
from .pca import vertex_errors

__all__ = ["PreviewResult", "preview_html", "write_preview"]

_PAGE = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="cloth-usd">
<title>{title}</title>
<style>
html, body {{ margin: 0; height: 100%; font: 14px system-ui, sans-serif; background: #e8ebef; }}
#view {{ position: absolute; inset: 0 0 48px 0; }}
#bar {{ position: absolute; left: 0; right: 0; bottom: 0; height: 48px; display: flex; gap: 12px;
        align-items: center; padding: 0 12px; background: #2b2f36; color: #eef; box-sizing: border-box; }}
#time {{ flex: 1; }}
#label {{ min-width: 15em; font-variant-numeric: tabular-nums; }}
#title {{ position: absolute; left: 12px; top: 8px; color: #333; }}
#errors {{ position: absolute; left: 12px; top: 32px; color: #b00; white-space: pre-wrap; }}
</style>
</head>
<body data-state="loading">
<div id="view"></div>
<div id="title">{heading}</div>
<pre id="errors" hidden></pre>
<div id="bar"><button id="play" type="button">Pause</button><input id="time" type="range" min="0" max="0" step="1" value="0"
 aria-label="frame"><span id="label"></span></div>
<script id="cloth-usd-data" type="application/json">{data}</script>
<script>{player}</script>
</body>
</html>
"""


@dataclass(frozen=True)
class PreviewResult:
    path: Path
    frames: int
    targets: int
    max_error_mm: float


def _player() -> str:
    js = resources.files("cloth_usd.export").joinpath("assets/preview.bundle.js").read_text(encoding="utf-8")
    return js.replace("</script", "<\\/script")  # the page's parser must not see it end early


def preview_html(glb: bytes, *, title: str, times: np.ndarray, time_codes: np.ndarray, track: np.ndarray,
                 floor: float) -> str:
    """The page for a .glb.

    Args:
        times: (T,) seconds of each frame (the glb's animation keys).
        time_codes: (T,) the USD time code of each frame, shown on the timeline.
        track: (T, 3) the garment's centre per frame [m]; the camera follows it.
        floor: height of the ground grid [m].
    """
    data = {"glb": base64.b64encode(glb).decode(), "frames": int(track.shape[0]),
            "times": [float(t) for t in times], "codes": [f"{c:g}" for c in time_codes],
            "track": np.round(track, 4).tolist(), "floor": floor}
    return _PAGE.format(title=html.escape(title), heading=html.escape(title), data=json.dumps(data),
                        player=_player())


def write_preview(source: str | os.PathLike, output: str | os.PathLike, *, max_error_mm: float | None = None,
                  targets: int | None = None, with_body: bool = True, garment: str | None = None,
                  scene: str | os.PathLike | None = None, body_model: str | os.PathLike | None = None,
                  force: bool = False) -> PreviewResult:
    """Write the preview page of a baked shot or cache (garment and, by default, body)."""
    out = check_output_file(output, force=force, suffixes=(".html", ".htm"))
    anim, body = read_baked(source, garment=garment, scene=scene, with_body=with_body, body_model=body_model)
    basis = compress(anim, max_error_mm=max_error_mm, targets=targets)
    glb = garment_glb(anim, basis, body, source)
    lowest = anim.points[..., 1].min()
    if body is not None:
        lowest = min(lowest, float(body.rest_vertices[:, 1].min() - body.rest_joints[0, 1]
                                   + body.root_translation[:, 1].min()))
    title = f"{Path(os.fspath(source)).name}: {anim.name}, {anim.points.shape[0]} frames at {anim.fps:g} fps"
    track = anim.points.mean(axis=1)
    if body is not None:  # aim below the garment's centre, nearer the body's
        track = track - [0.0, 0.25, 0.0]
    page = preview_html(glb, title=title, times=anim.times, time_codes=anim.time_codes, track=track,
                        floor=float(lowest))
    write_atomic(out, page.encode("utf-8"))
    err = vertex_errors(basis.reconstruct(), anim.points)
    return PreviewResult(path=out, frames=anim.points.shape[0], targets=int(basis.targets.shape[0]),
                         max_error_mm=float(err.max() * 1000))
