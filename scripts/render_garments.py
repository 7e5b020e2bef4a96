"""A close-up Cycles render of made garments (`cloth-usd garment make`) on their bodies,
side by side, each textured with a checker through its UVs (primvars:st), so the pattern's
grain and the seams show.

    .venv-blender/bin/python scripts/render_garments.py OUT.png LABEL=GARMENT.usda [...]
        # after bash scripts/test_addon.sh (which creates .venv-blender)

The body is computed by cloth_usd from the garment file's skeleton betas; Blender's own USD
(pxr) reads the file. Cycles renders on the CPU.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SITE = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib" / "python3.11" / "site-packages"
sys.path.append(str(SITE))  # Blender's own pxr
sys.path.insert(0, str(ROOT))

from render_tiers import save_row, studio  # noqa: E402  (the same studio as the tier close-ups)


def _material(name: str, rgb, checker: bool) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.85
    if not checker:
        bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
        return mat
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = "st"
    tex = nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = 40.0
    tex.inputs["Color1"].default_value = (*rgb, 1.0)
    tex.inputs["Color2"].default_value = tuple(min(1.0, c * 1.6 + 0.15) for c in rgb) + (1.0,)
    links.new(uv.outputs["UV"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def _mesh(name: str, verts: np.ndarray, faces: np.ndarray, rgb, st=None, st_indices=None) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], faces.tolist())
    if st is not None:
        layer = mesh.uv_layers.new(name="st")
        layer.data.foreach_set("uv", st[np.asarray(st_indices).ravel()].astype(np.float32).ravel())
    mesh.shade_smooth()
    ob = bpy.data.objects.new(name, mesh)
    ob.rotation_euler = (np.pi / 2, 0.0, 0.0)  # Y-up metres -> Blender's Z-up
    mesh.materials.append(_material(name, rgb, st is not None))
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _read(path: str):
    from pxr import Usd, UsdGeom

    from cloth_usd.core.body import load_body_model, shape_body
    from cloth_usd.usd.read import open_stage, read_scene

    scene = read_scene(open_stage(path))
    garment, char = scene.garments[0], scene.characters[0]
    stage = Usd.Stage.Open(path)
    primvar = UsdGeom.PrimvarsAPI(UsdGeom.Mesh(stage.GetPrimAtPath(garment.prim_path))).GetPrimvar("st")
    st = np.array(primvar.Get(), dtype=np.float64)
    indices = np.array(primvar.GetIndices(), dtype=np.int64).reshape(-1, 3)
    body = load_body_model()
    verts, _ = shape_body(body, char.betas)
    offset = char.rest_root_position - np.asarray(shape_body(body, char.betas)[1])[0]
    return np.asarray(verts) + offset, body.faces, garment.rest_points, garment.triangles, st, indices


def main(argv: list[str]) -> None:
    if len(argv) < 2:
        raise SystemExit(__doc__)
    out = Path(argv[0])
    panels = [a.split("=", 1) for a in argv[1:]]
    colours = [(0.12, 0.28, 0.62), (0.55, 0.12, 0.16), (0.15, 0.38, 0.22), (0.35, 0.3, 0.12)]
    scene, camera, target = studio(samples=24, width=360, height=560, lens=50)
    tmp = Path(tempfile.mkdtemp(prefix="cloth_usd_garments_"))
    images = []
    for k, (label, path) in enumerate(panels):
        body_v, body_f, pts, tris, st, st_idx = _read(path)
        body = _mesh("Body", body_v, body_f, (0.8, 0.62, 0.52))
        cloth = _mesh(label, pts, tris, colours[k % len(colours)], st, st_idx)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        centre_y = 0.5 * (lo[1] + hi[1])
        centre = np.array([0.5 * (lo[0] + hi[0]), -0.5 * (lo[2] + hi[2]), centre_y])
        target.location = centre
        reach = max(hi[1] - lo[1], 0.6 * (hi[0] - lo[0]))
        camera.location = centre + np.array([0.45, -1.4, 0.25]) * (reach / 0.75 + 0.4)
        scene.render.filepath = str(tmp / f"panel_{k}.png")
        bpy.ops.render.render(write_still=True)
        images.append(bpy.data.images.load(scene.render.filepath))
        bpy.data.objects.remove(cloth)
        bpy.data.objects.remove(body)
        print(f"{label}: rendered", flush=True)
    save_row(scene, images, out)
    print(f"wrote {out} ({', '.join(label for label, _ in panels)})")


if __name__ == "__main__":
    main(sys.argv[1:])
