"""A cache's provenance: the typed form, its customLayerData on disk, and chunks merged."""

from pxr import Sdf

from cloth_usd.core.frame_range import FrameRange
from cloth_usd.core.provenance import FileRecord, GarmentReport, Provenance, merge_chunks
from cloth_usd.core.scene import Tier
from cloth_usd.usd.provenance import from_custom_data, to_custom_data


def _prov(frames: FrameRange, n: int, moved: int, disp: float) -> Provenance:
    learned = GarmentReport("/Char/Shirt", Tier.DETAIL, vertices=100, frames=n, mean_body_distance_mm=12.3456,
                            bundle="tshirt-v3", fit=(0.25, -1.5, 2.0), postprocess_moved=moved,
                            max_displacement_mm=disp, max_offset_mm=disp / 2, fallback_coarse=1)
    skinned = GarmentReport("/Char/Skirt", Tier.SKINNING, vertices=50, frames=n, mean_body_distance_mm=4.0,
                            max_displacement_mm=disp)
    return Provenance(tool_version="0.0", source_layer="/shots/a.usda", frames=frames,
                      body_models={"neutral": FileRecord("body.npz", "ab" * 32)},
                      model_bundle=FileRecord("tshirt-v3", "cd" * 32), garments=(learned, skinned),
                      inputs_sha256="ef" * 32)


def test_provenance_is_the_documented_dictionary_and_reads_back():
    prov = _prov(FrameRange(1001, 1010), 10, 7, 31.25)
    data = to_custom_data(prov)["cloth_usd"]
    assert data["frame_range"] == "1001:1010:1"
    assert data["garments"]["/Char/Shirt"]["fit"] == "0.25 -1.5 2"
    assert data["garments"]["/Char/Shirt"]["mean_body_distance_mm"] == 12.346
    assert data["garments"]["/Char/Skirt"] == {"tier": "skinning", "vertices": 50, "frames": 10,
                                                "mean_body_distance_mm": 4.0, "max_displacement_mm": 31.25,
                                                "fit": "not computed (skinning tier)"}
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.customLayerData = to_custom_data(prov)
    back = from_custom_data(dict(layer.customLayerData))
    assert to_custom_data(back) == to_custom_data(prov)
    assert from_custom_data({}) is None and from_custom_data({"cloth_usd": {"frame_range": "x"}}) is None


def test_chunks_merge_into_the_whole_bake():
    a, b = _prov(FrameRange(1, 4), 4, 7, 20.0), _prov(FrameRange(5, 6), 2, 3, 30.0)
    whole = merge_chunks([a, b], inputs_sha256="00" * 32)
    shirt, skirt = whole.garments
    assert whole.frames == FrameRange(1, 6) and whole.inputs_sha256 == "00" * 32
    assert (shirt.frames, shirt.postprocess_moved, shirt.fallback_coarse) == (6, 10, 2)
    assert (shirt.max_displacement_mm, shirt.max_offset_mm, shirt.fit) == (30.0, 15.0, (0.25, -1.5, 2.0))
    assert (skirt.frames, skirt.tier) == (6, Tier.SKINNING)
