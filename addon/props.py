"""What the add-on stores: preferences, and per-scene bake settings (``scene.cloth_usd``)."""

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)
from bpy.types import AddonPreferences, PropertyGroup

from cloth_usd.core.scene import Tier

_TIER_HELP = {
    Tier.SKINNING: "Skin the garment with the body (no learned model; fastest)",
    Tier.COARSE: "Learned coarse drape (needs a model bundle)",
    Tier.DETAIL: "Learned coarse drape plus wrinkle detail (needs a model bundle)",
}
_TIERS = [(t.value, t.value.title(), _TIER_HELP[t]) for t in Tier]

_FRAME_RANGES = [
    ("STAGE", "Stage", "The shot's own startTimeCode..endTimeCode"),
    ("SCENE", "Scene", "This scene's frame start..end"),
    ("CUSTOM", "Custom", "The start and end frames below"),
]

#: Icons of the inspection lines, by kind.
ITEM_ICONS = {"STAGE": "SCENE_DATA", "CHARACTER": "ARMATURE_DATA", "GARMENT": "MOD_CLOTH",
              "PROBLEM": "ERROR", "WARNING": "ERROR"}


class ClothUsdPreferences(AddonPreferences):
    """Where the models live (Edit > Preferences > Add-ons > Cloth USD)."""

    bl_idname = __package__

    body_model: StringProperty(
        name="Body Model",
        description="SMPL-format body model: a .npz or .pkl file, or a folder of SMPL_<GENDER> "
                    "files. Empty uses the body model embedded in cloth_usd",
        subtype='FILE_PATH',
    )
    models_dir: StringProperty(
        name="Model Bundles",
        description="Folder of trained model bundles (or one bundle) for the coarse and detail "
                    "tiers. Empty uses the bundles shipped with cloth_usd",
        subtype='DIR_PATH',
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "body_model")
        layout.prop(self, "models_dir")


class ClothUsdInspectItem(PropertyGroup):
    """One line of what Inspect found in the shot, or of what the last bake warned about."""

    kind: StringProperty()  # a key of ITEM_ICONS
    text: StringProperty()


def _shot_changed(self, context):
    self.inspected.clear()


class ClothUsdSettings(PropertyGroup):
    """The Cloth USD panel's settings, one set per scene."""

    shot_path: StringProperty(
        name="Shot",
        description="USD stage with SMPL characters and garments to bake",
        subtype='FILE_PATH',
        update=_shot_changed,
    )
    tier: EnumProperty(
        name="Tier",
        description="Default tier for garments that author no cloth:tier of their own",
        items=_TIERS,
        default=Tier.SKINNING.value,
    )
    frame_range: EnumProperty(
        name="Frames",
        description="Which frames to bake",
        items=_FRAME_RANGES,
        default="STAGE",
    )
    frame_start: IntProperty(name="Start", description="First frame to bake", default=1)
    frame_end: IntProperty(name="End", description="Last frame to bake (inclusive)", default=250)
    output_path: StringProperty(
        name="Output",
        description="Cache layer to write (.usdc or .usda). Empty: <shot>_cloth.usdc beside the "
                    "shot. A shot layer <output>_shot.usda that sublayers [cache, shot] is "
                    "written beside it and imported",
        subtype='FILE_PATH',
    )
    overwrite: BoolProperty(
        name="Overwrite Files",
        description="Replace existing output files even if this scene did not write them",
        default=False,
    )
    inspected: CollectionProperty(type=ClothUsdInspectItem)
    bake_warnings: CollectionProperty(
        type=ClothUsdInspectItem,
        description="What the last bake warned about (frames the guard replaced, poses and garments "
                    "outside what the models were trained on), one line each",
    )
    baked_cache: StringProperty(
        description="Cache layer of this scene's last bake (its files may be replaced)",
        subtype='FILE_PATH',
    )
    collection: PointerProperty(
        type=bpy.types.Collection,
        description="Collection holding the imported cache objects, replaced on every bake",
    )


classes = (ClothUsdPreferences, ClothUsdInspectItem, ClothUsdSettings)


def attach() -> None:
    """Give every scene its ``cloth_usd`` settings."""
    bpy.types.Scene.cloth_usd = PointerProperty(type=ClothUsdSettings)


def detach() -> None:
    del bpy.types.Scene.cloth_usd
