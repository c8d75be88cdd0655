"""Cutting and joining feed profiles (s(t) as a scipy PPoly in t).

Written by hand because scipy's PPoly can be extended but not sliced: a slice re-expands the
piece it cuts about the new left end (Taylor coefficients, exact to rounding) and keeps the
other pieces as they are.
"""

from __future__ import annotations

from math import comb

import numpy as np
from scipy.interpolate import PPoly

from lookahead.planning.base import FeedProfile


def slice_profile(profile: FeedProfile, t0: float, t1: float | None = None) -> FeedProfile:
    """The profile between its times t0 < t1 (seconds from its start; t1 None: its end),
    re-timed to start at 0."""
    pp = profile.s_of_t
    x0 = pp.x[0]
    t1 = profile.duration if t1 is None else t1
    inner = pp.x[(pp.x > x0 + t0 + 1e-12) & (pp.x < x0 + t1 - 1e-12)]
    edges = np.concatenate([[x0 + t0], inner, [x0 + t1]])
    deg = pp.c.shape[0] - 1
    left = edges[:-1]
    # each new piece takes the old piece that holds its midpoint: a breakpoint within 1e-12
    # of t0 is dropped above, and the piece that ends there (a heuristic profile starts with
    # one 1e-17 s long) must not be stretched over the new piece (it was, by the piece on
    # the right of `left`: a slice at t = 0 of such a profile broke amax by 1 %)
    mid = 0.5 * (edges[:-1] + edges[1:])
    idx = np.clip(np.searchsorted(pp.x, mid, side="right") - 1, 0, pp.c.shape[1] - 1)
    dx = left - pp.x[idx]
    c = np.zeros((deg + 1, left.size))
    for n in range(deg + 1):  # n-th Taylor coefficient of piece idx about dx
        for m in range(n, deg + 1):
            c[deg - n] += pp.c[deg - m, idx] * comb(m, n) * dx ** (m - n)
    return FeedProfile(PPoly(c, edges - edges[0], extrapolate=False))


def concatenate(profiles: list[FeedProfile]) -> FeedProfile:
    """Profiles played one after the other (each starts where the previous one ends in s);
    pieces of lower degree are padded to the highest degree."""
    degree = max(p.s_of_t.c.shape[0] for p in profiles)
    xs, cs, offset = [np.zeros(1)], [], 0.0
    for p in profiles:
        pp = p.s_of_t
        c = np.zeros((degree, pp.c.shape[1]))
        c[degree - pp.c.shape[0]:] = pp.c
        cs.append(c)
        xs.append(offset + (pp.x[1:] - pp.x[0]))
        offset = xs[-1][-1]
    return FeedProfile(PPoly(np.concatenate(cs, axis=1), np.concatenate(xs), extrapolate=False))
