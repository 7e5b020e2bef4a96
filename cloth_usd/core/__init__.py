"""The numpy core: body model, association, skinning, mesh maths. No pxr, torch,
onnxruntime or bpy is imported here (a test holds this)."""

from .association import Association, associate
from .body import BodyModel, load_body_model, posed_vertices, shape_body
from .scene import Category, Character, Garment, Motion, Scene, StageInfo, Tier
from .skinning import SkinBinding, bind_garment, skin_garment

__all__ = [
    "Association", "associate", "BodyModel", "load_body_model", "posed_vertices", "shape_body",
    "Category", "Character", "Garment", "Motion", "Scene", "StageInfo", "Tier",
    "SkinBinding", "bind_garment", "skin_garment",
]
