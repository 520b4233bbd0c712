"""sweep.results' summaries: units on every metric, and each law's medians as ratios to DSCNDO's.

The results table is written here with known values, so the expected medians and ratios are plain arithmetic."""
import json

import pytest

from mwip_ros.sweep import results as R

pytestmark = pytest.mark.unit


def table(laws=("dsc", "dscndo", "lqr")):
    """Three upright scenarios per law: theta_b RMS base * (1, 2, 3), u RMS 10 * base * (1, 2, 3); one fallen row."""
    base = {"dsc": 5.0, "dscndo": 1.0, "lqr": 12.0, "lqr_ndo": 2.5}
    cols = {k: [] for k in ("scenario", "seed", "controller", "upright", "t_fall", *R.METRICS)}
    for law in laws:
        for i, f in enumerate((1.0, 2.0, 3.0, 100.0)):
            up = f < 100
            vals = {"theta_b_p2p": 3 * base[law] * f, "theta_b_rms": base[law] * f, "max_abs_theta_b": f,
                    "u_rms": 10 * base[law] * f, "tau_hat1_err_rms": float("nan"), "tau_hat2_err_rms": 1.0}
            for k, v in dict(scenario=i, seed=i, controller=law, upright=up, t_fall=float("nan") if up else 0.5,
                             **vals).items():
                cols[k].append(v)
    return cols


SPEC = {"name": "t", "duration_s": 2.0, "window": [1.0, 2.0], "varied": {}}


def test_the_summary_gives_units_and_each_laws_medians_over_dscndos(tmp_path):
    doc = R.summarize(table(), SPEC)
    assert doc["units"] == {"theta_b_p2p": "rad", "theta_b_rms": "rad", "max_abs_theta_b": "rad", "u_rms": "N m",
                            "tau_hat1_err_rms": "N m", "tau_hat2_err_rms": "N m"}
    assert doc["ratios"]["reference"] == "dscndo"
    # medians over the upright rows: base * 2 for theta_b, 10 * base * 2 for u: the ratio is base / 1
    assert doc["ratios"]["laws"]["dsc"] == {"theta_b_p2p": pytest.approx(5.0), "theta_b_rms": pytest.approx(5.0),
                                            "u_rms": pytest.approx(5.0)}
    assert doc["ratios"]["laws"]["lqr"]["theta_b_rms"] == pytest.approx(12.0)
    assert "dscndo" not in doc["ratios"]["laws"]
    R.write_summary(doc, tmp_path)

    def refuse(c):
        raise ValueError(c)
    back = json.loads((tmp_path / "summary.json").read_text(), parse_constant=refuse)
    assert back["controllers"]["dsc"]["metrics"]["tau_hat1_err_rms"]["median"] is None
    md = (tmp_path / "summary.md").read_text()
    header = next(line for line in md.splitlines() if line.startswith("| law | upright"))
    for m, unit in doc["units"].items():
        assert f"{m} [{unit}]" in header
    assert "| dsc | 5.00 | 5.00 | 5.00 |" in md and "| lqr | 12.00 | 12.00 | 12.00 |" in md
    assert "theta_b_rms median / dscndo's [x]" in md


def test_without_dscndo_the_ratios_are_to_the_last_law_and_say_so():
    doc = R.summarize(table(("dsc", "lqr", "lqr_ndo")), SPEC)
    assert doc["ratios"]["reference"] == "lqr_ndo" and "did not run dscndo" in doc["ratios"]["why"]
    assert doc["ratios"]["laws"]["lqr"]["u_rms"] == pytest.approx(12.0 / 2.5)
    assert "did not run dscndo" in R.summary_markdown(doc)
