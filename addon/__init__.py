"""Cloth USD for Blender: bake learned garment point caches from a USD shot.

A thin front end on the ``cloth_usd`` Python API: pick a shot in View3D > Sidebar >
Cloth USD, Inspect it, Bake; the cache is imported into the "ClothUSD Cache"
collection and replaced on every bake. The manifest is ``blender_manifest.toml``.
"""

import bpy

from . import operators, panel, props

_classes = (*props.classes, *operators.classes, *panel.classes)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    props.attach()


def unregister():
    props.detach()
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
