"""The Blender add-on, run in real Blender (bpy as a module): panel, Inspect, Bake,
re-bake and failures. Run with ``bash scripts/test_addon.sh``."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="needs bpy (Blender as a Python module): bash scripts/test_addon.sh")

from tests.addon.helpers import MODULE, ROOT, make_tube_shot  # noqa: E402

pytestmark = pytest.mark.blender

SAMPLE = ROOT / "samples" / "walk_tshirt" / "scene.usda"
POSITION_TOL = 1e-5  # [m]: float32 points of a body-sized garment


# ---------------------------------------------------------------------- helpers


def bake_op(**settings) -> set[str]:
    """Set ``scene.cloth_usd`` fields and run the Bake operator."""
    for name, value in settings.items():
        setattr(bpy.context.scene.cloth_usd, name, value)
    return bpy.ops.cloth_usd.bake()


def cache_objects() -> list:
    collection = bpy.context.scene.cloth_usd.collection
    return sorted(collection.objects, key=lambda ob: ob.name) if collection else []


def garment_object(name: str):
    (ob,) = [ob for ob in cache_objects() if ob.type == "MESH" and ob.name == name]
    return ob


def evaluated_world_points(ob, frame: int) -> np.ndarray:
    """(N, 3) evaluated vertex positions of ``ob`` at ``frame`` in Blender world space [m]."""
    bpy.context.scene.frame_set(frame)
    evaluated = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    co = np.empty(3 * len(mesh.vertices), dtype=np.float64)
    mesh.vertices.foreach_get("co", co)
    matrix = np.array(evaluated.matrix_world)
    evaluated.to_mesh_clear()
    return co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]


def expected_world_points(cache: Path, scene: Path, prim_path: str, frame: float) -> np.ndarray:
    """(N, 3) where Blender must show a garment at ``frame``: the cache layer's time sample,
    through the prim's local-to-world in the scene, then Blender's USD import conversion
    (metersPerUnit to metres, and a Y-up stage turned +90 degrees about X into Z-up)."""
    from pxr import Sdf, Usd, UsdGeom

    layer = Sdf.Layer.OpenAsAnonymous(str(cache))  # not the registry's copy Blender holds
    points = np.array(layer.QueryTimeSample(Sdf.Path(prim_path).AppendProperty("points"), frame),
                      dtype=np.float64)
    stage = Usd.Stage.Open(str(scene))
    local_to_world = np.array(UsdGeom.XformCache(frame).GetLocalToWorldTransform(
        stage.GetPrimAtPath(prim_path)))  # row vectors
    world = points @ local_to_world[:3, :3] + local_to_world[3, :3]
    to_blender = UsdGeom.GetStageMetersPerUnit(stage) * np.eye(3)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y:
        to_blender = to_blender @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return world @ to_blender.T


def snapshot() -> dict:
    """Everything a failed bake must leave alone."""
    data = {name: sorted((i.name, i.users) for i in getattr(bpy.data, name))
            for name in ("objects", "meshes", "cache_files", "collections", "materials", "actions")}
    data["membership"] = sorted((ob.name, tuple(c.name for c in ob.users_collection))
                                for ob in bpy.data.objects)
    settings = bpy.context.scene.cloth_usd
    data["settings"] = (settings.baked_cache, [i.text for i in settings.inspected])
    data["frames"] = (bpy.context.scene.frame_start, bpy.context.scene.frame_end)
    return data


def folder_state(folder: Path) -> dict:
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.iterdir()}


@pytest.fixture(scope="module")
def shots(tmp_path_factory) -> dict[str, Path]:
    """The shots the tests bake; each sits alone in its folder (outputs go beside it)."""
    root = tmp_path_factory.mktemp("shots")
    out = {
        "tube_y_m": make_tube_shot(root / "tube_y_m" / "shot.usda"),
        "tube_z_cm": make_tube_shot(root / "tube_z_cm" / "shot.usda", up="Z", meters_per_unit=0.01),
        "nan": make_tube_shot(root / "nan" / "shot.usda", broken="nan"),
        "joint": make_tube_shot(root / "joint" / "shot.usda", broken="joint"),
    }
    if SAMPLE.exists():
        (root / "sample").mkdir()
        out["sample"] = Path(shutil.copy(SAMPLE, root / "sample" / "scene.usda"))
    return out


@pytest.fixture
def shot(shots, tmp_path):
    """A fresh copy of a named shot in its own folder (no outputs from other tests)."""
    def copy(name: str) -> Path:
        if name not in shots:
            pytest.skip(f"{name}: {SAMPLE} is not there yet")
        folder = tmp_path / name
        folder.mkdir()
        return Path(shutil.copy(shots[name], folder / shots[name].name))
    return copy


class FakeLayout:
    """Records what a panel draws and checks each call the way UILayout would."""

    def __init__(self, log: list):
        self.log = log

    def _child(self, *args, **kwargs):
        return FakeLayout(self.log)

    row = column = box = split = _child

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"no property {name} on {data}"
        self.log.append(("prop", name))

    def operator(self, idname, **kwargs):
        category, name = idname.split(".")
        getattr(getattr(bpy.ops, category), name).get_rna_type()  # KeyError if unregistered
        self._icon(kwargs.get("icon", "NONE"))
        self.log.append(("operator", idname))

    def label(self, *, text="", icon="NONE"):
        self._icon(icon)
        self.log.append(("label", text))

    @staticmethod
    def _icon(icon):
        icons = bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items.keys()
        assert icon in icons, f"unknown icon {icon}"


# ------------------------------------------------------------------------ tests


def test_registers_panel_operators_and_settings(blender):
    import addon_utils

    panel = bpy.types.CLOTH_USD_PT_bake
    assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == ("VIEW_3D", "UI", "Cloth USD")
    for name in ("use_last_import", "inspect", "bake"):
        op = getattr(bpy.types, f"CLOTH_USD_OT_{name}")
        assert "poll" in vars(op), f"{name} has no poll"
    settings = bpy.context.scene.cloth_usd
    assert (settings.shot_path, settings.tier, settings.frame_range) == ("", "skinning", "STAGE")
    tiers = settings.bl_rna.properties["tier"].enum_items
    assert [i.identifier for i in tiers] == ["skinning", "coarse", "detail"]
    assert not bpy.ops.cloth_usd.bake.poll() and not bpy.ops.cloth_usd.inspect.poll()

    addon_utils.disable(MODULE, default_set=True)
    assert not hasattr(bpy.types, "CLOTH_USD_PT_bake") and not hasattr(bpy.types.Scene, "cloth_usd")
    addon_utils.enable(MODULE, default_set=True)  # the fixture disables it again
    assert hasattr(bpy.types.Scene, "cloth_usd")


def test_cloth_usd_runs_on_blenders_own_usd_and_numpy():
    import numpy
    import pxr

    local = Path(bpy.utils.resource_path("LOCAL")).resolve()
    assert local in Path(pxr.__file__).resolve().parents, f"pxr from {pxr.__file__}, not Blender's"
    assert numpy.__version__.startswith("1.26.")  # what Blender 4.2 to 5.0 ship


def test_inspect_lists_characters_and_garments_and_the_panel_draws_them(blender, shot):
    path = shot("tube_z_cm")
    settings = bpy.context.scene.cloth_usd
    settings.shot_path = str(path)
    settings.frame_range = "CUSTOM"
    assert bpy.ops.cloth_usd.inspect() == {"FINISHED"}
    lines = [(i.kind, i.text) for i in settings.inspected]
    assert lines[:3] == [
        ("STAGE", "frames 1001-1024 at 24 fps, Z-up, 0.01 m/unit"),
        ("CHARACTER", "/Character/Skeleton (neutral)"),
        ("GARMENT", "/Character/Tube: tshirt, 192 vertices, tier from panel"),
    ]
    # the tube's ellipse cuts into the body's flanks: what the bake will warn about, listed first
    (warning,) = lines[3:]
    assert warning[0] == "WARNING" and warning[1].startswith("/Character/Tube: ") and "inside the body" in warning[1]
    assert (settings.frame_start, settings.frame_end) == (1001, 1024)

    log: list = []
    bpy.types.CLOTH_USD_PT_bake.draw(SimpleNamespace(layout=FakeLayout(log)), bpy.context)
    labels = [text for kind, text in log if kind == "label"]
    assert [text for _, text in lines] == labels[:4]
    assert "Writes shot_cloth.usdc" in labels
    assert [x for kind, x in log if kind == "operator"] == [
        "cloth_usd.use_last_import", "cloth_usd.inspect", "cloth_usd.bake"]
    props = [x for kind, x in log if kind == "prop"]
    assert props == ["shot_path", "tier", "frame_range", "frame_start", "frame_end", "output_path",
                     "overwrite"]

    settings.shot_path = str(path.with_name("other.usda"))  # a new shot forgets the old listing
    assert len(settings.inspected) == 0
    with pytest.raises(RuntimeError, match=r"other\.usda: no such file"):
        bpy.ops.cloth_usd.inspect()


def test_use_last_import_picks_the_stage_blender_imported(blender, shot):
    path = shot("tube_y_m")
    assert not bpy.ops.cloth_usd.use_last_import.poll()
    bpy.context.window_manager.operator_properties_last("wm.usd_import").filepath = str(path)
    assert bpy.ops.cloth_usd.use_last_import() == {"FINISHED"}
    assert bpy.context.scene.cloth_usd.shot_path == str(path)


@pytest.mark.parametrize("name, garment", [("tube_y_m", "Tube"), ("tube_z_cm", "Tube"),
                                           ("sample", "Tshirt")])
def test_bake_imports_an_animated_garment_that_matches_the_cache(blender, prefs, shot, name, garment):
    from cloth_usd.core.body import default_body_model_path

    path = shot(name)
    prefs.body_model = str(default_body_model_path())  # the preference reaches cloth_usd.bake
    assert bake_op(shot_path=str(path)) == {"FINISHED"}

    cache = path.with_name(f"{path.stem}_cloth.usdc")
    shot_layer = path.with_name(f"{path.stem}_cloth_shot.usda")
    assert cache.is_file() and shot_layer.is_file()
    assert bpy.context.scene.cloth_usd.collection.name == "ClothUSD Cache"
    ob = garment_object(garment)
    (modifier,) = [m for m in ob.modifiers if m.type == "MESH_SEQUENCE_CACHE"]
    assert Path(bpy.path.abspath(modifier.cache_file.filepath)) == shot_layer
    assert (bpy.context.scene.frame_start, bpy.context.scene.frame_end) == {
        "tube_y_m": (1001, 1024), "tube_z_cm": (1001, 1024), "sample": (1001, 1096)}[name]

    prim = f"/Character/{garment}"
    seen = {}
    for frame in (1001, 1012, bpy.context.scene.frame_end):
        seen[frame] = evaluated_world_points(ob, frame)
        np.testing.assert_allclose(seen[frame], expected_world_points(cache, path, prim, frame),
                                   rtol=0, atol=POSITION_TOL, err_msg=f"frame {frame}")
    moved = np.linalg.norm(seen[bpy.context.scene.frame_end] - seen[1001], axis=1)
    assert moved.max() > 0.05  # the garment walks along: the check above is not trivially true


def test_what_a_bake_warns_about_is_listed_in_the_panel(blender, shot, tmp_path):
    """The guard's replacements and inputs outside the trained range were logged only: an
    animator baking from the panel saw none of them."""
    tight = make_tube_shot(tmp_path / "tight" / "shot.usda", frames=4, ease=-0.03)  # the tube in the body
    settings = bpy.context.scene.cloth_usd
    assert bake_op(shot_path=str(tight)) == {"FINISHED"}
    (item,) = settings.bake_warnings
    assert item.kind == "WARNING" and "inside the body </Character/Skeleton> at rest" in item.text

    log: list = []
    bpy.types.CLOTH_USD_PT_bake.draw(SimpleNamespace(layout=FakeLayout(log)), bpy.context)
    assert [text for kind, text in log if kind == "label"][-1] == item.text  # below the Bake button

    clean = shot("sample")  # (the tubes' ellipses cut into the body's flanks: they warn too)
    assert bake_op(shot_path=str(clean), frame_range="CUSTOM", frame_start=1001, frame_end=1004) == {"FINISHED"}
    assert len(settings.bake_warnings) == 0  # a clean bake clears the list


def test_rebake_replaces_the_import_without_duplicates_or_orphans(blender, shot):
    path = shot("tube_y_m")
    settings = dict(shot_path=str(path), frame_range="CUSTOM", frame_start=1001, frame_end=1010)
    assert bake_op(**settings) == {"FINISHED"}
    first = [(ob.name, ob.type) for ob in cache_objects()]
    assert first == [("Character", "EMPTY"), ("Tube", "MESH")]

    # Same output files again (the add-on's own, so no Overwrite needed), longer range.
    assert bake_op(frame_range="STAGE") == {"FINISHED"}
    assert [(ob.name, ob.type) for ob in cache_objects()] == first
    assert sorted(ob.name for ob in bpy.data.objects) == ["Character", "Tube"]
    assert [(m.name, m.users) for m in bpy.data.meshes] == [("Tube", 1)]
    assert [c.users for c in bpy.data.cache_files] == [1]
    assert [c.name for c in bpy.data.collections] == ["ClothUSD Cache"]
    # Frame 1020 exists only in the second cache: Blender reads the new files, not stale layers.
    cache = path.with_name("shot_cloth.usdc")
    np.testing.assert_allclose(evaluated_world_points(garment_object("Tube"), 1020),
                               expected_world_points(cache, path, "/Character/Tube", 1020),
                               rtol=0, atol=POSITION_TOL)


def test_scene_frame_range_bakes_the_scene_frames(blender, shot):
    from pxr import Sdf

    path = shot("tube_z_cm")
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1005, 1008
    assert bake_op(shot_path=str(path), frame_range="SCENE") == {"FINISHED"}
    layer = Sdf.Layer.OpenAsAnonymous(str(path.with_name("shot_cloth.usdc")))
    assert layer.ListTimeSamplesForPath("/Character/Tube.points") == [1005.0, 1006.0, 1007.0, 1008.0]


@pytest.mark.parametrize("case, message", [
    ("nan", r"/Character/Tube.*points\[7\].*not finite"),
    ("joint", r"/Character/Skeleton.*left_elbow"),
    ("body_model", r"no_body\.npz: body model file not found"),
    ("tier", r"tier 'detail' needs a trained model bundle"),
    ("exists", r"shot_cloth\.usdc: already exists"),
])
def test_a_failed_bake_reports_one_line_and_leaves_the_scene_as_it_was(blender, prefs, shot, case, message):
    good = shot("tube_y_m")
    assert bake_op(shot_path=str(good)) == {"FINISHED"}  # something in the scene to keep
    target = good
    if case in ("nan", "joint"):
        target = shot(case)
        bpy.context.scene.cloth_usd.shot_path = str(target)
    elif case == "body_model":
        prefs.body_model = str(good.with_name("no_body.npz"))
    elif case == "tier":  # a Model Bundles folder without a T-shirt bundle
        (good.parent / "bundles").mkdir(exist_ok=True)
        prefs.models_dir = str(good.parent / "bundles")
        bpy.context.scene.cloth_usd.tier = "detail"
    elif case == "exists":
        target = shot("tube_z_cm")
        target.with_name("shot_cloth.usdc").write_bytes(b"somebody else's file")
        bpy.context.scene.cloth_usd.shot_path = str(target)
    before, files = snapshot(), folder_state(target.parent)

    with pytest.raises(RuntimeError, match=message) as error:
        bpy.ops.cloth_usd.bake()
    assert str(error.value).startswith("Error: ") and "\n" not in str(error.value).strip()
    assert snapshot() == before
    assert folder_state(target.parent) == files


def test_overwrite_replaces_files_the_add_on_did_not_write(blender, shot):
    path = shot("tube_z_cm")
    path.with_name("shot_cloth.usdc").write_bytes(b"somebody else's file")
    assert bake_op(shot_path=str(path), overwrite=True) == {"FINISHED"}
    assert garment_object("Tube").modifiers[0].type == "MESH_SEQUENCE_CACHE"


def test_a_blender_without_usd_import_refuses_before_writing(blender, shot, monkeypatch):
    # Some Linux distributions build Blender without USD (Debian's 4.3): Bake must say so
    # in one line and write nothing, rather than bake and then fail to import.
    import sys

    scene_io = next(m for name, m in sys.modules.items() if name.endswith(".scene_io") and hasattr(m, "import_shot"))
    monkeypatch.setattr(scene_io, "usd_import_missing", lambda: "this Blender was built without USD support")
    path = shot("tube_y_m")
    bpy.context.scene.cloth_usd.shot_path = str(path)
    before, files = snapshot(), folder_state(path.parent)
    with pytest.raises(RuntimeError, match="without USD support"):
        bpy.ops.cloth_usd.bake()
    assert snapshot() == before
    assert folder_state(path.parent) == files
