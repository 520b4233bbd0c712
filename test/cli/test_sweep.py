"""mwip_sweep as a user runs it: outputs, progress, bad specs (exit 2, nothing written), Ctrl-C, --write-params."""
import csv
import json
import signal
import subprocess
import sys
import time

import pytest
import yaml

from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep.results import read_results

# tiers per test: the two that run several whole sweeps (worker pools, figures) are e2e

BASE = str(default_params_file())


def write_spec(path, **over):
    doc = {"base": BASE, "controllers": ["dsc", "dscndo"], "duration_s": 2.0, "metrics_window_s": [1.0, 2.0],
           "seed": 5, "samples": 6,
           "vary": {"plant_sim.actual.m_b": {"scale": [0.7, 1.3]},
                    "plant_sim.initial.theta_b": {"linspace": [-1.0, 1.0, 5]},
                    "plant_sim.torque_limit": {"values": [300.0]}}}
    doc.update(over)
    path.write_text(yaml.safe_dump(doc))
    return path


def sweep(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "mwip_ros.cli.sweep", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.cli
def test_a_sweep_writes_rows_summary_and_figures(tmp_path):
    spec = write_spec(tmp_path / "s.yaml")
    r = sweep(spec, "--out", tmp_path / "out", "--workers", "1", "--chunk", "8")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out"
    with open(out / "results.csv") as f:
        head = next(csv.reader(f))
    assert head == ["scenario", "seed", "controller", "plant_sim.actual.m_b", "plant_sim.initial.theta_b",
                    "plant_sim.torque_limit", "upright",
                    "t_fall", "failure", "theta_b_p2p", "theta_b_rms", "max_abs_theta_b", "u_rms", "tau_hat1_err_rms",
                    "tau_hat2_err_rms"]
    cols = read_results(out / "results.csv")
    assert len(cols["scenario"]) == 5 * 6 * 2
    assert sorted(set(cols["plant_sim.initial.theta_b"])) == [-1.0, -0.5, 0.0, 0.5, 1.0]
    # with |u| <= 300 N m the robot falls from 1 rad and recovers from upright
    up = {(th, c): u for th, c, u in zip(cols["plant_sim.initial.theta_b"], cols["controller"], cols["upright"])}
    assert up[(0.0, "dscndo")] and not up[(1.0, "dsc")]
    doc = json.loads((out / "summary.json").read_text())
    for law in ("dsc", "dscndo"):
        e = doc["controllers"][law]
        sel = [u for u, c in zip(cols["upright"], cols["controller"]) if c == law]
        assert e["runs"] == 30 and e["upright"] == sum(sel)
        assert e["region_of_attraction_theta_b0"] in (0.0, 0.5)
        assert set(e["metrics"]["theta_b_rms"]) == {"median", "p90", "max"}
    md = (out / "summary.md").read_text()
    assert "| dscndo |" in md and "Region of attraction" in md
    for fig in ("upright_map.png", "theta_b_rms.png", "roa.png"):
        assert (out / fig).stat().st_size > 5_000, fig
    assert "scenario-steps/s" in r.stderr   # plain progress lines off a terminal
    assert (out / "sweep.json").is_file() and (out / "base.yaml").is_file()


@pytest.mark.e2e
def test_results_csv_is_the_same_file_however_many_workers_ran_it(tmp_path):
    spec = write_spec(tmp_path / "s.yaml", samples=7)
    for w in ("1", "2"):
        r = sweep(spec, "--out", tmp_path / w, "--workers", w, "--chunk", "6", "--no-figures")
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "1" / "results.csv").read_bytes() == (tmp_path / "2" / "results.csv").read_bytes()
    assert "2 worker processes" in r.stderr


@pytest.mark.parametrize("over, words", [
    ({"vary": {"plant_sim.actual.mb": {"scale": [0.7, 1.3]}}}, "did you mean 'actual.m_b'"),
    ({"vary": {"dscndo_controller.actual.m_b": {"grid": [1.0]}}}, "belongs under plant_sim"),
    ({"vary": {"dscndo_controller.k1": {"uniform": [5.0, 1.0]}}}, "low < high"),
    ({"vary": {"dscndo_controller.k1": {"grid": []}}}, "non-empty list"),
    ({"controlers": ["dsc"]}, "did you mean 'controllers'"),
])
@pytest.mark.cli
def test_a_bad_spec_exits_2_naming_the_key_before_any_work(tmp_path, over, words):
    spec = write_spec(tmp_path / "s.yaml", **over)
    r = sweep(spec, "--out", tmp_path / "out", "--workers", "1")
    assert r.returncode == 2 and words in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.cli
def test_an_unreadable_spec_and_existing_results_exit_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("vary: {a: [1, 2\n")
    r = sweep(bad, "--out", tmp_path / "o")
    assert r.returncode == 2 and "not valid YAML" in r.stderr
    spec = write_spec(tmp_path / "s.yaml", samples=1, vary={})
    assert sweep(spec, "--out", tmp_path / "o2", "--workers", "1").returncode == 0
    r = sweep(spec, "--out", tmp_path / "o2", "--workers", "1")
    assert r.returncode == 2 and "--force" in r.stderr


@pytest.mark.cli
def test_ctrl_c_keeps_every_finished_row_readable(tmp_path):
    spec = write_spec(tmp_path / "s.yaml", samples=400, duration_s=4.0, metrics_window_s=[2.0, 4.0])
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "mwip_ros.cli.sweep", str(spec), "--out", str(out), "--workers", "1",
                          "--chunk", "50"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end:   # wait for the first finished chunk
            if (out / "results.csv").exists() and len((out / "results.csv").read_text().splitlines()) > 1:
                break
            time.sleep(0.05)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(10)
    assert p.returncode == 130, err
    cols = read_results(out / "results.csv")
    n = len(cols["scenario"])
    assert 50 <= n < 4000 and n % 50 == 0 and "interrupted" in err and f"{n:,} of 4,000 rows" in err


@pytest.mark.cli
def test_write_params_gives_the_rows_scenario_to_mwip_sim(tmp_path):
    spec = write_spec(tmp_path / "s.yaml", samples=2, duration_s=4.0, metrics_window_s=[2.0, 4.0],
                      vary={"plant_sim.actual.m_b": {"scale": [0.7, 1.3]},
                            "dscndo_controller.k1": {"grid": [4.0, 8.0]}})
    out = tmp_path / "out"
    assert sweep(spec, "--out", out, "--workers", "1", "--no-figures").returncode == 0
    f = tmp_path / "s3.yaml"
    r = sweep("--results", out, "--scenario", 3, "--controller", "dsc", "--write-params", f)
    assert r.returncode == 0, r.stderr
    cols = read_results(out / "results.csv")
    j = [k for k, (s, c) in enumerate(zip(cols["scenario"], cols["controller"])) if s == 3 and c == "dsc"][0]
    sim = subprocess.run([sys.executable, "-m", "mwip_ros.cli.sim", "--params", str(f), "-q", "--window", "2", "4",
                          "--csv", str(tmp_path / "run.csv")], capture_output=True, text=True, timeout=120)
    assert sim.returncode == 0, sim.stderr
    from mwip_ros.core.closed_loop import metrics
    from mwip_ros.runs import read_csv
    run = read_csv(tmp_path / "run.csv")
    m = metrics.compute(run.columns, (2.0, 4.0), 1.0472)
    assert abs(m.theta_b_rms - cols["theta_b_rms"][j]) < 1e-9 and abs(m.u_rms - cols["u_rms"][j]) < 1e-9
    assert "use_observer: false" in f.read_text() and "k1: 8.0" in f.read_text()   # scenario 3: k1 = 8.0, dsc
    r = sweep("--results", out, "--scenario", 99, "--write-params", f)
    assert r.returncode == 2 and "no row for scenario 99" in r.stderr


@pytest.mark.e2e
def test_no_output_of_mwip_sweep_is_overwritten_without_force(tmp_path):
    spec = write_spec(tmp_path / "s.yaml", samples=1, vary={})
    out = tmp_path / "out"
    assert sweep(spec, "--out", out, "--workers", "1").returncode == 0
    assert (out / "theta_b_rms.png").is_file()
    # --write-params: an existing file is refused (one line), kept, and written with --force
    f = tmp_path / "s0.yaml"
    f.write_text("mine\n")
    r = sweep("--results", out, "--scenario", 0, "--write-params", f)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--force" in r.stderr
    assert f.read_text() == "mine\n"
    r = sweep("--results", out, "--scenario", 0, "--write-params", f, "--force")
    assert r.returncode == 0 and "plant_sim:" in f.read_text()
    # --plot-rms the same way
    png = tmp_path / "rms.png"
    png.write_bytes(b"old")
    assert sweep("--results", out, "--plot-rms", png).returncode == 2 and png.read_bytes() == b"old"
    assert sweep("--results", out, "--plot-rms", png, "--force").returncode == 0 and png.read_bytes() != b"old"
    # an --out holding any output of a sweep (not only results.csv) is refused
    other = tmp_path / "other"
    other.mkdir()
    (other / "summary.md").write_text("old summary")
    r = sweep(spec, "--out", other, "--workers", "1")
    assert r.returncode == 2 and "summary.md" in r.stderr and (other / "summary.md").read_text() == "old summary"
    # --force: what this run does not write (its figures, with --no-figures) is not left from the last run
    assert sweep(spec, "--out", out, "--workers", "1", "--no-figures", "--force").returncode == 0
    assert not (out / "theta_b_rms.png").exists() and (out / "results.csv").is_file()
