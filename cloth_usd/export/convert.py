"""``cloth-usd convert`` and ``cloth-usd preview``: a baked shot to glTF, VAT or a web page.

This module joins the USD reading (:mod:`cloth_usd.usd.animation`, imported when a
command runs) to the numpy writers of this package.
"""

from __future__ import annotations

import enum
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._version import __version__
from ..core.animation import MeshAnimation, SkinnedAnimation
from ..errors import ArgumentError
from .files import check_output_file
from .gltf import animated_garment_gltf, glb_bytes, write_gltf
from .pca import MorphBasis, fit_morph_basis, vertex_errors
from .vat import Engine, TextureFormat, VatResult, write_vat

__all__ = ["OutputFormat", "ConvertResult", "read_baked", "compress", "convert", "DEFAULT_MAX_ERROR_MM"]

_log = logging.getLogger(__name__)

#: ``--max-error`` default [mm].
DEFAULT_MAX_ERROR_MM = 1.0


class OutputFormat(str, enum.Enum):
    """What ``convert`` writes."""

    GLTF = "gltf"
    """A .glb or .gltf with morph-target animation."""
    VAT = "vat"
    """A folder of vertex-animation textures, mesh and JSON."""


@dataclass(frozen=True)
class ConvertResult:
    """What was written and how far it is from the cache."""

    files: tuple[Path, ...]
    frames: int
    vertices: int
    targets: int | None
    """K, the morph targets of a glTF (None for VAT)."""
    max_error_mm: float
    """Largest per-vertex distance to the cache over all frames [mm]."""
    mean_error_mm: float
    """Mean per-vertex distance to the cache [mm]."""


def read_baked(source: str | os.PathLike, *, garment: str | None = None, scene: str | os.PathLike | None = None,
               with_body: bool = False, body_model: str | os.PathLike | None = None
               ) -> tuple[MeshAnimation, SkinnedAnimation | None]:
    """A baked garment (and its body) from a shot or cache layer."""
    from ..usd.animation import open_baked_stage, read_body_animation, read_garment_animation

    stage = open_baked_stage(source, scene=scene)
    anim = read_garment_animation(stage, garment=garment)
    body = (read_body_animation(stage, anim.body_path, anim.time_codes, body_model=body_model)
            if with_body else None)
    return anim, body


def compress(anim: MeshAnimation, *, max_error_mm: float | None = None, targets: int | None = None) -> MorphBasis:
    """The garment's cache as a morph basis; ``max_error_mm`` defaults to 1 mm when
    ``targets`` is not given."""
    if targets is None and max_error_mm is None:
        max_error_mm = DEFAULT_MAX_ERROR_MM
    return fit_morph_basis(anim.points, max_error=None if max_error_mm is None else max_error_mm / 1000.0,
                           targets=targets)


def _extras(source, anim: MeshAnimation) -> dict:
    return {"cloth_usd": {"tool_version": __version__, "source": os.fspath(source), "garment": anim.name,
                          "time_codes": [float(anim.time_codes[0]), float(anim.time_codes[-1])],
                          "fps": anim.fps}}


def garment_glb(anim: MeshAnimation, basis: MorphBasis, body: SkinnedAnimation | None, source) -> bytes:
    """The .glb bytes of a compressed garment (and body)."""
    return glb_bytes(*animated_garment_gltf(anim, basis, body=body, extras=_extras(source, anim)))


def convert(source: str | os.PathLike, output: str | os.PathLike, *, fmt: OutputFormat | None = None,
            max_error_mm: float | None = None, targets: int | None = None, with_body: bool = False,
            garment: str | None = None, scene: str | os.PathLike | None = None,
            body_model: str | os.PathLike | None = None, engine: Engine = Engine.UNITY,
            vat_format: TextureFormat = TextureFormat.EXR, max_width: int = 8192, force: bool = False
            ) -> ConvertResult:
    """Convert a baked shot or cache to glTF (morph targets) or VAT.

    Args:
        fmt: glTF (the default) or VAT.
        max_error_mm, targets: how many morph targets (glTF only; see :func:`compress`).
        with_body: glTF only: add the body as a skinned mesh with the skeleton's animation.

    Raises:
        ArgumentError: options that do not go together; and what the readers and writers raise.
    """
    fmt = OutputFormat(fmt or OutputFormat.GLTF)
    if fmt is OutputFormat.GLTF:
        out = check_output_file(output, force=force, suffixes=(".glb", ".gltf"))
    else:
        if with_body or targets is not None or max_error_mm is not None:
            raise ArgumentError("--format vat stores every frame exactly; --with-body, --targets and --max-error "
                                "apply to glTF only")
        out = Path(output)
    anim, body = read_baked(source, garment=garment, scene=scene, with_body=with_body, body_model=body_model)
    if fmt is OutputFormat.VAT:
        result = write_vat(anim, out, engine=engine, fmt=vat_format, max_width=max_width, force=force,
                           extras=_extras(source, anim)["cloth_usd"])
        err = vat_errors(result, anim)
        return ConvertResult(files=result.files, frames=anim.points.shape[0], vertices=anim.points.shape[1],
                             targets=None, max_error_mm=float(err.max() * 1000), mean_error_mm=float(err.mean() * 1000))
    basis = compress(anim, max_error_mm=max_error_mm, targets=targets)
    write_gltf(out, *animated_garment_gltf(anim, basis, body=body, extras=_extras(source, anim)))
    err = vertex_errors(basis.reconstruct(), anim.points)
    return ConvertResult(files=(out,), frames=anim.points.shape[0], vertices=anim.points.shape[1],
                         targets=int(basis.targets.shape[0]), max_error_mm=float(err.max() * 1000),
                         mean_error_mm=float(err.mean() * 1000))


def vat_errors(result: VatResult, anim: MeshAnimation) -> np.ndarray:
    """(T, N) distance [m] between what the stock shader decodes from the written files
    and the cache."""
    from .gltf import read_accessor, read_glb
    from .vat import decode_vat, read_exr, read_png16

    files = dict(zip(("mesh", "position", "rotation", "data"), result.files))
    doc, blob = read_glb(files["mesh"].read_bytes())
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    rest = read_accessor(doc, blob, attrs["POSITION"]).astype(np.float64)
    uv1 = read_accessor(doc, blob, attrs["TEXCOORD_1"]).astype(np.float64)
    pos = files["position"]
    texture = read_exr(pos) if pos.suffix == ".exr" else read_png16(pos) / 65535.0
    decoded = np.stack([decode_vat(texture, uv1, rest, result.data, f)[0] for f in range(anim.points.shape[0])])
    return vertex_errors(decoded, anim.points)
