"""Figures one failed law cannot ruin (issue 47, item 4), inspected as matplotlib figures captured at savefig: the
y ranges are those of the runs that stayed up and each failure is marked; the speed figure is titled after the files
that ran; a path (and a Fig. 3 curve) a figure cannot tell from another's is dashed and said to be the same; a
narrow figure's legend is not cut at its edges."""
import numpy as np
import pytest
from matplotlib.figure import Figure

from mwip_ros.cli import plotting
from mwip_ros.core.closed_loop.trajectory import TRAJECTORY_COLUMNS, Trajectory

pytestmark = pytest.mark.unit

H = 0.01
R = 0.25


@pytest.fixture
def saved(monkeypatch):
    """Every figure saved while the test runs, in order."""
    figs = []
    real = Figure.savefig

    def grab(self, *args, **kwargs):
        figs.append(self)
        return real(self, *args, **kwargs)
    monkeypatch.setattr(Figure, "savefig", grab)
    return figs


def make_run(label, a=0.05, fail_at=None, t_end=10.0, offset=0.0):
    """A driven run (the square's columns): theta_b = a sin t, u = 2000 a cos t, v about 0.5; ``fail_at``: from then on
    its wheels run away and its command blows up to 1.8e6 N m (SMC on the square), and the run ends 0.1 s later."""
    t = np.arange(int(round(t_end / H)) + 1) * H
    if fail_at is not None:
        t = t[t <= fail_at + 0.1 + 1e-9]
    cols = {c: np.zeros_like(t) for c in TRAJECTORY_COLUMNS}
    cols.update(t=t, theta_b=a * np.sin(t), dtheta_b=a * np.cos(t), dtheta_w=2.0 + 20 * a * np.sin(t),
                u=2000 * a * np.cos(t), v_ref=np.full_like(t, 0.5), dpsi_ref=np.zeros_like(t),
                x=0.5 * t + offset, y=np.full_like(t, offset), yaw=np.zeros_like(t))
    if fail_at is not None:
        late = t > fail_at - 0.05
        cols["u"][late] = 1.8e6
        cols["dtheta_w"][late] = 20_000.0   # v = 5,000 m/s
        cols["theta_b"][late] = -0.9
    return Trajectory(label, cols, fail_at is not None, H)


def _legend_texts(fig):
    return [t.get_text() for leg in fig.legends for t in leg.get_texts()]


def test_fig3_scales_each_panel_to_the_runs_that_stayed_up_and_marks_the_failure(tmp_path, saved):
    runs = [make_run("dsc"), make_run("dscndo", a=0.03), make_run("smc", fail_at=7.96)]
    plotting.fig3(runs, tmp_path / "f.png", falls={"smc": 7.96})
    fig = saved[-1]
    theta, dtheta, dwheel, u = fig.axes
    assert u.get_ylim()[1] < 200.0 and dwheel.get_ylim()[1] < 10.0   # not 1.8e6 N m, not 20,000 rad/s
    assert -0.07 < theta.get_ylim()[0] < -0.05 and 0.05 < theta.get_ylim()[1] < 0.07
    assert "smc failed at t = 7.960 s" in _legend_texts(fig)
    for ax in fig.axes:   # the failure's dotted line in every panel, at its time
        assert any(line.get_linestyle() == ":" and list(line.get_xdata()) == [7.96, 7.96] for line in ax.lines)
    marks = [line for line in theta.lines if line.get_marker() == "X"]
    lo, hi = theta.get_ylim()
    assert len(marks) == 1 and lo <= marks[0].get_ydata()[0] <= hi   # the X held at the edge, in view


def test_fig3_without_a_failure_keeps_matplotlibs_range(tmp_path, saved):
    runs = [make_run("dsc"), make_run("big", a=5.0)]
    plotting.fig3(runs, tmp_path / "f.png")
    assert saved[-1].axes[0].get_ylim()[1] > 4.0


def test_the_speed_figure_is_titled_after_the_files_and_scaled_to_the_runs_that_stayed_up(tmp_path, saved):
    runs = [make_run("lqr"), make_run("smc", fail_at=7.96)]
    plotting.speed_plot(runs, tmp_path / "s.png", R, "config/paper.yaml config/square.yaml", {"smc": 7.96})
    fig = saved[-1]
    title = fig._suptitle.get_text()
    assert "config/square.yaml" in title and "motion.yaml" not in title
    assert all(ax.get_ylim()[1] < 2.0 for ax in fig.axes)              # v is 0.25 * (2 +- 1): not 5,000 m/s
    smc_texts = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert smc_texts == ["smc failed at t = 7.960 s"]


def test_a_path_a_figure_cannot_tell_from_another_is_dashed_and_said_to_be_the_same(tmp_path, saved):
    runs = [make_run("lqr"), make_run("dsc", offset=0.5), make_run("mpc", offset=0.004),   # 4 mm in x and y: 5.7 mm
            make_run("smc", fail_at=7.96, offset=1.0)]
    plotting.path_plot(runs, tmp_path / "p.png", H, falls={"smc": 7.96})
    ax = saved[-1].axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "mpc (the path of lqr, within 0.006 m: drawn over it, dashed)" in texts
    assert "smc (failed at t = 7.960 s: X)" in texts
    assert not any("the path of" in t for t in texts if t.startswith("dsc"))   # 0.5 m apart: told apart
    mpc = next(line for line in ax.lines if line.get_label().startswith("mpc"))
    assert mpc.get_linestyle() != "-"


def test_fig3_says_which_curves_it_draws_over_another(tmp_path, saved):
    runs = [make_run("lqr"), make_run("mpc", a=0.0501), make_run("dscndo", a=0.02)]
    plotting.fig3(runs, tmp_path / "f.png")
    fig = saved[-1]
    notes = " ".join(t.get_text() for t in fig.axes[-1].texts)
    assert "mpc is dashed over lqr" in notes and "dscndo is dashed" not in notes


def test_a_narrow_figures_legend_is_not_cut_at_its_edges(tmp_path, saved):
    """pitch_estimate.png of one run (5.2 in wide): its four labels in as many columns as fit."""
    run = make_run("raw")
    run.columns["theta_b_hat"] = run["theta_b"] + 0.001
    assert plotting.pitch_estimate_plot([run], tmp_path / "p.png", window=(2.0, 4.0))
    fig = saved[-1]
    fig.canvas.draw()
    box = fig.legends[0].get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width
    assert not any(box.overlaps(ax.get_window_extent()) for ax in fig.axes)


def test_a_long_title_is_wrapped_inside_the_figure_not_cut_at_its_edges(tmp_path, saved):
    """The speed figure is titled after the files as the user named them: run from another directory, two absolute
    paths (about 110 characters) were cut at both edges of the 8.5 in figure; the title is wrapped to fit."""
    runs = [make_run("lqr"), make_run("dscndo")]
    source = "/work/wt/h54-verify47/config/paper.yaml /work/wt/h54-verify47/config/square.yaml"
    plotting.speed_plot(runs, tmp_path / "s.png", R, source)
    fig = saved[-1]
    fig.canvas.draw()
    title = fig._suptitle
    box = title.get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width and box.y1 <= fig.bbox.height, (box, fig.bbox)
    assert title.get_text().replace("\n", " ") == f"speed and its reference ({source})"   # every word kept
    assert not any(box.overlaps(ax.get_window_extent()) for ax in fig.axes)
