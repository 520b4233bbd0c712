"""mwip_sim --plot shades the metrics window (and marks a fall) as mwip_report's fig3.png does."""
import pytest

from mwip_ros.cli import plotting, sim

pytestmark = pytest.mark.unit


def test_the_plot_is_given_the_metrics_window_and_the_falls(tmp_path, monkeypatch, capsys):
    seen = {}
    real = plotting.fig3

    def spy(runs, path, title=None, window=None, falls=None):
        seen.update(window=window, falls=falls)
        real(runs, path, title=title, window=window, falls=falls)

    monkeypatch.setattr(plotting, "fig3", spy)
    png = tmp_path / "f.png"
    assert sim.main(["--duration", "1", "--window", "0.25", "0.75", "-q", "--plot", str(png)]) == 0
    assert tuple(seen["window"]) == (0.25, 0.75) and seen["falls"] == {} and png.stat().st_size > 10_000
    assert "wrote" in capsys.readouterr().out
