"""Render a frame of a shot (body + garments) to PNG, to look at a bake.

Uses matplotlib (the ``preview`` extra; ``scripts/setup.sh`` installs it) with flat Lambert
shading: a preview, not a production render. The body comes from the body model, the
garment points from the composed stage, so what is drawn is what a USD viewer would show.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .core.body import lbs, load_body_model, shape_body
from .core.frames import canonical_motion
from .core.shards import read_shard
from .errors import ArgumentError, ClothUsdError, OutputWriteError
from .usd.read import garment_points_internal, open_stage, read_motion, read_scene

__all__ = ["draw_panels", "posed_bodies", "render_frames", "render_shard", "shard_frames"]

BODY_RGB = (0.85, 0.68, 0.58)
GARMENT_RGB = (0.25, 0.45, 0.75)

_VIEWS = {"front": (0.0, 0.0), "side": (0.0, 90.0), "three-quarter": (10.0, 35.0)}


def _shade(tri: np.ndarray, light: np.ndarray) -> np.ndarray:
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return 0.35 + 0.65 * np.abs(n @ light)


def draw_panels(panels: Sequence[tuple[str, list[tuple[np.ndarray, tuple[float, float, float]]]]],
                output: str | Path, *, view: str = "three-quarter",
                size: tuple[float, float] = (4.0, 5.0)) -> Path:
    """Draw meshes side by side into one PNG, one panel per (title, meshes).

    Args:
        panels: per panel its title and meshes, each ``(triangles (F, 3, 3) [m] Y-up, rgb)``.
    """
    try:
        import matplotlib
    except ImportError as exc:
        raise ClothUsdError(f"cloth-usd render draws with matplotlib ({exc}); install it with pip install "
                            "'cloth-usd[preview]'") from exc

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    if view not in _VIEWS:
        raise ArgumentError(f"--view '{view}': unknown (valid: {', '.join(_VIEWS)})")
    fig = plt.figure(figsize=(size[0] * len(panels), size[1]), dpi=100)
    light = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
    for i, (title, meshes) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1, projection="3d")
        # One collection, so matplotlib depth-sorts body and garment triangles together.
        tris = np.concatenate([m[0] for m in meshes])[:, :, [0, 2, 1]]  # matplotlib's z is up
        colors = np.concatenate([np.broadcast_to(c, (m.shape[0], 3)) for m, c in meshes])
        shade = _shade(tris, light[[0, 2, 1]])[:, None] * colors
        ax.add_collection3d(Poly3DCollection(tris, facecolors=shade, edgecolors="none"))
        allpts = np.concatenate([m[0].reshape(-1, 3) for m in meshes])[:, [0, 2, 1]]
        center, radius = allpts.mean(axis=0), np.ptp(allpts, axis=0).max() / 2
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), center):
            setter(c - radius, c + radius)
        ax.set_box_aspect((1, 1, 1))
        elev, azim = _VIEWS[view]
        ax.view_init(elev=elev, azim=azim - 90)
        ax.set_axis_off()
        ax.set_title(title)
    output = Path(output)
    try:
        fig.savefig(output, bbox_inches="tight")
    except OSError as exc:
        raise OutputWriteError(f"-o {output}: cannot write the PNG ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
    return output


def posed_bodies(stage, scene, times: Sequence[float], *, body_model: str | Path | None = None
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each character's body posed at some time codes, in cloth_usd's frame (Y-up metres).

    Args:
        stage: an open ``Usd.Stage``; scene: its :func:`~cloth_usd.usd.read.read_scene`.
        times: (T,) time codes.
    Returns:
        per character ``(vertices (T, V, 3) float64 [m], faces (F, 3) int)``.
    """
    times = np.asarray(times, dtype=np.float64)
    out = []
    for char in scene.characters:
        body = load_body_model(body_model, gender=char.gender)
        v_shaped, joints = shape_body(body, char.betas)
        motion = canonical_motion(char, read_motion(stage, char, times), joints)
        out.append((lbs(body, v_shaped, joints, motion.poses, motion.transl)[0], body.faces))
    return out


def render_frames(stage_path: str | Path, frames: Sequence[float], output: str | Path, *,
                  body_model: str | Path | None = None, view: str = "three-quarter",
                  size: tuple[float, float] = (4.0, 5.0)) -> Path:
    """Draw body and garments at each frame side by side into one PNG.

    Args:
        frames: (T,) time codes (:func:`~cloth_usd.core.frame_range.parse_time_codes`).
    """
    if view not in _VIEWS:
        raise ArgumentError(f"--view '{view}': unknown (valid: {', '.join(_VIEWS)})")
    stage = open_stage(stage_path)
    scene = read_scene(stage)
    times = np.asarray(frames, dtype=np.float64)
    bodies = [verts[:, faces] for verts, faces in posed_bodies(stage, scene, times, body_model=body_model)]
    panels = []
    for i, t in enumerate(times):
        meshes = [(tri[i], BODY_RGB) for tri in bodies]
        for g in scene.garments:
            pts = garment_points_internal(stage, g.prim_path, float(t))
            meshes.append((pts[g.triangles], GARMENT_RGB))
        panels.append((f"time code {t:g}", meshes))
    return draw_panels(panels, output, view=view, size=size)


def shard_frames(times: Sequence[float], text: str) -> list[int]:
    """A shard's frame indices from parsed ``--frames`` values (``text``, to name them).

    Raises:
        ArgumentError: a value that is not a whole number.
    """
    bad = [t for t in times if not float(t).is_integer()]
    if bad:
        raise ArgumentError(f"--frames '{text}': a shard's frames are indices (whole numbers), not {bad[0]:g}")
    return [int(t) for t in times]


def render_shard(shard_path: str | Path, frames: Sequence[int], output: str | Path, *,
                 body_model: str | Path | None = None, view: str = "three-quarter",
                 size: tuple[float, float] = (4.0, 5.0)) -> Path:
    """Draw a simulated sequence of the data factory (a shard) at some frame indices."""
    shard = read_shard(shard_path)
    count = shard.positions.shape[0]
    bad = [f for f in frames if not 0 <= int(f) < count]
    if bad:
        raise ArgumentError(f"--frames {bad}: {shard_path} has frames 0-{count - 1}")
    body = load_body_model(body_model)
    v_shaped, joints = shape_body(body, shard.betas)
    idx = np.asarray(frames, dtype=np.int64)
    posed = lbs(body, v_shaped, joints, shard.poses[idx], shard.transl[idx])[0]
    panels = [(f"frame {f}", [(posed[i][body.faces], BODY_RGB),
                              (shard.positions[f].astype(np.float64)[shard.garment_faces], GARMENT_RGB)])
              for i, f in enumerate(idx)]
    return draw_panels(panels, output, view=view, size=size)
