"""G-code reader, point files, winder kinematics."""

import numpy as np
import pytest

from lookahead.geometry import AxisIdentity, TwoDriveWinder, load_points_file, read_gcode

PROGRAM = """%
(winder program) ; header
N10 G21 G90
N20 G1 X10 A90 F600
N30 X10 A90
N40 X10 A90
N50 G92 X0 A0 (carriage zero here)
N60 X5
N70 G91 A-10
N80 G20 X1 F60
N90 G0 X1
N100 G90 X0
M30
G1 X999
"""


def test_gcode_moves_g92_units_and_feed() -> None:
    r = read_gcode(PROGRAM, dialect="rs274")
    assert r.axes == ["X", "C"]
    assert r.points.tolist() == [
        [10.0, 90.0],
        [15.0, 90.0],  # G92 X0 at X10: X5 -> machine 15
        [15.0, 80.0],  # incremental A-10, degrees
        [40.4, 80.0],  # G20: X1 inch, incremental
        [65.8, 80.0],
        [10.0, 80.0],  # G90 X0 in programmed coordinates = machine 10 (G92 offset)
    ]
    assert r.skipped == 2
    assert r.lines.tolist() == [4, 8, 9, 10, 11, 12]
    # rs274: F600 mm/min measures X when X moves: X10 A90 takes 1 s, so the path speed
    # (path_scale 1: the norm of X mm and A deg) may reach hypot(10, 90) per s
    assert r.feed[0] == pytest.approx(np.hypot(10.0, 90.0))
    assert np.allclose(r.feed[1:3], 10.0)  # X alone; A alone (F in deg/min)
    assert r.feed[3] == pytest.approx(60 * 25.4 / 60)  # F60 inch/min
    assert r.programmed_time_s == pytest.approx(1.0 + 0.5 + 1.0 + 1.0)
    assert np.isnan(r.feed[4])  # rapid: no cap
    assert np.isnan(r.feed[5])  # G0 is modal
    marlin = read_gcode(PROGRAM)  # the default dialect: G0 takes the modal F like G1
    assert np.array_equal(marlin.points, r.points)
    assert marlin.feed[4] == marlin.feed[5] == pytest.approx(25.4)


def test_gcode_third_axis_and_thousands_of_moves() -> None:
    lines = ["G1 F1200"] + [f"X{i} Y{i * 0.5:.3f} Z2" for i in range(1, 3001)] + ["X3000 Y1500 Z2"]
    r = read_gcode("\n".join(lines), axis_map={"X": "X", "Y": "C", "Z": "Z"}, axes=["X", "C", "Z"])
    assert r.points.shape == (3000, 3) and r.skipped == 1
    assert np.allclose(r.points[-1], [3000, 1500, 2]) and np.allclose(r.feed, 20.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("G1 X1\nG1 X2 Q5\n", "line 2: unsupported word Q5"),
        ("G1 X1\n\nG2 X2 A1\n", "line 3: unsupported word G2"),
        ("G1 X1 Z3\n", "line 1: letter Z .Z3.: this machine has no axis for it; map it in the "
                        "configuration .gcode.letters"),
        ("X1\n", "line 1: axis words before any G0/G1"),
        ("G1 X1 (open comment\n", "line 1: unbalanced"),
        ("G1 X1\nG1 X1.2.3\n", "line 2: cannot read"),
        ("G1 X1\nM3\n", "line 2: unsupported word M3"),
        ("G92\n", "line 1: G92 needs"),
    ],
)
def test_gcode_errors_name_the_line(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        read_gcode(text)


def test_points_files(tmp_path) -> None:
    csv_file = tmp_path / "job.csv"
    csv_file.write_text("X,C\n0,0\n1.5,10\n\n3,20\n")
    axes, pts = load_points_file(csv_file)
    assert axes == ["X", "C"] and pts.tolist() == [[0, 0], [1.5, 10], [3, 20]]
    axes, pts = load_points_file(csv_file, axes=["C", "X"])
    assert pts[:, 0].tolist() == [0, 10, 20]
    bad = tmp_path / "bad.csv"
    bad.write_text("X,C\n0,0\n\n1,nan\n")
    with pytest.raises(ValueError, match="line 4"):
        load_points_file(bad)
    npy = tmp_path / "job.npy"
    np.save(npy, np.arange(6.0).reshape(3, 2))
    with pytest.raises(ValueError, match="axes"):
        load_points_file(npy)
    axes, pts = load_points_file(npy, axes=["X", "C"])
    assert pts.shape == (3, 2)
    np.save(npy, np.arange(6.0))
    with pytest.raises(ValueError, match="shape"):
        load_points_file(npy, axes=["X", "C"])


def test_winder_kinematics_unwraps_through_360() -> None:
    turns = np.linspace(0, 3 * 360, 200)  # three revolutions, degrees
    x = np.linspace(0, 500, 200)
    contact = np.column_stack([x, 100 * np.cos(np.radians(turns)), 100 * np.sin(np.radians(turns))])
    axes = TwoDriveWinder().inverse(contact, orientations=np.ones((200, 3)))
    assert np.allclose(axes[:, 0], x) and np.allclose(axes[:, 1], turns)
    shifted = TwoDriveWinder(c_start=720.0).inverse(contact)
    assert np.allclose(shifted[:, 1], turns + 720.0)
    backwards = TwoDriveWinder().inverse(contact[::-1])
    assert np.allclose(backwards[:, 1], turns[::-1] - 1080.0)


def test_kinematics_errors_and_identity() -> None:
    with pytest.raises(ValueError, match=r"points\[1\] lies on the mandrel axis"):
        TwoDriveWinder().inverse(np.array([[0, 1.0, 0], [1, 0, 0], [2, 0, 1.0]]))
    with pytest.raises(ValueError, match=r"points\[0\] is not finite"):
        TwoDriveWinder().inverse(np.array([[np.nan, 1.0, 0]]))
    with pytest.raises(ValueError, match="orientations"):
        TwoDriveWinder().inverse(np.ones((2, 3)), orientations=np.ones((3, 3)))
    ident = AxisIdentity(["X", "C"])
    pts = np.array([[1.0, 2.0], [3.0, 4.0]])
    out = ident.inverse(pts)
    assert np.array_equal(out, pts) and out is not pts
    with pytest.raises(ValueError, match="shape"):
        ident.inverse(np.ones((2, 3)))
