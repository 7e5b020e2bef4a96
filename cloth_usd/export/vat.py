"""Vertex-animation textures in the layout of SideFX Labs VAT 3.0, "Soft-Body Deformation".

What the stock VAT 3.0 soft-body materials read (docs/game_export.md says where each
rule comes from and which material settings to use):

- a **position texture**, one texel per vertex per frame: vertex ``i`` of frame ``f`` at
  column ``i % W``, row ``f * R + i // W`` counted from the top, ``W = min(N, max_width)``
  texels wide, ``R = ceil(N / W)`` rows per frame. RGB is the vertex's offset from its
  place in the mesh (the first frame), in the engine's axes and units; raw in a
  half-float EXR, or ``(offset - bound_min) / (bound_max - bound_min)`` in a 16-bit PNG.
  A holds the normal, compressed ("Use Compressed Normals"): a sphere-map pair of 5-bit
  codes, ``(hi * 32 + lo) / 1024``.
- a **rotation texture** of the same layout (the materials' default, "Use Compressed
  Normals" off): per vertex and frame the quaternion (x, y, z, w) that turns (0, 1, 0)
  into the normal; raw in EXR, ``q * 0.5 + 0.5`` in PNG;
- the **mesh** (a .glb) at the first frame, its second UV channel (``TEXCOORD_1``, the
  engine's UV1) the centre of each vertex's texel in frame 0 (glTF's ``v`` runs down);
- a **JSON** of the material data: frame count, frames per second, the bounds (snapped
  out to a 10 cm grid, flags in their fractions as VAT 3.0 packs them), texture size.

Axes: glTF importers map glTF's (x, y, z) metres to Unity's (-x, y, z) metres and to
Unreal's (x, z, y) * 100 centimetres; the offsets in the textures are written in the
engine's frame the same way, so that they add to the imported mesh's vertices.

Shape letters: T frames, N vertices, W texture width, H texture height.
"""

from __future__ import annotations

import enum
import json
import logging
import os
import struct
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.animation import MeshAnimation
from ..errors import ArgumentError, ClothUsdError, OutputWriteError
from .files import check_output_dir, write_atomic
from .gltf import GltfBuilder, _ARRAY_BUFFER, _FLOAT, _vertex_normals, glb_bytes

_log = logging.getLogger(__name__)

__all__ = ["Engine", "TextureFormat", "VatLayout", "VatResult", "vat_layout", "encode_normals", "decode_normals",
           "normal_quaternions", "rotate_up",
           "write_vat", "decode_vat", "write_png16", "read_png16", "ENGINE_AXES"]


class Engine(str, enum.Enum):
    """Target engine: sets the axes and unit of the texture data."""

    UNITY = "unity"
    UNREAL = "unreal"


class TextureFormat(str, enum.Enum):
    """How positions are stored."""

    EXR = "exr"
    """Half-float OpenEXR, raw offsets (VAT 3.0's HDR mode)."""
    PNG16 = "png16"
    """16-bit PNG, offsets normalised to the bounds (VAT 3.0's LDR mode at 16 bits)."""


#: Engine -> (3x3 axis map from glTF/internal axes, scale from metres).
ENGINE_AXES: dict[Engine, tuple[np.ndarray, float]] = {
    Engine.UNITY: (np.diag([-1.0, 1.0, 1.0]), 1.0),
    Engine.UNREAL: (np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]), 100.0),
}


@dataclass(frozen=True)
class VatLayout:
    """Where each vertex's texels are."""

    width: int
    """W, texels per row."""
    rows_per_frame: int
    """R = ceil(N / W)."""
    frames: int
    """T."""

    @property
    def height(self) -> int:
        return self.frames * self.rows_per_frame

    def uv(self, n: int) -> np.ndarray:
        """(N, 2) float64 glTF UV (v down) of each vertex's texel centre in frame 0."""
        i = np.arange(n)
        return np.column_stack([(i % self.width + 0.5) / self.width, (i // self.width + 0.5) / self.height])


def vat_layout(n: int, t: int, *, max_width: int = 8192) -> VatLayout:
    """The texture layout for N vertices and T frames."""
    if max_width < 1:
        raise ArgumentError(f"--max-width {max_width}: must be at least 1")
    width = min(n, max_width)
    return VatLayout(width=width, rows_per_frame=-(-n // width), frames=t)


def encode_normals(normals: np.ndarray) -> np.ndarray:
    """(..., 3) unit normals (engine axes) -> (...,) int codes 0..1023 (hi * 32 + lo), the
    sphere map VAT's compressed normals decode as ``(-e.x r, 1 - s/2, e.y r)``."""
    n = np.asarray(normals, dtype=np.float64)
    s = np.clip(2.0 * (1.0 - n[..., 1]), 0.0, 4.0)
    horizontal = np.stack([-n[..., 0], n[..., 2]], axis=-1)
    length = np.linalg.norm(horizontal, axis=-1, keepdims=True)
    direction = np.where(length > 1e-12, horizontal / np.maximum(length, 1e-12), [1.0, 0.0])
    e = direction * np.sqrt(s)[..., None]
    q = (e + 2.0) / 4.0 * 31.5
    best, best_dot = None, None
    for dx in (0, 1):  # the neighbouring code that decodes closest to the normal
        for dy in (0, 1):
            code = (np.clip(np.floor(q[..., 0]) + dx, 0, 31) * 32 + np.clip(np.floor(q[..., 1]) + dy, 0, 31))
            dot = np.sum(decode_normals(code / 1024.0) * n, axis=-1)
            best = code if best is None else np.where(dot > best_dot, code, best)
            best_dot = dot if best_dot is None else np.maximum(dot, best_dot)
    return best.astype(np.int64)


def decode_normals(alpha: np.ndarray) -> np.ndarray:
    """The stock shader's decode of a compressed normal from position alpha (..., ) -> (..., 3)."""
    packed = np.asarray(alpha, dtype=np.float64) * 1024.0
    hi = np.floor(packed / 32.0)
    e = np.stack([hi / 31.5, (packed - hi * 32.0) / 31.5], axis=-1) * 4.0 - 2.0
    s = np.sum(e * e, axis=-1)
    r = np.sqrt(np.clip(1.0 - s / 4.0, 0.0, None))
    n = np.stack([-e[..., 0] * r, 1.0 - s / 2.0, e[..., 1] * r], axis=-1)
    n = np.clip(n, -1.0, 1.0)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)


def normal_quaternions(normals: np.ndarray) -> np.ndarray:
    """(..., 3) unit normals -> (..., 4) unit quaternions (x, y, z, w): the shortest turn
    from (0, 1, 0) to each normal (half a turn about x for a normal pointing down)."""
    n = np.asarray(normals, dtype=np.float64)
    q = np.stack([n[..., 2], np.zeros(n.shape[:-1]), -n[..., 0], 1.0 + n[..., 1]], axis=-1)
    length = np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(length > 1e-6, q / np.maximum(length, 1e-12), [1.0, 0.0, 0.0, 0.0])


def rotate_up(q: np.ndarray) -> np.ndarray:
    """The stock shader's normal from a rotation sample: (0, 1, 0) turned by ``q`` (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
    v = np.broadcast_to([0.0, 1.0, 0.0], q.shape[:-1] + (3,))
    t = np.cross(q[..., :3], v)
    return v + 2.0 * np.cross(q[..., :3], t + v * q[..., 3:4])


def _frame_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    return np.stack([_vertex_normals(p, triangles) for p in points])


def _snapped_bounds(lo: np.ndarray, hi: np.ndarray, scale: float, *, hdr: bool, rows: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Bounds as VAT 3.0 publishes them: snapped out to a 0.1 * scale grid, flags in the
    fraction (Max Z: +0.5 for HDR, + hundreds of rows * 0.01; Min Y: - (rows % 100) * 0.01;
    no power-of-two padding, so Min X and Min Z stay on the grid)."""
    g = 0.1 * scale
    lo_s = np.floor(lo / g + 1e-6) * g
    hi_s = np.ceil(hi / g - 1e-6) * g
    hi_s[2] += ((0.5 if hdr else 0.0) + (rows // 100) * 0.01) * g
    lo_s[1] -= (rows % 100) * 0.01 * g
    # The shader reads the texture's used width from ceil(Min Z) and height from frac(-Max X),
    # in float32: a hair below the grid line reads as "all of it", a hair above as "none".
    hi_s[0] -= 2e-5 * g  # 0.16 texel at 8192 wide; above float32 rounding up to 10 m
    lo_s[2] -= 2e-5 * g
    return lo_s, hi_s


@dataclass(frozen=True)
class VatResult:
    """What :func:`write_vat` wrote."""

    files: tuple[Path, ...]
    layout: VatLayout
    data: dict
    """The JSON written beside the textures."""


def write_png16(path: Path, rgba: np.ndarray) -> Path:
    """A (H, W, 4) uint16 array as a 16-bit RGBA PNG, written atomically."""
    rgba = np.ascontiguousarray(rgba, dtype=">u2")
    h, w = rgba.shape[:2]
    raw = b"".join(b"\0" + rgba[y].tobytes() for y in range(h))

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    return write_atomic(path, data)


def read_png16(path: Path) -> np.ndarray:
    """(H, W, 4) uint16 of a PNG written by :func:`write_png16` (filter 0 rows only)."""
    data = Path(path).read_bytes()
    pos, idat, size = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack_from(">I4s", data, pos)
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            size = struct.unpack_from(">II", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    w, h = size
    rows = np.frombuffer(zlib.decompress(idat), dtype=np.uint8).reshape(h, 1 + w * 8)
    return rows[:, 1:].copy().view(">u2").reshape(h, w, 4).astype(np.uint16)


def _openexr():
    """The OpenEXR module, or a ClothUsdError that says what to install."""
    try:
        import OpenEXR
    except ImportError:
        raise ClothUsdError("--vat-format exr needs the OpenEXR package: pip install 'cloth-usd[game]' "
                            "(or pass --vat-format png16)") from None
    return OpenEXR


def _write_exr(path: Path, rgba: np.ndarray) -> Path:
    OpenEXR = _openexr()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp.exr", dir=path.parent)
    os.close(fd)
    try:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        OpenEXR.File(header, {"RGBA": np.ascontiguousarray(rgba, dtype=np.float16)}).write(tmp)
        os.replace(tmp, path)
    except (OSError, RuntimeError) as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise OutputWriteError(f"{path}: could not be written ({exc}); nothing was written") from None
    return path


def read_exr(path: Path) -> np.ndarray:
    """(H, W, 4) float32 of an RGBA EXR."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        return np.asarray(f.channels()["RGBA"].pixels, dtype=np.float32)


def vat_file_names(stem: str, fmt: TextureFormat) -> dict[str, str]:
    ext = "exr" if fmt is TextureFormat.EXR else "png"
    return {"mesh": f"{stem}_mesh.glb", "position": f"{stem}_pos.{ext}", "rotation": f"{stem}_rot.{ext}",
            "data": f"{stem}_data.json"}


def write_vat(anim: MeshAnimation, out_dir: str | os.PathLike, *, engine: Engine = Engine.UNITY,
              fmt: TextureFormat = TextureFormat.EXR, max_width: int = 8192, force: bool = False,
              stem: str | None = None, extras: dict | None = None) -> VatResult:
    """Write a garment's cache as VAT 3.0 soft-body textures, mesh and JSON into ``out_dir``.

    Raises:
        ArgumentError, OutputExistsError: bad folder or files exist without ``force``.
        OutputWriteError: a write failed.
    """
    if fmt is TextureFormat.EXR:
        _openexr()  # before any folder is made
    stem = stem or (anim.name.rsplit("/", 1)[-1] or "garment")
    names = vat_file_names(stem, fmt)
    out = check_output_dir(out_dir, force=force, names=names.values())
    points = np.asarray(anim.points, dtype=np.float64)
    t, n = points.shape[:2]
    steps = np.diff(anim.times)
    if steps.size and np.ptp(steps) > 1e-6 * max(1.0, float(steps.max())):
        _log.warning("%s: frames are not evenly spaced in time (%g to %g s apart); VAT plays them evenly at "
                     "%g fps", anim.name, steps.min(), steps.max(), frame_rate(anim))
    layout = vat_layout(n, t, max_width=max_width)
    axes, scale = ENGINE_AXES[engine]
    offsets = np.einsum("ij,tnj->tni", axes, points - points[0]) * scale  # engine axes and units
    # A mirroring axis map flips the winding too (importers do), so normals map as vectors.
    normals = np.einsum("ij,tnj->tni", axes, _frame_normals(points, anim.triangles))
    lo, hi = offsets.reshape(-1, 3).min(axis=0), offsets.reshape(-1, 3).max(axis=0)
    hdr = fmt is TextureFormat.EXR
    bound_min, bound_max = _snapped_bounds(lo, hi, scale, hdr=hdr, rows=layout.rows_per_frame)
    codes = encode_normals(normals)

    def texture(rgb: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        tex = np.zeros((layout.height, layout.width, 4), dtype=np.float64)
        tex[..., 3] = 1.0
        i = np.arange(n)
        rows = (np.arange(t)[:, None] * layout.rows_per_frame + i // layout.width)  # (T, N)
        tex[rows, np.broadcast_to(i % layout.width, rows.shape)] = np.concatenate([rgb, alpha[..., None]], axis=-1)
        return tex

    if hdr:
        position = texture(offsets, codes / 1024.0)
        _write_exr(out / names["position"], position)
        quats = normal_quaternions(normals)
        _write_exr(out / names["rotation"], texture(quats[..., :3], quats[..., 3]))
    else:
        unit = (offsets - bound_min) / (bound_max - bound_min)
        position = texture(unit, np.zeros((t, n)))
        rgba = np.clip(np.rint(position * 65535.0), 0, 65535).astype(np.uint16)
        alpha = np.ceil(codes / 1024.0 * 65535.0)  # never below the code: the shader floors it
        rows = np.arange(t)[:, None] * layout.rows_per_frame + np.arange(n) // layout.width
        rgba[rows, np.broadcast_to(np.arange(n) % layout.width, rows.shape), 3] = alpha
        write_png16(out / names["position"], rgba)
        quats = normal_quaternions(normals) * 0.5 + 0.5
        rotation = texture(quats[..., :3], quats[..., 3])
        write_png16(out / names["rotation"], np.clip(np.rint(rotation * 65535.0), 0, 65535).astype(np.uint16))
    write_atomic(out / names["mesh"], glb_bytes(*_vat_mesh(anim, points[0], layout)))
    data = _vat_data(anim, layout, engine, fmt, bound_min, bound_max, lo, hi, names, extras)
    write_atomic(out / names["data"], (json.dumps(data, indent=2) + "\n").encode())
    return VatResult(files=tuple(out / v for v in names.values()), layout=layout, data=data)


def _vat_mesh(anim: MeshAnimation, rest: np.ndarray, layout: VatLayout) -> tuple[dict, bytes]:
    """The mesh at the first frame with TEXCOORD_1 = the VAT UV (TEXCOORD_0: the garment's
    UVs, or the VAT UV again when it has none, as glTF wants UV sets numbered from 0)."""
    b = GltfBuilder()
    n = rest.shape[0]
    vat_uv = layout.uv(n)
    uv0 = np.column_stack([anim.uvs[:, 0], 1.0 - anim.uvs[:, 1]]) if anim.uvs is not None else vat_uv
    attributes = {"POSITION": b.accessor(rest, _FLOAT, target=_ARRAY_BUFFER, bounds=True),
                  "NORMAL": b.accessor(_vertex_normals(rest, anim.triangles), _FLOAT, target=_ARRAY_BUFFER),
                  "TEXCOORD_0": b.accessor(uv0, _FLOAT, target=_ARRAY_BUFFER),
                  "TEXCOORD_1": b.accessor(vat_uv, _FLOAT, target=_ARRAY_BUFFER)}
    material = b.material("garment_vat", (0.25, 0.45, 0.75), double_sided=True)
    name = anim.name.rsplit("/", 1)[-1] or "garment"
    b.doc["meshes"].append({"name": name, "primitives": [
        {"attributes": attributes, "indices": b.indices(anim.triangles, n), "material": material}]})
    b.node({"name": name, "mesh": 0, "extras": {"usd_prim": anim.name}})
    return b.finish()


def frame_rate(anim: MeshAnimation) -> float:
    """Frames per second of the samples (a bake that steps over time codes has fewer)."""
    t = anim.times.shape[0]
    return float((t - 1) / anim.times[-1]) if t > 1 and anim.times[-1] > 0 else anim.fps


def _vat_data(anim, layout, engine, fmt, bound_min, bound_max, lo, hi, names, extras) -> dict:
    unit = "m" if engine is Engine.UNITY else "cm"
    fps = frame_rate(anim)
    material = {"Frame Count": layout.frames, "Houdini FPS": fps,
                **{f"Bound Max {a}": float(v) for a, v in zip("XYZ", bound_max)},
                **{f"Bound Min {a}": float(v) for a, v in zip("XYZ", bound_min)},
                "Positions Require Two Textures": False, "Use Compressed Normals": True,
                "Interpolate": True, "Auto Playback": True}
    unity = {"_frameCount": layout.frames, "_houdiniFPS": fps,
             **{f"_boundMax{a}": float(v) for a, v in zip("XYZ", bound_max)},
             **{f"_boundMin{a}": float(v) for a, v in zip("XYZ", bound_min)},
             "_B_autoPlayback": 1, "_B_interpolate": 1, "_B_UNLOAD_ROT_TEX": 1, "_B_LOAD_POS_TWO_TEX": 0}
    return {
        "format": "SideFX Labs VAT 3.0, Soft-Body Deformation (constant topology)",
        "engine": engine.value, "unit": unit, "texture_format": fmt.value,
        "frames": layout.frames, "fps": fps, "vertices": int(anim.points.shape[1]),
        "time_codes": [float(anim.time_codes[0]), float(anim.time_codes[-1])],
        "texture": {"width": layout.width, "height": layout.height, "rows_per_frame": layout.rows_per_frame,
                    "position_rgb": "offset from the mesh (first frame)" + (
                        " [raw]" if fmt is TextureFormat.EXR else " (x - Bound Min) / (Bound Max - Bound Min)"),
                    "position_alpha": "compressed normal (hi * 32 + lo) / 1024",
                    "rotation_rgba": "quaternion (x, y, z, w) turning (0, 1, 0) to the normal" + (
                        " [raw]" if fmt is TextureFormat.EXR else ", q * 0.5 + 0.5"), "uv_channel": 1},
        "offset_bounds": {"min": [float(v) for v in lo], "max": [float(v) for v in hi], "unit": unit},
        "material": material, "unity_material": unity, "files": names, **({"source": extras} if extras else {}),
    }


def decode_vat(texture: np.ndarray, uv1: np.ndarray, rest: np.ndarray, data: dict, frame: int, *,
               rotation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the stock soft-body shader computes for one frame, back in glTF axes and metres:
    ``(positions (N, 3), normals (N, 3))``. A reference for tests and measurements.

    Args:
        texture: (H, W, 4) float position texture as sampled (PNG values / 65535).
        uv1: (N, 2) glTF UV1 of the mesh; rest: (N, 3) mesh positions [m].
        rotation: the rotation texture, as sampled; normals come from it when given
            ("Use Compressed Normals" off), else from the position texture's alpha.
    """
    engine = Engine(data["engine"])
    axes, scale = ENGINE_AXES[engine]
    m = data["material"]
    frames = m["Frame Count"]
    f32 = np.float32  # material parameters are float32 in the engines
    bmin = np.array([m[f"Bound Min {a}"] for a in "XYZ"], dtype=f32) * f32(10.0 / scale)
    bmax = np.array([m[f"Bound Max {a}"] for a in "XYZ"], dtype=f32) * f32(10.0 / scale)
    raw = (bmax[2] - np.floor(bmax[2])) >= 0.5
    u_scale = float(f32(1.0) - (np.ceil(bmin[2]) - bmin[2]))
    v_scale = float(f32(1.0) - ((-bmax[0]) - np.floor(-bmax[0])))
    h, w = texture.shape[:2]
    v_unity = 1.0 - uv1[:, 1]  # the engine's UV (v up) after a glTF import
    base_v = (1.0 - v_unity) * v_scale
    v = 1.0 - (base_v + frame / frames * v_scale)
    rows = np.clip(np.floor((1.0 - v) * h), 0, h - 1).astype(np.int64)
    cols = np.clip(np.floor(uv1[:, 0] * u_scale * w), 0, w - 1).astype(np.int64)
    sample = texture[rows, cols].astype(np.float64)
    lo = np.array([m[f"Bound Min {a}"] for a in "XYZ"])
    hi = np.array([m[f"Bound Max {a}"] for a in "XYZ"])
    offset = sample[:, :3] if raw else sample[:, :3] * (hi - lo) + lo
    if rotation is None:
        normal = decode_normals(sample[:, 3])
    else:
        q = rotation[rows, cols].astype(np.float64)
        normal = rotate_up(q if raw else (q - 0.5) * 2.0)
        normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    back = np.linalg.inv(axes)
    return rest + (offset / scale) @ back.T, normal @ back.T
