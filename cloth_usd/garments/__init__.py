"""Garments the way garments are made: parametric sewing patterns (T-shirt, dress,
trousers) drafted from a body's measurements, triangulated flat, sewn round the T-posed
body and draped with Newton (:func:`make_garment`), UVs from the panels; and garments
made elsewhere (OBJ, glTF, USD; MakeHuman's ``.mhclo`` bindings) fitted to the body
(:func:`fit_garment`).

Importing this package is cheap: numpy and scipy only; Newton is imported when a garment
is sewn.
"""

from .designs import DESIGNS, PRESETS, DressDesign, TrousersDesign, TShirtDesign, design_from_params, draft
from .fit import FitConfig, FittedGarment, fit_garment
from .make import MadeGarment, make_garment, pack_uvs, pattern_spacing
from .measure import BodyMeasurements, measure_body
from .mhclo import Mhclo, read_mhclo
from .pattern import Panel, Pattern, PatternError, PatternMesh, Seam, triangulate_pattern
from .source import GarmentFitError, SourceMesh, read_garment_mesh

__all__ = ["DESIGNS", "PRESETS", "TShirtDesign", "DressDesign", "TrousersDesign", "design_from_params", "draft",
           "MadeGarment", "make_garment", "pack_uvs", "pattern_spacing", "BodyMeasurements", "measure_body",
           "Panel", "Pattern", "PatternError", "PatternMesh", "Seam", "triangulate_pattern",
           "FitConfig", "FittedGarment", "fit_garment", "Mhclo", "read_mhclo", "GarmentFitError", "SourceMesh",
           "read_garment_mesh"]
