"""Plots of a plan: the paper's Fig. 2 (feed, path acceleration and jerk along the path)
above the axis velocities, accelerations and jerks against their limits.

matplotlib is in the `bench` extra: imported lazily, with the Agg backend (files only).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from lookahead.limits import AxisLimits
from lookahead.planning.base import FeedProfile
from lookahead.sampling import Samples


def plot_plan(filename: str, profile: FeedProfile, samples: Samples, limits: AxisLimits,
              dt: float, axes: Sequence[str], title: str = "") -> None:
    """Write a PNG: path quantities over s (top row), axis quantities over t (3 rows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.arange(len(samples)) * dt
    s, v, a, j = profile.at(t)
    # axis jerk by finite differences of the sampled accelerations (what the drive sees)
    jerk = np.vstack([np.diff(samples.acc, axis=0) / dt, np.zeros((1, samples.acc.shape[1]))])
    fig, grid = plt.subplots(4, 1, figsize=(10, 11), sharex=False)
    ax = grid[0]
    ax.plot(s, v, label="feed v [unit/s]")
    ax.plot(s, a / 10.0, label="path acc a / 10")
    ax.plot(s, j / 100.0, label="path jerk j / 100", alpha=0.6)
    ax.set_xlabel("s (path units)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "feed profile along the path")
    for row, (name, data, lim) in enumerate(
        (("velocity", samples.vel, limits.vmax), ("acceleration", samples.acc, limits.amax),
         ("jerk", jerk, limits.jmax)), start=1):
        ax = grid[row]
        for i, axis in enumerate(axes):
            ax.plot(t, data[:, i] / lim[i], label=f"{axis} / {lim[i]:g}")
        ax.axhline(1.0, color="k", lw=0.6, ls="--")
        ax.axhline(-1.0, color="k", lw=0.6, ls="--")
        ax.set_ylabel(f"{name} / limit")
        ax.legend(loc="upper right", fontsize=8)
    grid[-1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(filename, dpi=110)
    plt.close(fig)
