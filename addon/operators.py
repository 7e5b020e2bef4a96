"""The panel's buttons: Use Last Import, Inspect and Bake. cloth_usd does the work."""

from bpy.types import Operator

import cloth_usd
from cloth_usd.errors import ClothUsdError

from . import scene_io


class CLOTH_USD_OT_use_last_import(Operator):
    """Use the USD file last imported into Blender as the shot"""

    bl_idname = "cloth_usd.use_last_import"
    bl_label = "Use Last Imported Stage"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return bool(scene_io.last_imported_stage(context))

    def execute(self, context):
        context.scene.cloth_usd.shot_path = scene_io.last_imported_stage(context)
        return {'FINISHED'}


class CLOTH_USD_OT_inspect(Operator):
    """List the shot's characters, garments, warnings and contract problems"""

    bl_idname = "cloth_usd.inspect"
    bl_label = "Inspect"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return bool(context.scene.cloth_usd.shot_path)

    def execute(self, context):
        settings = context.scene.cloth_usd
        try:
            report = cloth_usd.inspect_stage(scene_io.abspath(settings.shot_path),
                                             body_model=scene_io.body_model(context))
        except ClothUsdError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        settings.inspected.clear()
        for kind, text in summary_lines(report):
            item = settings.inspected.add()
            item.kind, item.text = kind, text
        stage = report.scene.stage
        if stage.start_time_code is not None and stage.end_time_code is not None:
            settings.frame_start, settings.frame_end = int(stage.start_time_code), int(stage.end_time_code)
        else:
            settings.frame_start, settings.frame_end = context.scene.frame_start, context.scene.frame_end
        scene = report.scene
        self.report({'WARNING'} if report.problems or report.warnings else {'INFO'},
                    f"{len(scene.characters)} character(s), {len(scene.garments)} garment(s), "
                    f"{len(report.warnings)} warning(s), {len(report.problems)} problem(s)")
        return {'FINISHED'}


class CLOTH_USD_OT_bake(Operator):
    """Bake the shot's garments into a USD point cache and import it (replacing the last bake)"""

    bl_idname = "cloth_usd.bake"
    bl_label = "Bake"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return bool(context.scene.cloth_usd.shot_path)

    def execute(self, context):
        settings = context.scene.cloth_usd
        missing = scene_io.usd_import_missing()
        if missing:  # before baking, so nothing is written that cannot be shown
            self.report({'ERROR'}, missing)
            return {'CANCELLED'}
        cache, shot_layer = scene_io.output_paths(settings)
        own = str(cache) == settings.baked_cache  # re-baking our own output replaces it
        with scene_io.progress(context, 3) as advance:
            try:
                result = cloth_usd.bake(scene_io.abspath(settings.shot_path), cache, shot=shot_layer,
                                        frames=scene_io.frames(context, settings), tier=settings.tier,
                                        force=own or settings.overwrite,
                                        body_model=scene_io.body_model(context),
                                        models=scene_io.models_dir(context))
            except (ClothUsdError, OSError) as exc:
                self.report({'ERROR'}, str(exc))
                return {'CANCELLED'}
            advance(1)
            settings.baked_cache = str(result.cache)
            collection = scene_io.cache_collection(context.scene)
            scene_io.remove_imported(collection)
            advance(2)
            try:
                scene_io.import_shot(context, collection, result.shot, [g.prim_path for g in result.garments])
            except RuntimeError as exc:
                self.report({'ERROR'}, f"baked {result.cache} but could not import it: {exc}")
                return {'CANCELLED'}
            advance(3)
        frames = result.times.shape[0]
        warnings = [w for g in result.garments for w in g.warnings]  # the guard's and the trained range's
        settings.bake_warnings.clear()
        for text in warnings:
            item = settings.bake_warnings.add()
            item.kind, item.text = "WARNING", text
            self.report({'WARNING'}, text)  # each in the Info editor
        done = (f"Baked {len(result.garments)} garment(s), {frames} frames in {result.seconds:.2f} s: "
                f"{result.cache.name}")
        if warnings:
            self.report({'WARNING'}, f"{done}, with {len(warnings)} warning(s) (listed in the panel)")
        else:
            self.report({'INFO'}, done)
        return {'FINISHED'}


def summary_lines(report) -> list[tuple[str, str]]:
    """``(kind, text)`` lines for the panel from a ``cloth_usd.inspect_stage`` report."""
    stage = report.scene.stage
    span = ("no frame range" if stage.start_time_code is None or stage.end_time_code is None
            else f"frames {stage.start_time_code:g}-{stage.end_time_code:g}")
    lines = [("STAGE", f"{span} at {stage.frames_per_second:g} fps, {stage.up_axis}-up, "
                       f"{stage.meters_per_unit:g} m/unit")]
    lines += [("CHARACTER", f"{c.prim_path} ({c.gender})") for c in report.scene.characters]
    for g in report.scene.garments:
        tier = g.tier.value if g.tier else "from panel"
        state = "" if g.enabled else ", disabled"
        lines.append(("GARMENT", f"{g.prim_path}: {g.category.value}, {g.rest_points.shape[0]} "
                                 f"vertices, tier {tier}{state}"))
    lines += [("WARNING", warning) for warning in report.warnings]
    lines += [("PROBLEM", problem) for problem in report.problems]
    return lines


classes = (CLOTH_USD_OT_use_last_import, CLOTH_USD_OT_inspect, CLOTH_USD_OT_bake)
