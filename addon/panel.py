"""The sidebar panel: View3D > Sidebar (N) > Cloth USD."""

from bpy.types import Panel

from . import scene_io
from .props import ITEM_ICONS


class CLOTH_USD_PT_bake(Panel):
    bl_idname = "CLOTH_USD_PT_bake"
    bl_label = "Cloth USD"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Cloth USD"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.cloth_usd

        row = layout.row(align=True)
        row.prop(settings, "shot_path", text="")
        row.operator("cloth_usd.use_last_import", text="", icon='IMPORT')
        layout.operator("cloth_usd.inspect", icon='VIEWZOOM')
        if len(settings.inspected):
            box = layout.box()
            for item in settings.inspected:
                box.label(text=item.text, icon=ITEM_ICONS.get(item.kind, 'DOT'))

        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(settings, "tier")
        col.prop(settings, "frame_range")
        if settings.frame_range == "CUSTOM":
            sub = col.column(align=True)
            sub.prop(settings, "frame_start")
            sub.prop(settings, "frame_end")
        col.prop(settings, "output_path")
        paths = scene_io.output_paths(settings)
        if paths is not None and not settings.output_path:
            col.label(text=f"Writes {paths[0].name}", icon='FILE')
        col.prop(settings, "overwrite")
        layout.operator("cloth_usd.bake", icon='MOD_CLOTH')
        if len(settings.bake_warnings):
            box = layout.box()
            for item in settings.bake_warnings:
                box.label(text=item.text, icon=ITEM_ICONS.get(item.kind, 'DOT'))


classes = (CLOTH_USD_PT_bake,)
