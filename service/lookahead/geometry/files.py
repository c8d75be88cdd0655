"""Point streams from files: CSV with a header row of axis names, or NumPy .npy."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path as FilePath

import numpy as np

from lookahead.geometry.spline_path import validate_points


def load_points_file(
    path: str | FilePath, axes: Sequence[str] | None = None
) -> tuple[list[str], np.ndarray]:
    """(axes, points (n, naxes)) from `path`.

    CSV (.csv/.txt): the first row names the axes; with `axes` given, those columns are
    picked in that order. NPY (.npy): a 2-D float array; `axes` is required. ValueError
    names the row (CSV: file line) of any bad value.
    """
    path = FilePath(path)
    if path.suffix.lower() == ".npy":
        if axes is None:
            raise ValueError(f"{path}: .npy files carry no axis names; pass axes")
        return list(axes), validate_points(np.load(path, allow_pickle=False), len(axes), str(path))
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        rows = [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]
    if not rows:
        raise ValueError(f"{path}: empty file")
    header = [h.strip() for h in rows[0][1]]
    wanted = list(axes) if axes is not None else header
    missing = [a for a in wanted if a not in header]
    if missing:
        raise ValueError(f"{path}: header {header} lacks axes {missing}")
    cols = [header.index(a) for a in wanted]
    points = np.empty((len(rows) - 1, len(cols)))
    for i, (line, row) in enumerate(rows[1:]):
        if len(row) != len(header):
            raise ValueError(f"{path}: line {line}: expected {len(header)} values, got {len(row)}")
        try:
            points[i] = [float(row[c]) for c in cols]
        except ValueError as err:
            raise ValueError(f"{path}: line {line}: {err}") from None
        if not np.all(np.isfinite(points[i])):
            raise ValueError(f"{path}: line {line}: value is not finite")
    return wanted, points
