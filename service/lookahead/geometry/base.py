"""The path model every planner works on.

A `Path` is a curve x(u) in machine-axis space (N axes, each in its own unit), with a
native parameter u in [u_min, u_max] and an arc length s in [0, length] measured in the
path metric: ds = || path_scale * dx ||_2 (PROTOCOL.md "Path speed"; for the winder
X in mm and C in deg scaled by pi/180*R, so s is fibre length in mm).

Planners work in s. `eval_s` returns derivatives with respect to s, obtained from the
u-derivatives by the chain rule through u(s) (the paper's section 2.1 warning).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class Path(ABC):
    """A curve in axis space. Subclasses: fitted point streams, B-spline/NURBS pieces,
    and the concatenation of pieces (`CompositePath`)."""

    #: number of axes
    naxes: int
    #: per-axis scale of the path metric, shape (naxes,)
    path_scale: np.ndarray

    @property
    @abstractmethod
    def length(self) -> float:
        """Total arc length in the path metric (path units)."""

    @property
    @abstractmethod
    def u_range(self) -> tuple[float, float]:
        """The native parameter interval [u_min, u_max]."""

    @abstractmethod
    def eval_u(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        """Position and derivatives with respect to u.

        Returns shape (order + 1, len(u), naxes): [x, dx/du, d2x/du2, d3x/du3][:order+1].
        """

    @abstractmethod
    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        """Arc length at parameter u (accurate to 1e-9 relative)."""

    @abstractmethod
    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        """Parameter at arc length s (inverse of s_of_u, accurate to 1e-9 relative)."""

    def eval_s(self, s: np.ndarray, order: int = 3) -> np.ndarray:
        """Position and derivatives with respect to arc length s.

        Returns shape (order + 1, len(s), naxes): [x, x_s, x_ss, x_sss][:order+1]
        (see `arc_length_derivatives`)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        u = self.u_of_s(s)
        if order <= 0:
            return self.eval_u(u, order=0)[:1]
        d = self.eval_u(u, order=min(order, 3))
        if order >= 3:
            _, xs, xss, xsss = arc_length_derivatives(d, self.path_scale)
            return np.stack([d[0], xs, xss, xsss])
        # x_s and x_ss do not depend on x_uuu: the same values as the full chain rule,
        # without evaluating or differentiating what is not asked for
        _, _, _, _, xs, xss = _chain_rule_2(d[1], d[2] if order >= 2 else None,
                                            self.path_scale)
        return np.stack([d[0], xs] if order == 1 else [d[0], xs, xss])

    @abstractmethod
    def breakpoints_s(self) -> np.ndarray:
        """Arc lengths of the parameter knots (where some derivative may jump), sorted,
        including 0 and length. Planners may use them to choose planning segments."""

    def continuity(self) -> int:
        """Smoothness order guaranteed at interior knots: 2 for C2, 1 for C1 (pchip).

        At a C1 knot x_ss jumps; a planner must cap the feed there at
        sqrt(jmax * dt / |jump of x_ss|) per axis (DESIGN.md, pitfalls)."""
        return 2

    def corners_s(self) -> np.ndarray:
        """Arc lengths of tangent discontinuities, where the machine must come to rest."""
        return np.empty(0)


def arc_length_derivatives(d: np.ndarray, path_scale: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """sigma = ds/du (n,) and x_s, x_ss, x_sss (each (n, naxes)) from the u-derivatives
    d[1:4] = x_u, x_uu, x_uuu (each (n, naxes); d[0], the position, is not used): the chain
    rule through u(s), for callers that hold u and so skip the arc-length inversion.

    With sigma(u) = ||path_scale * x_u||: u_s = 1/sigma, u_ss = -sigma_u / sigma^3,
    u_sss = (3 sigma_u^2 - sigma sigma_uu) / sigma^5.
    """
    xu, xuu, xuuu = d[1], d[2], d[3]
    w = np.asarray(path_scale, dtype=float) ** 2
    sigma, us, sigma_u, uss, xs, xss = _chain_rule_2(xu, xuu, path_scale)
    us2 = us * us
    sigma_uu = ((xuu * xuu) @ w + (xu * xuuu) @ w - sigma_u * sigma_u) * us
    usss = (3.0 * sigma_u * sigma_u - sigma * sigma_uu) * (us2 * us2 * us)
    xsss = xuuu * (us2 * us)[:, None] + xuu * (3.0 * us * uss)[:, None] + xu * usss[:, None]
    return sigma, xs, xss, xsss


def _chain_rule_2(xu: np.ndarray, xuu: np.ndarray | None, path_scale: np.ndarray
                  ) -> tuple[np.ndarray, ...]:
    """The first two orders of `arc_length_derivatives`: sigma, u_s, sigma_u, u_ss, x_s,
    x_ss (the last four None without xuu)."""
    # weighted sums over the few axes as matrix-vector products, reciprocals reused: half
    # the time of axis-wise sums and divisions on the 10^5 points of a long job
    w = np.asarray(path_scale, dtype=float) ** 2
    sigma = np.maximum(np.sqrt((xu * xu) @ w), np.finfo(float).tiny)
    us = 1.0 / sigma
    xs = xu * us[:, None]
    if xuu is None:
        return sigma, us, None, None, xs, None
    sigma_u = ((xu * xuu) @ w) * us
    us2 = us * us
    uss = -sigma_u * us2 * us
    xss = xuu * us2[:, None] + xu * uss[:, None]
    return sigma, us, sigma_u, uss, xs, xss
