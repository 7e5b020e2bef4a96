"""glTF 2.0 writing (numpy, json and struct only): a garment as morph-target animation,
a body as a skinned mesh, and the VAT mesh with its texture-addressing UV channel.

The garment's cache is stored as :class:`~cloth_usd.export.pca.MorphBasis`: the mean
shape as the mesh, K morph targets, and a ``weights`` animation channel sampled at
every frame with LINEAR interpolation. glTF's frame is cloth_usd's internal one (metres,
Y-up), so positions are written as they are read. USD's texture ``v`` runs up, glTF's
down: ``v_gltf = 1 - v_usd``.

Shape letters: T frames, N vertices, M triangles, K morph targets, V body vertices,
J joints.
"""

from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._version import __version__
from ..core.animation import MeshAnimation, SkinnedAnimation
from .files import write_atomic
from .pca import MorphBasis

__all__ = ["GltfBuilder", "GarmentLook", "add_garment", "add_skinned_body", "animated_garment_gltf", "glb_bytes",
           "gltf_bytes", "write_gltf", "read_glb", "read_accessor"]

_FLOAT, _UINT8, _UINT16, _UINT32 = 5126, 5121, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_DTYPES = {_FLOAT: np.float32, _UINT8: np.uint8, _UINT16: np.uint16, _UINT32: np.uint32}


@dataclass(frozen=True)
class GarmentLook:
    """How the garment and body are drawn (a plain PBR material each)."""

    garment_rgb: tuple[float, float, float] = (0.25, 0.45, 0.75)
    body_rgb: tuple[float, float, float] = (0.85, 0.68, 0.58)


@dataclass
class GltfBuilder:
    """Accumulates one binary buffer and the glTF JSON that describes it."""

    blob: bytearray = field(default_factory=bytearray)
    doc: dict = field(default_factory=lambda: {
        "asset": {"version": "2.0", "generator": f"cloth-usd {__version__}"},
        "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [], "materials": [],
        "accessors": [], "bufferViews": [], "buffers": []})

    def view(self, data: bytes, *, target: int | None = None, stride: int | None = None) -> int:
        """Append bytes (4-byte aligned) as a bufferView; returns its index."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        entry = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            entry["target"] = target
        if stride is not None:
            entry["byteStride"] = stride
        self.blob.extend(data)
        self.doc["bufferViews"].append(entry)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, component: int, *, target: int | None = None,
                 bounds: bool = False, normalized: bool = False) -> int:
        """Append an array (rows = elements) as an accessor; returns its index."""
        array = np.ascontiguousarray(array, dtype=_DTYPES[component])
        width = 1 if array.ndim == 1 else int(np.prod(array.shape[1:]))
        flat = array.reshape(array.shape[0], width)
        entry = {"bufferView": self.view(flat.tobytes(), target=target), "componentType": component,
                 "count": int(array.shape[0]), "type": _TYPES[width]}
        if normalized:
            entry["normalized"] = True
        if bounds:
            entry["min"] = [v.item() for v in flat.min(axis=0)]
            entry["max"] = [v.item() for v in flat.max(axis=0)]
        self.doc["accessors"].append(entry)
        return len(self.doc["accessors"]) - 1

    def material(self, name: str, rgb: tuple[float, float, float], *, double_sided: bool) -> int:
        self.doc["materials"].append({"name": name, "doubleSided": double_sided, "pbrMetallicRoughness": {
            "baseColorFactor": [*rgb, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}})
        return len(self.doc["materials"]) - 1

    def node(self, node: dict, *, root: bool = True) -> int:
        self.doc["nodes"].append(node)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def indices(self, triangles: np.ndarray, vertices: int) -> int:
        component = _UINT16 if vertices < 65535 else _UINT32
        return self.accessor(np.asarray(triangles).reshape(-1), component, target=_ELEMENT_ARRAY_BUFFER)

    def animation(self, name: str, samplers: list[dict], channels: list[dict]) -> None:
        self.doc.setdefault("animations", []).append({"name": name, "samplers": samplers, "channels": channels})

    def finish(self) -> tuple[dict, bytes]:
        """The JSON document (without the buffer's uri) and the padded binary buffer."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        doc = json.loads(json.dumps(self.doc))
        doc["buffers"] = [{"byteLength": len(self.blob)}]
        for key in ("materials", "animations"):
            if not doc.get(key):
                doc.pop(key, None)
        return doc, bytes(self.blob)


def add_garment(builder: GltfBuilder, anim: MeshAnimation, basis: MorphBasis, *, material: int,
                times: np.ndarray) -> int:
    """The garment mesh (mean shape + morph targets) and its weights channel; returns its node."""
    n = basis.base.shape[0]
    attributes = {"POSITION": builder.accessor(basis.base, _FLOAT, target=_ARRAY_BUFFER, bounds=True)}
    if anim.uvs is not None:
        uv = np.column_stack([anim.uvs[:, 0], 1.0 - anim.uvs[:, 1]])
        attributes["TEXCOORD_0"] = builder.accessor(uv, _FLOAT, target=_ARRAY_BUFFER)
    primitive = {"attributes": attributes, "indices": builder.indices(anim.triangles, n), "material": material}
    k = basis.targets.shape[0]
    mesh = {"name": anim.name.rsplit("/", 1)[-1] or "garment", "primitives": [primitive]}
    if k:
        primitive["targets"] = [{"POSITION": builder.accessor(basis.targets[i], _FLOAT, target=_ARRAY_BUFFER,
                                                              bounds=True)} for i in range(k)]
        mesh["weights"] = [float(w) for w in basis.weights[0]]
        mesh["extras"] = {"targetNames": [f"pc{i:03d}" for i in range(k)]}
    builder.doc["meshes"].append(mesh)
    node = builder.node({"name": mesh["name"], "mesh": len(builder.doc["meshes"]) - 1,
                         "extras": {"usd_prim": anim.name}})
    if k and times.size > 1:
        time_acc = builder.accessor(times.astype(np.float32), _FLOAT, bounds=True)
        weights_acc = builder.accessor(basis.weights.reshape(-1), _FLOAT)
        builder.animation("cloth", [{"input": time_acc, "output": weights_acc, "interpolation": "LINEAR"}],
                          [{"sampler": 0, "target": {"node": node, "path": "weights"}}])
    return node


def _top4(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V, 4) joint indices and (V, 4) weights: the 4 largest, renormalised (glTF's JOINTS_0).

    An entry of weight 0 names joint 0, as the validator wants (and fewer than 4 joints
    are padded so).
    """
    v, j = weights.shape
    if j < 4:
        weights = np.concatenate([weights, np.zeros((v, 4 - j))], axis=1)
    order = np.argsort(-weights, axis=1, kind="stable")[:, :4]
    w = np.take_along_axis(weights, order, axis=1)
    w = np.where(w > 1e-6, w, 0.0)
    w = (w / w.sum(axis=1, keepdims=True)).astype(np.float32)
    w[:, 0] += np.float32(1.0) - w.sum(axis=1, dtype=np.float32)  # exact float32 sums
    order = np.where(w > 0, order, 0)
    return order.astype(np.uint16 if j > 255 else np.uint8), w


def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    tri = vertices[triangles]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(vertices)
    for c in range(3):
        np.add.at(normals, triangles[:, c], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 0, normals / np.maximum(length, 1e-20), [0.0, 1.0, 0.0])


def add_skinned_body(builder: GltfBuilder, body: SkinnedAnimation, *, material: int) -> int:
    """The body as a skinned mesh, its joint nodes and their rotation / root translation
    channels (added to the first animation, or a new one); returns the mesh node."""
    j = body.rest_joints.shape[0]
    first = len(builder.doc["nodes"])
    for i in range(j):
        p = int(body.parents[i])
        offset = body.rest_joints[i] - (body.rest_joints[p] if p >= 0 else 0.0)
        if p < 0:
            offset = body.root_translation[0]
        builder.node({"name": body.joint_names[i], "translation": [float(v) for v in offset],
                      "rotation": [float(v) for v in body.rotations[0, i]]}, root=p < 0)
    for i in range(j):
        children = [first + c for c in range(j) if int(body.parents[c]) == i]
        if children:
            builder.doc["nodes"][first + i]["children"] = children
    inverse_bind = np.tile(np.eye(4, dtype=np.float32), (j, 1, 1))
    inverse_bind[:, :3, 3] = -body.rest_joints
    skin = {"joints": list(range(first, first + j)), "skeleton": first,
            "inverseBindMatrices": builder.accessor(inverse_bind.transpose(0, 2, 1).reshape(j, 16), _FLOAT)}
    builder.doc.setdefault("skins", []).append(skin)
    joints, weights = _top4(body.weights)
    v = body.rest_vertices.shape[0]
    attributes = {
        "POSITION": builder.accessor(body.rest_vertices, _FLOAT, target=_ARRAY_BUFFER, bounds=True),
        "NORMAL": builder.accessor(_vertex_normals(body.rest_vertices, body.triangles), _FLOAT,
                                   target=_ARRAY_BUFFER),
        "JOINTS_0": builder.accessor(joints, _UINT16 if joints.dtype == np.uint16 else _UINT8, target=_ARRAY_BUFFER),
        "WEIGHTS_0": builder.accessor(weights, _FLOAT, target=_ARRAY_BUFFER)}
    builder.doc["meshes"].append({"name": "body", "primitives": [
        {"attributes": attributes, "indices": builder.indices(body.triangles, v), "material": material}]})
    node = builder.node({"name": "body", "mesh": len(builder.doc["meshes"]) - 1,
                         "skin": len(builder.doc["skins"]) - 1, "extras": {"usd_prim": body.name}})
    if body.times.size > 1:
        anims = builder.doc.setdefault("animations", [])
        if not anims:
            builder.animation("cloth", [], [])
        anim = anims[0]
        time_acc = builder.accessor(body.times.astype(np.float32), _FLOAT, bounds=True)

        def channel(node_index: int, path: str, values: np.ndarray) -> None:
            anim["samplers"].append({"input": time_acc, "output": builder.accessor(values, _FLOAT),
                                     "interpolation": "LINEAR"})
            anim["channels"].append({"sampler": len(anim["samplers"]) - 1,
                                     "target": {"node": node_index, "path": path}})

        rotations = _continuous(body.rotations)
        for i in range(j):
            channel(first + i, "rotation", rotations[:, i])
        channel(first, "translation", body.root_translation)
    return node


def _continuous(q: np.ndarray) -> np.ndarray:
    """(T, J, 4) quaternions with signs flipped so that consecutive frames agree (shortest
    path under LINEAR interpolation)."""
    q = q.copy()
    for t in range(1, q.shape[0]):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t, flip] *= -1
    return q


def animated_garment_gltf(anim: MeshAnimation, basis: MorphBasis, *, body: SkinnedAnimation | None = None,
                          look: GarmentLook = GarmentLook(), extras: dict | None = None) -> tuple[dict, bytes]:
    """The glTF document and buffer of a garment's compressed cache (and its body)."""
    b = GltfBuilder()
    add_garment(b, anim, basis, material=b.material("garment", look.garment_rgb, double_sided=True),
                times=anim.times)
    if body is not None:
        add_skinned_body(b, body, material=b.material("body", look.body_rgb, double_sided=False))
    if extras:
        b.doc["asset"]["extras"] = extras
    return b.finish()


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    """A binary glTF (.glb): header, JSON chunk (space padded), BIN chunk (zero padded)."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(text), b"JSON") + text
            + struct.pack("<I4s", len(blob), b"BIN\0") + blob)


def gltf_bytes(doc: dict, blob: bytes) -> bytes:
    """A .gltf JSON file with the buffer embedded as a base64 data URI (one file)."""
    doc = dict(doc)
    doc["buffers"] = [{"byteLength": len(blob),
                       "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}]
    return json.dumps(doc, separators=(",", ":")).encode()


def write_gltf(path: Path, doc: dict, blob: bytes) -> Path:
    """Write ``.glb`` or ``.gltf`` (by suffix), atomically."""
    data = glb_bytes(doc, blob) if path.suffix.lower() == ".glb" else gltf_bytes(doc, blob)
    return write_atomic(path, data)


def read_glb(data: bytes) -> tuple[dict, bytes]:
    """The JSON and BIN chunk of a .glb (for tests and measurements)."""
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2:
        raise ValueError("not a glTF 2.0 binary")
    length, _ = struct.unpack_from("<I4s", data, 12)
    doc = json.loads(data[20:20 + length])
    blob_length, _ = struct.unpack_from("<I4s", data, 20 + length)
    return doc, data[28 + length:28 + length + blob_length]


def read_accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    """An accessor of a (tightly packed) glTF buffer as a numpy array, rows = elements."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    width = {v: k for k, v in _TYPES.items()}[acc["type"]]
    dtype = _DTYPES[acc["componentType"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    arr = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=start)
    return arr.reshape(acc["count"], width) if width > 1 else arr
