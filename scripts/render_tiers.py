"""A close-up Cycles render of one frame of baked caches side by side, on the body.

    .venv-blender/bin/python scripts/render_tiers.py SCENE.usda FRAME OUT.png \\
        LABEL=CACHE.usdc [LABEL=CACHE.usdc ...] [--full] [--yaw=DEG]  # after bash scripts/test_addon.sh
        # --full: the whole figure (a dress, trousers); --yaw: the camera turned about the
        # up axis with a character that faces away from +Z
    .venv-blender/bin/python scripts/render_tiers.py --frame-file FRAME.npz OUT.png [--full]
        # FRAME.npz from scripts/testset_frame.py: a test-set frame, Newton's panel included

Each cache is a cloth_usd point cache of the scene's garment; the body is computed by
cloth_usd at that frame (the scene has only the skeleton). Blender's own USD (pxr) reads
the caches; Cycles renders on the CPU, a few seconds a panel. The camera frames the chest
and a sleeve from the front-left, where a painted-on shirt, speckle and folds show.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SITE = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib" / "python3.11" / "site-packages"
sys.path.append(str(SITE))  # Blender's own pxr
sys.path.insert(0, str(ROOT))


def studio(*, samples: int, width: int, height: int, lens: float):
    """An empty Cycles scene (CPU) with a pale grey sky, a grazing sun from the upper left
    (folds cast shade) and a camera that tracks an empty; returns ``(scene, camera, target)``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_x, scene.render.resolution_y = width, height
    world = bpy.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.85, 0.86, 0.88, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.6
    scene.world = world
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.5
    sun.rotation_euler = (0.9, 0.1, -0.7)
    scene.collection.objects.link(sun)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.lens = lens
    target = bpy.data.objects.new("Target", None)
    camera.constraints.new("TRACK_TO").target = target
    scene.collection.objects.link(camera)
    scene.collection.objects.link(target)
    scene.camera = camera
    return scene, camera, target


def save_row(scene, images: list, out: Path) -> None:
    """The rendered panels ``images`` (bpy images of the scene's resolution) side by side, as a PNG."""
    w, h = scene.render.resolution_x, scene.render.resolution_y
    pixels = np.concatenate([np.array(im.pixels[:]).reshape(h, w, 4) for im in images], axis=1)
    img = bpy.data.images.new(out.stem, w * len(images), h)
    img.pixels[:] = pixels.ravel()
    img.filepath_raw = str(out.resolve())
    img.file_format = "PNG"
    img.save()


def _mesh(name: str, verts: np.ndarray, faces: np.ndarray, rgb) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    mesh.shade_smooth()
    ob = bpy.data.objects.new(name, mesh)
    ob.rotation_euler = (np.pi / 2, 0.0, 0.0)  # Y-up metres -> Blender's Z-up
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    mesh.materials.append(mat)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _cache_points(cache: str, prim: str, frame: float) -> np.ndarray:
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(cache)
    value = layer.QueryTimeSample(f"{prim}.points", frame)
    if value is None:
        raise SystemExit(f"{cache}: no {prim}.points sample at time code {frame:g}")
    return np.array(value, dtype=np.float64)


def _render_panels(body_verts: np.ndarray, body_faces: np.ndarray, faces: np.ndarray,
                   panels: list[tuple[str, np.ndarray]], out: Path, forward=(0.0, 0.0, 1.0), *,
                   full: bool = False) -> None:
    """Render the garment points of each ``(label, (N, 3) points)`` panel on the posed body,
    seen from the front-left of a body facing ``forward`` (cloth_usd's frame, Y up): the chest
    and a sleeve, or with ``full`` the whole figure (a dress, trousers)."""
    scene, camera, target = studio(samples=32, width=420, height=520 if not full else 640, lens=60)
    body = _mesh("Body", body_verts, body_faces, (0.8, 0.62, 0.52))
    # chest height, from the front-left (Blender Z-up: cloth_usd's y is Blender's z)
    chest = body_verts[body_verts[:, 1] > np.quantile(body_verts[:, 1], 0.6)].mean(axis=0)
    if full:
        chest = 0.5 * (body_verts.min(axis=0) + body_verts.max(axis=0)) + [0.0, 0.05, 0.0]
    centre = np.array([chest[0], -chest[2], chest[1] - 0.05])
    target.location = centre
    yaw = np.arctan2(forward[0], forward[2])
    side, ahead = (0.55, 1.55) if not full else (0.9, 3.2)  # to the body's left (+X at rest), in front (+Z)
    x = side * np.cos(yaw) + ahead * np.sin(yaw)
    z = -side * np.sin(yaw) + ahead * np.cos(yaw)
    camera.location = centre + np.array([x, -z, 0.25])

    tmp = Path(tempfile.mkdtemp(prefix="cloth_usd_tiers_"))
    images = []
    for k, (label, pts) in enumerate(panels):
        shirt = _mesh(label, pts, faces, (0.1, 0.25, 0.62))
        scene.render.filepath = str(tmp / f"panel_{k}.png")
        bpy.ops.render.render(write_still=True)
        images.append(bpy.data.images.load(scene.render.filepath))
        bpy.data.objects.remove(shirt)
        print(f"{label}: rendered", flush=True)
    del body
    save_row(scene, images, out)


def main(argv: list[str]) -> None:
    full = "--full" in argv
    if argv and argv[0] == "--frame-file" and len([a for a in argv if a != "--full"]) == 3:
        frame_file, out = (a for a in argv[1:] if a != "--full")
        data = np.load(frame_file)
        panels = [(str(label), pts) for label, pts in zip(data["labels"], data["points"])]
        _render_panels(data["body_vertices"], data["body_faces"], data["garment_faces"], panels, Path(out),
                       forward=data["forward"], full=full)
        print(f"wrote {out} ({', '.join(label for label, _ in panels)}; {data['sequence']}, "
              f"frame {int(data['frame'])})")
        return
    yaw = next((float(a.split("=", 1)[1]) for a in argv if a.startswith("--yaw=")), 0.0)
    argv = [a for a in argv if a != "--full" and not a.startswith("--yaw=")]
    if len(argv) < 4:
        raise SystemExit(__doc__)
    scene_path, frame, out = argv[0], float(argv[1]), Path(argv[2])
    from cloth_usd.render import posed_bodies
    from cloth_usd.usd.read import open_stage, read_scene

    stage = open_stage(scene_path)
    scene_data = read_scene(stage)
    garment = next(g for g in scene_data.garments if g.enabled)
    ((body_verts, body_faces),) = posed_bodies(stage, scene_data, [frame])
    panels = [(label, _cache_points(cache, garment.prim_path, frame)) for label, cache in
              (a.split("=", 1) for a in argv[3:])]
    forward = (np.sin(np.radians(yaw)), 0.0, np.cos(np.radians(yaw)))
    _render_panels(body_verts[0], body_faces, garment.triangles, panels, out, full=full, forward=forward)
    print(f"wrote {out} ({', '.join(label for label, _ in panels)}, time code {frame:g})")


if __name__ == "__main__":
    main(sys.argv[1:])
