"""Render addon/docs/render.png: the sample shot baked by the add-on, in Blender.

    .venv-blender/bin/python addon/docs/make_render.py      # after bash scripts/test_addon.sh

Bakes samples/walk_tshirt with the add-on's operator (as an animator would), adds the
body at the rendered frame (the stage has no body mesh; cloth_usd computes it), and
renders with Cycles on the CPU. bpy as a module draws no windows; the panel screenshot
comes from scripts/screenshot_addon.sh.
"""

import shutil
import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FRAMES = (1020, 1034)  # half a stride apart, side by side
SITE = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib" / "python3.11" / "site-packages"
sys.path.append(str(SITE))  # Blender's own pxr, as inside Blender


def enable_addon(tmp: Path) -> None:
    import addon_utils  # importable once bpy is

    shutil.copytree(ROOT / "addon", tmp / "repo" / "cloth_usd_blender",
                    ignore=shutil.ignore_patterns("__pycache__", "docs"))
    bpy.context.preferences.extensions.repos.new(name="docs", module="docs", source="USER",
                                                 custom_directory=str(tmp / "repo"))
    addon_utils.enable("bl_ext.docs.cloth_usd_blender", default_set=True)


def body_mesh(shot: Path, frame: float):
    """The posed body of the shot's character at ``frame``, as a Blender object."""
    from cloth_usd.render import posed_bodies
    from cloth_usd.usd.read import open_stage, read_scene

    stage = open_stage(shot)
    ((verts, faces),) = posed_bodies(stage, read_scene(stage), [frame])
    mesh = bpy.data.meshes.new("Body")
    mesh.from_pydata(verts[0].tolist(), [], faces.tolist())
    mesh.shade_smooth()
    ob = bpy.data.objects.new("Body", mesh)
    ob.rotation_euler = (np.pi / 2, 0.0, 0.0)  # cloth_usd's Y-up metres -> Blender's Z-up
    bpy.context.scene.collection.objects.link(ob)
    return ob


def material(name: str, rgb: tuple[float, float, float]):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # before Blender 5.0
        mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
    return mat


def main() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    tmp = Path(tempfile.mkdtemp(prefix="cloth_usd_docs_"))
    enable_addon(tmp)
    shot = Path(shutil.copy(ROOT / "samples" / "walk_tshirt" / "scene.usda", tmp / "walk_tshirt.usda"))
    scene = bpy.context.scene
    scene.cloth_usd.shot_path = str(shot)
    assert bpy.ops.cloth_usd.bake() == {"FINISHED"}
    shirt = next(ob for ob in scene.cloth_usd.collection.objects if ob.type == "MESH")
    shirt.data.materials.append(material("Shirt", (0.08, 0.22, 0.6)))
    shirt.modifiers.new("Smooth", "SUBSURF").levels = 1

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 24
    scene.render.resolution_x, scene.render.resolution_y = 360, 480
    scene.render.film_transparent = False
    world = bpy.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.8, 0.82, 0.85, 1.0)
    scene.world = world
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (0.7, 0.2, 0.6)
    scene.collection.objects.link(sun)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    target = bpy.data.objects.new("Target", None)
    camera.constraints.new("TRACK_TO").target = target
    scene.collection.objects.link(camera)
    scene.collection.objects.link(target)
    scene.camera = camera

    skin = material("Skin", (0.8, 0.6, 0.5))
    images = []
    for frame in FRAMES:
        body = body_mesh(shot, frame)
        body.data.materials.append(skin)
        scene.frame_set(frame)
        rest_centre = np.mean([v.co for v in body.data.vertices], axis=0)
        centre = np.array(body.matrix_world) @ np.append(rest_centre, 1.0)
        target.location = centre[:3]
        camera.location = centre[:3] + np.array([1.4, -2.8, 0.35])  # in front, to the side
        scene.render.filepath = str(tmp / f"frame_{frame}.png")
        bpy.ops.render.render(write_still=True)
        images.append(bpy.data.images.load(scene.render.filepath))
        bpy.data.objects.remove(body)

    # Side by side into one PNG.
    w, h = scene.render.resolution_x, scene.render.resolution_y
    pixels = np.concatenate([np.array(im.pixels[:]).reshape(h, w, 4) for im in images], axis=1)
    out = bpy.data.images.new("render", 2 * w, h)
    out.pixels[:] = pixels.ravel()
    out.filepath_raw = str(ROOT / "addon" / "docs" / "render.png")
    out.file_format = "PNG"
    out.save()
    print(out.filepath_raw)


if __name__ == "__main__":
    main()
