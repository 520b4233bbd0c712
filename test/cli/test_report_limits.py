"""mwip_report, runs.read_csv / read_bag_run and the animation on hostile inputs: bounded in time and memory
whatever the input's length or span, and what cannot be drawn is refused with one line (exit 2).

The limits are monkeypatched down where a real case would need gigabytes: the code counts before it
allocates, so the small case exercises the same refusal."""
import time
import tracemalloc

import numpy as np
import pytest

from mwip_ros import runs as R
from mwip_ros.cli import animation as A
from mwip_ros.cli import plotting, report
from mwip_ros.core.closed_loop.trajectory import TRAJECTORY_COLUMNS, Trajectory

pytestmark = pytest.mark.unit

HEADER = ",".join(TRAJECTORY_COLUMNS)


def write(path, text):
    path.write_text(text)
    return str(path)


def rows(*ts, theta_b=0.01):
    return "".join(f"{t},0,{theta_b},0,0,0,0,0,0,0\n" for t in ts)


def one_error_line(capsys, *words):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mwip_report: error: "), err
    for w in words:
        assert w in err[0], (w, err[0])
    return err[0]


@pytest.mark.parametrize("t_last", ["1e7", "1e9"])
def test_a_short_csv_of_a_huge_span_is_refused_for_the_animation_at_once_and_drawn_without_it(tmp_path, capsys,
                                                                                               t_last):
    f = write(tmp_path / "span.csv", HEADER + "\n" + rows(0, 1, t_last))
    tracemalloc.start()
    t0 = time.monotonic()
    try:
        code = report.main([f, "--out", str(tmp_path / "rep")])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert code == 2 and time.monotonic() - t0 < 10 and peak < 50 << 20   # once 3 GiB (1e7) or 149 GiB (1e9)
    one_error_line(capsys, "animation.gif plays in real time", "--no-animation")
    assert not (tmp_path / "rep").exists()
    assert report.main([f, "--out", str(tmp_path / "rep"), "--no-animation"]) == 0
    assert (tmp_path / "rep" / "fig3.png").is_file() and not (tmp_path / "rep" / "animation.gif").exists()


@pytest.mark.parametrize("body, words", [
    (HEADER + "\n" + rows("nan", 1), "t = nan s at row 1: every t must be finite"),
    (HEADER + "\n" + rows(0, "inf"), "t = inf s at row 2"),
    (HEADER + "\n" + rows(0, 2, 1), "t decreases at row 3"),
    (HEADER + "\n", "no rows (a header only)"),
    ("t\n0\n1\n2\n", "no theta_w, theta_b, dtheta_w, dtheta_b, u columns"),
    (HEADER + "\n0,0,0\n", "not an mwip_ros CSV"),
    ("t,t\n0,0\n", "the column 't' appears twice"),
    ("a,b\n0,0\n", "no header with a 't' column"),
    (HEADER + "\n" + rows(0) + "0.1,x,0,0,0,0,0,0,0,0\n", "not an mwip_ros CSV"),
    ("", "no header with a 't' column"),
    (HEADER + "\n0,0,1e308,0,0,0,0,0,0,0\n1,0,-1e308,0,0,0,0,0,0,0\n", "beyond what a figure can draw"),
])
def test_a_hostile_csv_is_one_line_and_exit_2(tmp_path, capsys, body, words):
    f = write(tmp_path / "bad.csv", body)
    assert report.main([f, "--out", str(tmp_path / "rep")]) == 2
    one_error_line(capsys, words)
    assert not (tmp_path / "rep").exists()


def test_a_six_column_csv_without_estimates_or_disturbance_is_reported(tmp_path, capsys):
    t = np.arange(201) * 0.01
    lines = ["t,theta_w,theta_b,dtheta_w,dtheta_b,u"] + [f"{float(x)!r},0.0,{0.01 * float(np.sin(x))!r},0.0,0.0,1.0"
                                                         for x in t]
    f = write(tmp_path / "six.csv", "\n".join(lines) + "\n")
    assert report.main([f, "--out", str(tmp_path / "rep"), "--gif-fps", "5"]) == 0
    written = {p.name for p in (tmp_path / "rep").iterdir()}
    assert {"fig3.png", "observer.png", "metrics.json", "animation.gif"} <= written


def test_rows_beyond_the_limit_are_refused_before_the_rest_is_read(tmp_path, capsys, monkeypatch):
    """A 10-million-row CSV once took > 3 GiB: at most MAX_ROWS (+1) rows are parsed, then one line."""
    assert R.MAX_ROWS == 2_000_000   # 2.8 h at 200 Hz, what docs/graph.md states (Sizes and files)
    monkeypatch.setattr(R, "MAX_ROWS", 1000)
    f = write(tmp_path / "long.csv", HEADER + "\n" + rows(*range(1001)))
    assert report.main([f, "--out", str(tmp_path / "rep")]) == 2
    one_error_line(capsys, "more than 1,000 rows", "cut or decimate it")
    assert len(R.read_csv(write(tmp_path / "ok.csv", HEADER + "\n" + rows(*range(1000))))) == 1000


def test_a_file_beyond_the_size_limit_is_refused_before_a_byte_is_read(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(R, "MAX_CSV_BYTES", 100)
    f = write(tmp_path / "big.csv", HEADER + "\n" + rows(*range(10)))
    monkeypatch.setattr("builtins.open", lambda *a, **k: pytest.fail("opened a file beyond the size limit"))
    assert report.main([f, "--out", str(tmp_path / "rep")]) == 2
    monkeypatch.undo()
    one_error_line(capsys, "big.csv", "more than a CSV of a run of at most", "not read")


def test_a_bag_beyond_the_row_or_size_limit_is_refused_with_one_line(tmp_path, capsys, monkeypatch):
    from test_report_bag import write_bag
    bag = write_bag(tmp_path / "bag", np.zeros(50), np.zeros(50))
    monkeypatch.setattr(R, "MAX_ROWS", 20)
    assert report.main([str(bag), "--out", str(tmp_path / "rep")]) == 2
    one_error_line(capsys, "more than 20 joint_states messages")
    monkeypatch.setattr(R, "MAX_ROWS", 2_000_000)
    monkeypatch.setattr(R, "MAX_BAG_BYTES", 1000)
    assert report.main([str(bag), "--out", str(tmp_path / "rep")]) == 2
    one_error_line(capsys, "more than a bag of a run of at most")


def test_frames_are_counted_before_they_are_allocated():
    t = np.array([0.0, 1.0, 1e9])
    run = Trajectory("far", {"t": t, "theta_w": np.zeros(3), "theta_b": np.zeros(3)}, False, np.nan)
    with pytest.raises(ValueError, match="frames"):
        A.frame_times([run], 20.0)                 # 2e10 frame times: refused, not allocated
    with pytest.raises(ValueError, match="real time"):
        A.write_gif([run], "/nonexistent/a.gif")   # refused before any drawing
    assert A.refusal([run]) and A.refusal([Trajectory("near", {"t": t[:2]}, False, 1.0)]) is None


def test_a_long_span_within_the_gifs_reach_gets_max_frames_each_at_most_a_gifs_longest(tmp_path, monkeypatch):
    monkeypatch.setattr(A, "MAX_FRAMES", 12)
    monkeypatch.setattr(A, "MAX_SPAN_S", 11 * A.MAX_FRAME_MS / 1000)
    t = np.array([0.0, 1.0, 5000.0])
    run = Trajectory("long", {"t": t, "theta_w": np.zeros(3), "theta_b": np.full(3, 0.1)}, False, np.nan)
    n = A.write_gif([run], tmp_path / "a.gif")
    assert 2 <= n <= 12
    from PIL import Image
    with Image.open(tmp_path / "a.gif") as im:
        assert im.n_frames == n and im.info["duration"] <= A.MAX_FRAME_MS


def test_figures_draw_at_most_max_points_a_line_keeping_the_extremes():
    n = 1_000_001
    t = np.arange(n) * 0.005
    y = np.sin(t)
    y[123_457] = 7.0        # a spike
    y[500_000:500_100] = np.nan
    td, yd = plotting.decimate(t, y)
    assert len(td) <= plotting.MAX_POINTS and np.all(np.diff(td) > 0)
    assert np.nanmax(yd) == 7.0 and np.nanmin(yd) == pytest.approx(-1.0, abs=1e-6)
    short = np.arange(10.0)
    assert plotting.decimate(short, short)[0] is not None and len(plotting.decimate(short, short)[0]) == 10
