"""Game-engine exports of a baked garment: glTF 2.0 with compressed morph-target animation,
SideFX Labs VAT 3.0 soft-body textures, and a self-contained browser preview.

The writers are numpy, json and struct only; reading the shot goes through
:mod:`cloth_usd.usd.animation` (pxr), imported only when a conversion runs.
"""

from .convert import ConvertResult, OutputFormat, convert, read_baked
from .pca import MorphBasis, fit_morph_basis
from .vat import Engine, TextureFormat, write_vat

__all__ = ["ConvertResult", "OutputFormat", "convert", "read_baked", "MorphBasis", "fit_morph_basis", "Engine",
           "TextureFormat", "write_vat"]
