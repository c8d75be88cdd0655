"""StreamingFit: chunking independence where final, C2 across seams, skips, tail bound."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lookahead.geometry import StreamingFit
from lookahead.geometry.streaming import BLOCK, LOOKAHEAD

SCALE = np.array([1.0, np.pi / 180 * 100])


def stream_points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    th = np.cumsum(0.002 + 0.05 * rng.random(n))
    return np.column_stack([100 * np.cos(th) + 0.3 * np.arange(n), np.degrees(th)])


def feed(fit: StreamingFit, pts: np.ndarray, sizes: list[int]) -> None:
    i = 0
    for k in sizes:
        fit.extend(pts[i : i + k])
        i += k
    if i < len(pts):
        fit.extend(pts[i:])


def final_pieces(fit: StreamingFit) -> int:
    path = fit.path()
    return int(np.searchsorted(path.breakpoints_s(), fit.final_length))


@pytest.mark.parametrize("method", ["cubic", "pchip"])
@settings(max_examples=25, deadline=None)
@given(sizes=st.lists(st.integers(1, 90), min_size=1, max_size=30), probe=st.booleans())
def test_chunking_gives_same_geometry_where_final(
    method: str, sizes: list[int], probe: bool
) -> None:
    pts = stream_points(400, seed=len(sizes))
    one = StreamingFit(2, SCALE, method)
    one.extend(pts)
    chunked = StreamingFit(2, SCALE, method)
    i = 0
    for k in sizes:
        chunked.extend(pts[i : i + k])
        i += k
        if probe and chunked.npoints >= 2:
            chunked.path()  # asking for the current path must not disturb anything
    if i < len(pts):
        chunked.extend(pts[i:])
    assert chunked.final_length == one.final_length
    k = final_pieces(one)
    assert k > 0
    a, b = one.path(), chunked.path()
    assert np.array_equal(a.pp.c[:, :k], b.pp.c[:, :k])  # bit-identical final pieces
    assert np.array_equal(a.breakpoints_s()[: k + 1], b.breakpoints_s()[: k + 1])
    fa, fb = one.finish(), chunked.finish()
    assert np.array_equal(fa.pp.c, fb.pp.c) and fa.length == fb.length


@pytest.mark.parametrize("method", ["cubic", "pchip"])
def test_final_geometry_never_changes_and_tail_is_bounded(method: str) -> None:
    pts = stream_points(1500, seed=7)
    fit = StreamingFit(2, SCALE, method)
    history = []
    rng = np.random.default_rng(1)
    i = 0
    while i < len(pts):
        k = int(rng.integers(1, 120))
        fit.extend(pts[i : i + k])
        i += k
        if fit.npoints < 2:
            continue
        path = fit.path()
        final = final_pieces(fit)
        tail = len(path.pp.x) - 1 - final
        bound = BLOCK + LOOKAHEAD + 2 if method == "cubic" else 1
        assert tail <= bound
        history.append((fit.final_length, final, path.pp.c[:, :final].copy()))
    end = fit.finish()
    assert fit.final_length == end.length
    lengths = [h[0] for h in history]
    assert lengths == sorted(lengths)
    for length, final, coef in history:
        assert np.array_equal(end.pp.c[:, :final], coef)
        assert end.breakpoints_s()[final] == length


def test_cubic_stream_is_c2_across_seams_and_interpolates() -> None:
    pts = stream_points(700, seed=2)
    fit = StreamingFit(2, SCALE, "cubic")
    feed(fit, pts, [13, 100, 1, 77, 200])
    path = fit.path()  # final part + tail: the seam is inside
    assert fit.final_length < path.length
    assert np.max(np.abs(path.pp(path.pp.x) - pts)) < 1e-9
    x, h = path.pp.x[1:-1], np.diff(path.pp.x)[:-1]
    for order in range(3):
        dp = path.pp.derivative(order) if order else path.pp
        left = np.stack([np.polyval(dp.c[:, i, :], h[i]) for i in range(len(x))])
        jump = np.max(np.abs(left - dp(x)), axis=1)
        assert np.max(jump) < 1e-9 * (1 + np.max(np.abs(dp(x)))), order


def test_cubic_stream_matches_the_global_natural_spline() -> None:
    from scipy.interpolate import CubicSpline

    pts = stream_points(600, seed=4)
    fit = StreamingFit(2, SCALE, "cubic")
    feed(fit, pts, [50] * 12)
    path = fit.finish()
    ref = CubicSpline(path.pp.x, pts, bc_type="natural")
    u = np.linspace(*path.u_range, 20001)
    assert np.max(np.abs(ref(u) - path.eval_u(u, 0)[0])) < 1e-9


def test_repeats_and_zero_moves_are_skipped_and_counted() -> None:
    pts = stream_points(50)
    noisy = np.insert(pts, [5, 5, 20, 49], pts[[4, 4, 19, 48]], axis=0)
    noisy = np.insert(noisy, 30, noisy[29] + 1e-12, axis=0)
    fit = StreamingFit(2, SCALE, "cubic")
    fit.extend(noisy[:6])  # ends on a repeat of its last kept point
    fit.extend(noisy[6:])
    assert fit.skipped == 5 and fit.npoints == 50
    clean = StreamingFit(2, SCALE, "cubic")
    clean.extend(pts)
    assert np.array_equal(fit.finish().pp.c, clean.finish().pp.c)


def test_small_streams_and_errors() -> None:
    fit = StreamingFit(2, SCALE, "cubic")
    fit.extend([[0.0, 0.0]])
    with pytest.raises(ValueError, match="at least 2"):
        fit.path()
    fit.extend([[1.0, 1.0]])
    line = fit.path()
    assert line.length == pytest.approx(np.hypot(1.0, SCALE[1]))
    with pytest.raises(ValueError, match=r"points \(stream from 2\)\[1\]"):
        fit.extend([[2.0, 2.0], [np.nan, 3.0]])
    with pytest.raises(ValueError, match="shape"):
        fit.extend(np.zeros((3, 3)))
    fit.finish()
    with pytest.raises(ValueError, match="finished"):
        fit.extend([[5.0, 5.0]])
    with pytest.raises(ValueError, match="method"):
        StreamingFit(2, SCALE, "quintic")
