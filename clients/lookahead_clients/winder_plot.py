"""The winder's plot of one job (matplotlib, Agg backend, imported only when plotting)."""

from __future__ import annotations

import numpy as np


def plot_job(path: str, arrays: dict[str, np.ndarray], report: dict, dt: float) -> None:
    """Write a PNG: commanded axis positions and velocities, following error, fibre angle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lookahead_clients.fibre import fibre_angle_deg

    axes = report["axes"]
    pos, vel = arrays["pos_cmd"], arrays["vel_cmd"]
    t = np.arange(len(pos)) * dt
    fig, ax = plt.subplots(4, 1, figsize=(10, 11), sharex=True)
    for i, name in enumerate(axes):
        ax[0].plot(t, pos[:, i], label=name)
        ax[1].plot(t, vel[:, i], label=name)
        ax[2].plot(t, pos[:, i] - arrays["pos_act"][:, i], label=name)
    ax[0].set_ylabel("position (axis units)")
    ax[1].set_ylabel("velocity (units/s)")
    ax[2].set_ylabel("following error")
    if report.get("radius_mm") and "X" in axes and "C" in axes:
        ix, ic = axes.index("X"), axes.index("C")
        r = report["radius_mm"]
        ax[3].plot(t, fibre_angle_deg(vel[:, ix], vel[:, ic], r), label="programmed")
        ax[3].plot(t, fibre_angle_deg(arrays["vel_act"][:, ix], arrays["vel_act"][:, ic], r),
                   label="laid", linestyle="--")
        for tr in report["traverses"]:
            ax[3].axvspan(tr["start"] * dt, tr["stop"] * dt, alpha=0.1, color="green")
    ax[3].set_ylabel("fibre angle (deg)")
    ax[3].set_xlabel("time (s)")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(loc="upper right")
    peaks = ", ".join(f"{k}: " + "/".join(f"{100 * f:.0f}%" for f in v)
                      for k, v in report["peak_fraction"].items())
    fig.suptitle(f"job {report['job']}: {report['duration_s']:.2f} s, "
                 f"{report['violations']} violations, peaks {peaks}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
