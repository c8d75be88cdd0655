"""Input geometry: curves in axis space, arc length, fits, kinematics, patterns, G-code."""

from lookahead.geometry.base import Path
from lookahead.geometry.files import load_points_file
from lookahead.geometry.gcode import GcodeResult, read_gcode
from lookahead.geometry.kinematics import AxisIdentity, Kinematics, TwoDriveWinder
from lookahead.geometry.nurbs import BSplinePath, CompositePath, NurbsPath, discretize
from lookahead.geometry.piecewise import PiecewisePath
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
    "PRESETS",
    "AxisIdentity",
    "BSplinePath",
    "CompositePath",
    "GcodeResult",
    "Kinematics",
    "NurbsPath",
    "Path",
    "PiecewisePath",
    "PresetInfo",
    "SplinePath",
    "StreamingFit",
    "TwoDriveWinder",
    "chord_parameters",
    "discretize",
    "fit_points",
    "helical_layer",
    "hoop_layer",
    "load_points_file",
    "preset_points",
    "read_gcode",
    "winding_angle",
]
