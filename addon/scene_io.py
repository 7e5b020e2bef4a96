"""All of the add-on's bpy plumbing: paths, preferences, progress, and the cache collection.

The operators call these helpers and cloth_usd; nothing here knows about USD contents.
"""

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path

import bpy

COLLECTION_NAME = "ClothUSD Cache"
_USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


def abspath(path: str) -> Path | None:
    """A Blender path (``//`` is the .blend's folder) as an absolute Path; None when empty."""
    return Path(bpy.path.abspath(path)).resolve() if path else None


def preferences(context):
    """This add-on's preferences, or None when it is registered without being enabled."""
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon else None


def body_model(context) -> Path | None:
    """The body model chosen in the preferences; None means cloth_usd's embedded one."""
    prefs = preferences(context)
    return abspath(prefs.body_model) if prefs else None


def models_dir(context) -> Path | None:
    """The model bundle folder chosen in the preferences; None means cloth_usd's shipped ones."""
    prefs = preferences(context)
    return abspath(prefs.models_dir) if prefs and prefs.models_dir else None


def output_paths(settings) -> tuple[Path, Path] | None:
    """``(cache layer, shot layer)`` a bake writes; None while no shot is chosen.

    The cache defaults to ``<shot stem>_cloth.usdc`` beside the shot; the shot layer is
    ``<cache stem>_shot.usda`` beside the cache.
    """
    shot = abspath(settings.shot_path)
    if shot is None:
        return None
    cache = abspath(settings.output_path) or shot.with_name(f"{shot.stem}_cloth.usdc")
    return cache, cache.with_name(f"{cache.stem}_shot.usda")


def frames(context, settings) -> str | None:
    """The ``START:END`` range to bake; None for the stage's own range."""
    if settings.frame_range == "SCENE":
        return f"{context.scene.frame_start}:{context.scene.frame_end}"
    if settings.frame_range == "CUSTOM":
        return f"{settings.frame_start}:{settings.frame_end}"
    return None


def last_imported_stage(context) -> str:
    """The USD file last imported with File > Import, or the newest USD cache file of
    this .blend that the add-on did not import itself; empty when there is none."""
    last = context.window_manager.operator_properties_last("wm.usd_import")
    if last is not None and last.filepath:
        return last.filepath
    ours = set(_cache_files(_objects(context.scene.cloth_usd.collection)))
    for cache in reversed(bpy.data.cache_files):
        if cache not in ours and cache.filepath.lower().endswith(_USD_SUFFIXES):
            return cache.filepath
    return ""


@contextlib.contextmanager
def progress(context, steps: int) -> Iterator:
    """Show progress in the status bar; yields ``advance(step)``."""
    wm = context.window_manager
    wm.progress_begin(0, steps)
    try:
        yield wm.progress_update
    finally:
        wm.progress_end()


def cache_collection(scene):
    """The scene's cache collection, created and linked under the scene when missing."""
    settings = scene.cloth_usd
    if settings.collection is None:
        settings.collection = bpy.data.collections.new(COLLECTION_NAME)
    if settings.collection.name not in scene.collection.children:
        scene.collection.children.link(settings.collection)
    return settings.collection


def remove_imported(collection) -> None:
    """Delete the collection's objects with their data, materials and cache files,
    as far as nothing else uses them (no orphans are left behind).

    Call it before importing a re-bake: while the old CacheFile lives, USD keeps its
    layers open and hands them to the new import, which would then play the old cache.
    """
    if collection is None:
        return
    objects = _objects(collection)
    data = {ob.data for ob in objects if ob.data is not None}
    materials = {m for d in data for m in getattr(d, "materials", ()) if m is not None}
    caches = set(_cache_files(objects))
    bpy.data.batch_remove(objects)
    for ids in (data, materials, caches):  # each group's users drop as the previous one goes
        bpy.data.batch_remove([i for i in ids if i.users == 0])


def usd_import_missing() -> str:
    """Why this Blender cannot import USD ('' when it can): some Linux distributions build
    Blender without USD (``bpy.app.build_options.usd`` is False)."""
    if not getattr(bpy.app.build_options, "usd", True) or not hasattr(bpy.ops.wm, "usd_import"):
        return ("this Blender was built without USD support, so the baked cache cannot be imported; "
                "use a blender.org build")
    return ""


def import_shot(context, collection, shot: Path, prim_paths: Sequence[str]) -> None:
    """Import the prims at ``prim_paths`` (and their ancestors) of a USD file into
    ``collection``; animated points become a Mesh Sequence Cache modifier.

    Raises RuntimeError when Blender's USD import fails.
    """
    missing = usd_import_missing()
    if missing:
        raise RuntimeError(missing)
    view_layer = context.view_layer
    view_layer.update()  # let the depsgraph drop its copies of removed cache files too
    previous = view_layer.active_layer_collection
    view_layer.active_layer_collection = view_layer.layer_collection.children[collection.name]
    try:
        result = bpy.ops.wm.usd_import(
            filepath=str(shot), prim_path_mask=",".join(prim_paths),
            import_cameras=False, import_lights=False, import_skeletons=False,
        )
    finally:
        view_layer.active_layer_collection = previous
    if result != {"FINISHED"}:
        raise RuntimeError(f"{shot}: Blender's USD import did not finish ({', '.join(result)})")


def _objects(collection) -> list:
    return list(collection.objects) if collection is not None else []


def _cache_files(objects) -> Iterator:
    for ob in objects:
        for mod in ob.modifiers:
            if mod.type == "MESH_SEQUENCE_CACHE" and mod.cache_file is not None:
                yield mod.cache_file
