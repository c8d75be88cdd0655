"""Input geometry: curves in axis space, arc length, fits, kinematics, patterns, G-code."""

from lookahead.geometry.base import Path
from lookahead.geometry.deviation import excursions, path_deviation, polyline_distance
from lookahead.geometry.files import load_points_file
from lookahead.geometry.fits import FITS, fit_path, make_streaming_fit
from lookahead.geometry.gcode import GcodeResult, read_gcode
from lookahead.geometry.kinematics import AxisIdentity, Kinematics, TwoDriveWinder
from lookahead.geometry.nurbs import BSplinePath, CompositePath, NurbsPath, discretize
from lookahead.geometry.piecewise import PiecewisePath
from lookahead.geometry.polyline import LinearFit
from lookahead.geometry.smoothing import SmoothFit
from lookahead.geometry.spline_path import SplinePath, chord_parameters, fit_points
from lookahead.geometry.streaming import StreamingFit
from lookahead.geometry.winding import (
    PRESETS,
    PresetInfo,
    helical_layer,
    hoop_layer,
    preset_points,
    winding_angle,
)

__all__ = [
    "FITS",
    "PRESETS",
    "AxisIdentity",
    "BSplinePath",
    "CompositePath",
    "GcodeResult",
    "Kinematics",
    "LinearFit",
    "NurbsPath",
    "Path",
    "PiecewisePath",
    "PresetInfo",
    "SmoothFit",
    "SplinePath",
    "StreamingFit",
    "TwoDriveWinder",
    "chord_parameters",
    "discretize",
    "excursions",
    "fit_path",
    "fit_points",
    "helical_layer",
    "hoop_layer",
    "load_points_file",
    "make_streaming_fit",
    "path_deviation",
    "polyline_distance",
    "preset_points",
    "read_gcode",
    "winding_angle",
]
