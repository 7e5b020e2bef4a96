"""The Blender side of docs/addon_panel.png, a real screenshot of the add-on's panel.

Runs inside a windowed Blender (not bpy from PyPI, which has no UI), started by
``scripts/screenshot_addon.sh`` under Xvfb with software OpenGL:

    blender -P scripts/screenshot_addon.py -- SYNC_DIR

It registers ``addon/`` as an extension (a repository pointing at a copy, as
``addon/docs/make_render.py`` does), points the panel at the walk_tshirt sample and
presses Inspect and Bake (the add-on's own operators), opens the sidebar on the Cloth
USD tab, then tells the shell script where the 3D view is; that script widens the
sidebar with the mouse and takes the screenshot. Debian's Blender is built without USD,
so Bake writes the cache but cannot import it (``wm.usd_import`` is missing); the script
then shows the cache with a small pxr reader of its own (said on stderr) so the viewport
still shows the baked shirt. The body is drawn from cloth_usd's body model, as in
make_render.py: the shot has only the skeleton and the garment.
"""

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import bpy
from mathutils import Vector

ROOT = Path(__file__).resolve().parents[1]
sys.dont_write_bytecode = True  # no Python 3.13 caches in the checkout
sys.path.insert(0, str(ROOT))  # cloth_usd from this checkout
if os.environ.get("CLOTH_USD_SITE"):  # usd-core for this Blender's Python
    sys.path.insert(0, os.environ["CLOTH_USD_SITE"])
sys.path.insert(0, str(ROOT / "addon" / "docs"))
from make_render import body_mesh  # noqa: E402  the body as the Cycles render draws it

# The shell script takes the picture (X's own screenshot, xwd: Blender's screenshot
# operators read back black under Xvfb's software GL): READY says the UI is drawn and
# where the 3D view is, WIDTH is the sidebar's width now; DONE tells Blender to quit.
SYNC = Path(sys.argv[sys.argv.index("--") + 1]) if "--" in sys.argv else Path(tempfile.mkdtemp())
READY, DONE, WIDTH = SYNC / "READY", SYNC / "DONE", SYNC / "WIDTH"
FRAME = 1034
TMP = Path(tempfile.mkdtemp(prefix="cloth_usd_shot_"))


def log(msg: str) -> None:
    print(f"screenshot_addon: {msg}", file=sys.stderr, flush=True)


def enable_addon() -> None:
    import addon_utils

    shutil.copytree(ROOT / "addon", TMP / "repo" / "cloth_usd_blender",
                    ignore=shutil.ignore_patterns("__pycache__", "docs"))
    bpy.context.preferences.extensions.repos.new(name="Cloth USD", module="screenshot", source="USER",
                                                 custom_directory=str(TMP / "repo"))
    mod = addon_utils.enable("bl_ext.screenshot.cloth_usd_blender", default_set=True)
    if mod is None:
        raise SystemExit("screenshot_addon: could not enable the add-on (see the traceback above)")


def material(name: str, rgb) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*rgb, 1.0)  # what the Solid view draws with color_type MATERIAL
    return mat


def cache_mesh_fallback(shot_layer: Path, prim_path: str, frame: float):
    """Without Blender's USD import: the baked garment at ``frame``, read with pxr."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(shot_layer))
    mesh_prim = UsdGeom.Mesh(stage.GetPrimAtPath(prim_path))
    points = mesh_prim.GetPointsAttr().Get(frame)
    counts = mesh_prim.GetFaceVertexCountsAttr().Get()
    indices = list(mesh_prim.GetFaceVertexIndicesAttr().Get())
    xform = UsdGeom.Xformable(mesh_prim).ComputeLocalToWorldTransform(frame)
    faces, i = [], 0
    for n in counts:
        faces.append(indices[i:i + n])
        i += n
    pts = [tuple(xform.Transform(p)) for p in points]
    mesh = bpy.data.meshes.new(prim_path.rsplit("/", 1)[-1])
    mesh.from_pydata(pts, [], faces)
    mesh.shade_smooth()
    ob = bpy.data.objects.new(mesh.name, mesh)
    ob.rotation_euler = (1.5707963, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def setup() -> None:
    for ob in list(bpy.data.objects):  # the factory cube, camera and light
        bpy.data.objects.remove(ob)
    enable_addon()
    shots = Path("/tmp/shots")  # a short path, so the panel's Shot field shows most of it
    shots.mkdir(exist_ok=True)
    shot = Path(shutil.copy(ROOT / "samples" / "walk_tshirt" / "scene.usda", shots / "walk_tshirt.usda"))
    scene = bpy.context.scene
    settings = scene.cloth_usd
    settings.shot_path = str(shot)
    log(f"inspect: {bpy.ops.cloth_usd.inspect()}")
    try:
        log(f"bake: {bpy.ops.cloth_usd.bake()}")
    except (RuntimeError, AttributeError) as exc:  # no wm.usd_import in this Blender
        log(f"bake: {str(exc).strip().splitlines()[-2:]}")
    shirt = None
    if settings.collection is not None:
        shirt = next((ob for ob in settings.collection.objects if ob.type == "MESH"), None)
    if shirt is None:
        cache = Path(settings.baked_cache) if settings.baked_cache else shots / "walk_tshirt_cloth.usdc"
        if not cache.is_file():  # the add-on refuses to bake where it cannot import: bake with the API
            import cloth_usd
            cloth_usd.bake(shot, cache, shot=cache.with_name(f"{cache.stem}_shot.usda"), force=True)
            log(f"baked {cache} with cloth_usd.bake (the add-on's Bake needs Blender's USD import)")
        log(f"this Blender imported nothing (USD import: {bpy.app.build_options.usd}); "
            "showing the baked cache with the script's own pxr reader")
        shirt = cache_mesh_fallback(cache.with_name(f"{cache.stem}_shot.usda"), "/Character/Tshirt", FRAME)
    scene.frame_start, scene.frame_end = 1001, 1096
    scene.frame_set(FRAME)
    shirt.data.materials.append(material("Shirt", (0.1, 0.28, 0.7)))
    body = body_mesh(shot, FRAME)
    body.data.materials.append(material("Skin", (0.8, 0.62, 0.52)))

    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    space = area.spaces.active
    space.show_region_ui = True
    space.shading.type = "SOLID"
    space.shading.color_type = "MATERIAL"
    space.overlay.show_floor = True
    for ob in bpy.data.objects:
        ob.select_set(ob in (body, shirt))
    bpy.context.view_layer.objects.active = shirt
    region = next(r for r in area.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_axis(type="FRONT")
        bpy.ops.view3d.view_orbit(angle=0.5, type="ORBITLEFT")
        bpy.ops.view3d.view_orbit(angle=0.15, type="ORBITUP")
        bpy.ops.view3d.view_selected()
    r3d = space.region_3d
    r3d.view_perspective = "PERSP"
    # Keep the figure clear of the (widened) sidebar: move the view's centre to its right.
    r3d.view_location += r3d.view_rotation @ Vector((0.75, 0.0, 0.0))
    space.overlay.show_cursor = False
    for ob in bpy.data.objects:
        ob.select_set(False)


_ticks = 0


def tick():
    """Keep the Cloth USD tab in front and redraw; once Blender has drawn for a while,
    write READY (the 3D view's rectangle, for the crop) and wait for DONE, then quit."""
    global _ticks
    _ticks += 1
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    ui = next(r for r in area.regions if r.type == "UI")
    if ui.active_panel_category != "Cloth USD":
        ui.active_panel_category = "Cloth USD"
    for a in window.screen.areas:
        a.tag_redraw()
    WIDTH.write_text(str(ui.width))  # the shell script widens the sidebar by dragging its edge
    if _ticks == 8:
        rect = {"x": area.x, "y": window.height - area.y - area.height, "width": area.width,
                "height": area.height, "sidebar": ui.width}
        log(f"ready: {rect}")
        READY.write_text(json.dumps(rect))
    if DONE.exists() or _ticks > 600:
        bpy.ops.wm.quit_blender()
        return None
    return 0.5


try:
    setup()
except BaseException:
    import traceback
    traceback.print_exc()
    sys.stderr.flush()
    os._exit(1)  # quit_blender() does not quit while the -P script runs
else:
    bpy.app.timers.register(tick, first_interval=1.0)
