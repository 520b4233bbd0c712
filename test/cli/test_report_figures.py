"""The report's and the sweep's figures, inspected as matplotlib figures (captured at savefig): titles from what
ran, legends clear of the axes, the metrics window shaded, the observer figure without estimates, one-axis
sweeps as lines, distinguishable identical curves, axis units from the parameter schema."""
import numpy as np
import pytest
from matplotlib.figure import Figure

from mwip_ros.cli import plotting, report
from mwip_ros.core.closed_loop.trajectory import TRAJECTORY_COLUMNS, Trajectory

pytestmark = pytest.mark.unit

H = 0.01


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


def make_run(label, t_end=10.0, a=0.02, estimates=False):
    t = np.arange(int(round(t_end / H)) + 1) * H
    cols = {c: np.zeros_like(t) for c in TRAJECTORY_COLUMNS}
    cols.update(t=t, theta_b=a * np.sin(2 * np.pi * t), u=30 * np.cos(2 * np.pi * t), tau_d1=5 * np.sin(t),
                tau_d2=np.cos(t), tau_hat1=4 * np.sin(t) if estimates else np.full_like(t, np.nan),
                tau_hat2=np.cos(t) if estimates else np.full_like(t, np.nan))
    return Trajectory(label, cols, False, H)


def boxes_overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def window_spans(ax):
    """The x ranges (data) of the patches labelled as the metrics window."""
    out = []
    for p in ax.patches:
        if "metrics window" in str(p.get_label()):
            xs = ax.transData.inverted().transform(p.get_verts())[:, 0]
            out.append((round(xs.min(), 9), round(xs.max(), 9)))
    return out


def test_fig3_is_titled_by_what_ran_shades_the_window_and_its_legend_covers_no_axes(tmp_path, saved):
    runs = [make_run("lqr"), make_run("lqr_ndo", a=0.01)]
    assert report.main([*_csvs(tmp_path, runs), "--out", str(tmp_path / "r"), "--no-animation",
                        "--window", "4", "9"]) == 0
    fig3 = saved[0]
    title = fig3._suptitle.get_text()
    assert "lqr" in title and "lqr_ndo" in title and "DSC" not in title
    fig3.canvas.draw()
    legend = fig3.legends[0].get_window_extent()
    axes = fig3.axes
    assert len(axes) == 4 and not any(boxes_overlap(legend, ax.get_window_extent()) for ax in axes)
    assert all(window_spans(ax) == [(4.0, 9.0)] for ax in axes)
    labels = fig3.legends[0].get_texts()
    assert {"lqr", "lqr_ndo"} <= {t.get_text() for t in labels}


def test_the_observer_figure_without_estimates_draws_tau_d_and_says_so(tmp_path, saved):
    runs = [make_run("dsc"), make_run("dscndo", estimates=True)]
    assert report.main([*_csvs(tmp_path, runs), "--out", str(tmp_path / "r"), "--no-animation"]) == 0
    obs = saved[1]
    axes = np.array(obs.axes).reshape(2, 2)
    for i in (0, 1):
        no_est, with_est = axes[i]
        assert "no estimate recorded" in [t.get_text() for t in no_est.texts]
        assert "no estimate recorded" not in [t.get_text() for t in with_est.texts]
        want = runs[0][f"tau_d{i + 1}"]
        assert any(np.array_equal(line.get_ydata(), want) for line in no_est.lines)   # the true tau_d is drawn
        assert len(with_est.lines) == 2 and len(no_est.lines) == 1
        assert window_spans(no_est) == [(5.0, 10.0)]
    obs.canvas.draw()
    legend = obs.legends[0].get_window_extent()
    assert not any(boxes_overlap(legend, ax.get_window_extent()) for ax in obs.axes)


def _csvs(tmp_path, runs):
    from mwip_ros.runs import write_csv
    paths = []
    for r in runs:
        paths.append(str(tmp_path / f"{r.label}.csv"))
        write_csv(r, paths[-1])
    return paths


def _sweep_cols(levels, laws=("dsc", "dscndo", "lqr", "lqr_ndo"), other=None):
    """results columns: every law upright for |theta_b(0)| <= 0.5 (so identical curves), a row per level."""
    cols = {"controller": [], "upright": [], "theta_b_rms": [], "scenario": [], plotting_key(): []}
    if other:
        cols[other[0]] = []
    i = 0
    for law in laws:
        for v in levels:
            for w in (other[1] if other else [None]):
                cols["controller"].append(law)
                cols[plotting_key()].append(float(v))
                if other:
                    cols[other[0]].append(float(w))
                cols["upright"].append(abs(v) <= 0.5)
                cols["theta_b_rms"].append(0.01)
                cols["scenario"].append(i)
                i += 1
    cols["plant_sim.torque_limit"] = [300.0] * i     # varied with a single value, as roa.yaml does
    return cols


def plotting_key():
    return "plant_sim.initial.theta_b"


def test_a_one_axis_sweep_draws_lines_not_a_one_row_image_and_identical_curves_stay_apart(tmp_path, saved):
    levels = np.linspace(-1.0, 1.0, 81)
    cols = _sweep_cols(levels)
    assert plotting.sweep_upright_map(cols, [(plotting_key(), True), ("plant_sim.torque_limit", True)],
                                      tmp_path / "m.png")
    fig = saved[-1]
    (ax,) = fig.axes
    assert not ax.images and len(ax.lines) == 4
    assert ax.get_xlabel() == "plant_sim.initial.theta_b [rad]"          # the unit from the schema
    truth = (np.abs(levels) <= 0.5).astype(float)
    for line in ax.lines:   # each law at its true share, never above 1 (the curves were offset up to 1.045)
        np.testing.assert_allclose(line.get_ydata(), truth, atol=1e-12)
    # four curves told apart: each its own marker and line style, the markers on staggered levels
    styles = {(line.get_marker(), line.get_linestyle()) for line in ax.lines}
    assert len(styles) == 4 and len({line.get_markevery() for line in ax.lines}) == 4
    assert "identical" in ax.get_title() and "dsc = dscndo = lqr = lqr_ndo" in ax.get_title()
    plotting.sweep_roa(cols, plotting_key(), {k: 0.5 for k in ("dsc", "dscndo", "lqr", "lqr_ndo")},
                       tmp_path / "roa.png")
    ax = saved[-1].axes[0]
    assert "identical" in ax.get_title() and ax.get_xlabel().endswith("[rad]")
    curves = [line for line in ax.lines if len(line.get_xdata()) == len(levels)]
    assert len(curves) == 4 and len({c.get_markevery() for c in curves}) == 4
    for line in ax.lines:   # the share curves and the ROA bars below them: nothing drawn above 1
        assert np.max(line.get_ydata()) <= 1.0, line.get_label()
    for c in curves:
        np.testing.assert_allclose(c.get_ydata(), truth, atol=1e-12)
    assert ax.get_ylim()[1] <= 1.06


def test_the_roa_share_of_eight_laws_never_rises_above_1_and_each_law_has_markers(tmp_path, saved):
    """8 laws every one upright on 5 levels: shares of exactly 1 (the offsets drew them up to 1.105)."""
    names = ("dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo")
    cols = _sweep_cols(np.linspace(-0.4, 0.4, 5), laws=names)
    plotting.sweep_roa(cols, plotting_key(), {k: 0.4 for k in names}, tmp_path / "roa.png")
    ax = saved[-1].axes[0]
    shares = [line for line in ax.lines if len(line.get_xdata()) == 5]
    assert len(shares) == 8
    for line in shares:
        assert np.all(np.asarray(line.get_ydata()) <= 1.0) and np.all(np.asarray(line.get_ydata()) == 1.0)
        start, step = line.get_markevery()
        assert start < 5   # a marker on one of the 5 levels: no law drawn without one


def _rms_cols(per_law):
    """results columns from {law: theta_b RMS of its upright runs}."""
    cols = {"controller": [], "upright": [], "theta_b_rms": []}
    for law, vals in per_law.items():
        for v in vals:
            cols["controller"].append(law)
            cols["upright"].append(True)
            cols["theta_b_rms"].append(float(v))
    return cols


def test_the_rms_distribution_gives_each_law_its_own_panel_and_names_identical_histograms(tmp_path, saved):
    """LQR, LQR+NDO and MPC with the same distribution were drawn exactly under MPC's histogram on one axis."""
    rng = np.random.default_rng(0)
    same = rng.uniform(0.01, 0.02, 50)
    cols = _rms_cols({"dsc": rng.uniform(0.05, 0.1, 50), "dscndo": rng.uniform(0.005, 0.01, 50), "lqr": same,
                      "lqr_ndo": same, "mpc": same})
    plotting.sweep_rms_distribution(cols, tmp_path / "rms.png")
    fig = saved[-1]
    panels = [ax for ax in fig.axes if ax.patches]
    assert len(panels) == 5                                   # one panel per law, none hidden under another
    texts = [" ".join(t.get_text() for t in ax.texts) for ax in fig.axes]
    assert [t.split(":")[0] for t in texts] == ["dsc", "dscndo", "lqr", "lqr_ndo", "mpc"]
    assert "same histogram" not in texts[2]
    assert "the same histogram as lqr" in texts[3] and "the same histogram as lqr and lqr_ndo" in texts[4]
    assert "same histogram" not in texts[0] + texts[1]
    assert all("50 upright" in t for t in texts)
    assert len({ax.get_xlim() for ax in fig.axes}) == 1      # one x axis for every panel: comparable


def test_a_two_axis_map_thins_its_ticks_and_labels_axes_with_units(tmp_path, saved):
    levels = np.linspace(-1.0, 1.0, 81)
    cols = _sweep_cols(levels, laws=("dsc", "dscndo"), other=("plant_sim.tau_ext1.amplitude", [0.0, 30.0]))
    assert plotting.sweep_upright_map(cols, [(plotting_key(), True), ("plant_sim.tau_ext1.amplitude", True)],
                                      tmp_path / "m.png")
    fig = saved[-1]
    maps = [ax for ax in fig.axes if ax.images]
    assert len(maps) == 2
    for ax in maps:
        assert 2 <= len(ax.get_xticklabels()) <= 10
        assert ax.get_xlabel() == "plant_sim.initial.theta_b [rad]"
        assert ax.get_ylabel() == "plant_sim.tau_ext1.amplitude [N m]"
        assert not ax.texts                                             # 81 columns: no per-cell numbers
    assert plotting.axis_label("nominal.m_b") == "nominal.m_b [kg]"
    assert plotting.axis_label("not.a.key") == "not.a.key"
