"""mwip_identify LOG --retune: identify, then tune the law on the identified model with mwip_tune's search
(mwip_ros.cli.identify_retune), and write one parameter file: the identified nominal body and the tuned gains."""
from __future__ import annotations

import math

import pytest

from graphproc import REPO
from mwip_ros import params as P
from mwip_ros.cli import identify
from mwip_ros.core import laws
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import write_csv
from test_identify_bag import refused  # noqa: E402  (test/cli is on sys.path under pytest)

pytestmark = pytest.mark.unit

CONFIG = REPO / "config"
PAPER = CONFIG / "paper.yaml"
UNSEEN = {"m_b": 250.0, "I_b": 48.0, "l": 0.28}   # a robot the tool never saw


@pytest.fixture(scope="module")
def ident_csv(tmp_path_factory):
    """The shipped identification experiment (30 s of the chirp) on the unseen robot, as mwip_sim's CSV."""
    v = P.merged_values(P.load_param_files([PAPER, CONFIG / "identify.yaml"]))
    v.update({f"actual.{k}": x for k, x in UNSEEN.items()})
    csv = tmp_path_factory.mktemp("retune") / "identify.csv"
    write_csv(simulate(P.closed_loop(v, controller="dscndo")), csv)
    return csv


def on_the_unseen_robot(files, law="dscndo"):
    """theta_b RMS over [5, 10] s of the paper's scenario on the unseen robot with the files' nominal model and
    gains."""
    v = P.merged_values(P.load_param_files(list(files)))
    v.update({f"actual.{k}": x for k, x in UNSEEN.items()})
    r = simulate(P.closed_loop(v, controller=law))
    assert not r.fallen
    return metrics.compute(r.columns, metrics.WINDOW, v["fall_angle"]).theta_b_rms


def margin(files, law):
    v = P.merged_values(P.load_param_files(list(files)))
    cls, nominal = laws.get(law), P.physical(v, "nominal")
    return cls.stability_margin(nominal, cls.design(v, nominal, P.period(v)), P.observer_gain(v),
                                observer=cls.observer)


@pytest.mark.slow
def test_retune_writes_gains_that_satisfy_theorem_2_and_beat_the_papers(ident_csv, tmp_path, capsys):
    """A short search (3 generations of 3 per gain): the file holds the identified body (to 0.1 %) and DSCNDO's
    k1, k2, tau4, X; Theorem 2 holds with them on the identified model; on the unseen robot in the paper's scenario
    they leave a fifth of the paper's gains' theta_b RMS at most (measured: 0.00418 rad to about 1e-4)."""
    out = tmp_path / "gains.yaml"
    assert identify.main([str(ident_csv), "--params", str(PAPER), "--retune", "--maxiter", "3", "--popsize", "3",
                          "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "retuning dscndo on the identified model" in text and "Theorem 2 holds on the identified model" in text
    assert "judged on a held-out set of 8 scenarios" in text and f"wrote {out}" in text
    doc = P.load_param_file(out).sections
    assert set(doc) == {"/**", "dscndo_controller", "disturbance_observer"}
    for k, truth in UNSEEN.items():
        assert doc["/**"][f"nominal.{k}"] == pytest.approx(truth, rel=1e-3), k
    assert set(doc["dscndo_controller"]) == {"k1", "k2", "tau4"} and set(doc["disturbance_observer"]) == {"X"}
    paper = P.merged_values(P.load_param_file(PAPER))
    assert all(doc["dscndo_controller"][k] != paper[k] for k in ("k1", "k2", "tau4"))
    assert margin([PAPER, out], "dscndo") > 0   # gamma > 0 on the identified nominal model (eq. 35)
    gamma = float(text.split("gamma = ")[1].split()[0])
    assert gamma == pytest.approx(margin([PAPER, out], "dscndo"), rel=1e-3)
    tuned, before = on_the_unseen_robot([PAPER, out]), on_the_unseen_robot([PAPER])
    assert before == pytest.approx(0.00418, rel=0.01)
    assert tuned < 0.2 * before, (tuned, before)
    assert "# --retune: dscndo's k1, k2, tau4, X.c1, X.c4 tuned on the identified model" in out.read_text()


@pytest.mark.slow
def test_retune_another_law(ident_csv, tmp_path, capsys):
    """--law lqr_ndo tunes the LQR weights and the observer's X (no Theorem 2 for it: said so)."""
    out = tmp_path / "lqr.yaml"
    assert identify.main([str(ident_csv), "--params", str(PAPER), "--retune", "--law", "lqr_ndo", "--maxiter", "2",
                          "--popsize", "2", "--out", str(out)]) == 0
    assert "the law has no Theorem 2 condition" in capsys.readouterr().out
    doc = P.load_param_file(out).sections
    assert set(doc["dscndo_controller"]) == {"lqr.Q", "lqr.R"} and set(doc["disturbance_observer"]) == {"X"}
    assert math.isfinite(on_the_unseen_robot([PAPER, out], "lqr_ndo"))


def test_an_existing_out_is_refused_before_the_log_is_read(tmp_path, capsys):
    out = tmp_path / "gains.yaml"
    out.write_text("keep me\n")
    err = refused([str(tmp_path / "missing.csv"), "--retune", "--out", str(out)], capsys)
    assert "exists" in err and "--force" in err and out.read_text() == "keep me\n"


@pytest.mark.parametrize("argv, words", [
    (["--law", "mpc"], "--law: one of dsc, dscndo, lqr, lqr_ndo, smc, smc_ndo"),
    (["--drive"], "not with --drive"),
    (["--maxiter", "0"], "--maxiter and --popsize: 1 or more"),
    (["--bounds", "Xc1=0.02:1.3"], "--bounds: 'Xc1' is not tuned here; tuned: k1, k2, tau4, X.c1, X.c4"),
    (["--bounds", "X.c1=20:10"], "--bounds: X.c1: the range [20, 10] is empty"),
])
def test_retune_mistakes_are_one_line(ident_csv, tmp_path, capsys, argv, words):
    out = tmp_path / "o.yaml"
    assert words in refused([str(ident_csv), "--retune", *argv, "--out", str(out)], capsys)
    assert not out.exists()


def test_bounds_need_retune(ident_csv, tmp_path, capsys):
    out = tmp_path / "o.yaml"
    assert "--bounds: the search bounds of --retune; give --retune too" in refused(
        [str(ident_csv), "--bounds", "k1=1:2", "--out", str(out)], capsys)
    assert not out.exists()


def test_retune_searches_within_the_bounds_given(ident_csv, tmp_path, capsys):
    """A small robot's observer must stay below 2 / (h max eig(M_hat^-1)) (Upkie: X.c1 < 1.3, docs/hardware-upkie.md):
    --bounds narrows the search as mwip_tune's does; here a band no default search would keep."""
    out = tmp_path / "gains.yaml"
    assert identify.main([str(ident_csv), "--params", str(PAPER), "--retune", "--maxiter", "1", "--popsize", "2",
                          "--bounds", "X.c1=150:160", "k1=7:7.5", "--out", str(out)]) == 0
    capsys.readouterr()
    v = P.merged_values(P.load_param_files([PAPER, out]))
    assert 150.0 <= v["X"][0] <= 160.0 and 7.0 <= v["k1"] <= 7.5


def test_help_names_the_retune_options(capsys):
    with pytest.raises(SystemExit) as done:
        identify.main(["--help"])
    assert done.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for word in ("--retune", "--law LAW", "--maxiter N", "--popsize N", "--bounds", "Theorem 2", "held-out set",
                 "ROS 2 parameter file"):
        assert word in text, word


def test_gains_that_break_theorem_2_are_never_written(ident_csv, tmp_path, capsys, monkeypatch):
    """Were the search to end on gains that break Theorem 2 (every candidate inadmissible: gamma <= 0, or NaN), the
    tool says so and writes nothing."""
    from mwip_ros.cli import identify_retune
    real = identify_retune.retune

    def broken(*a, **k):
        r = real(*a, **k)
        r.margin = -0.5
        return r
    monkeypatch.setattr(identify_retune, "retune", broken)
    out = tmp_path / "gains.yaml"
    assert identify.main([str(ident_csv), "--params", str(PAPER), "--retune", "--maxiter", "1", "--popsize", "1",
                          "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()   # the search's progress, then the one line that refuses
    assert err[0].startswith("mwip_identify: generation 1/1: J = ") and len(err) == 2
    assert err[-1].startswith("mwip_identify: error: --retune: no gains of dscndo")
    assert "satisfy Theorem 2 on the identified model (gamma = -0.5 at the best); nothing written" in err[-1]
    assert not out.exists()


def test_retune_from_the_raw_log_alone(tmp_path, capsys):
    """--raw --retune: the body from the raw sensors alone (a CSV whose state columns are NaN, as a robot's log),
    then the retune on it: the file's nominal body is the unseen robot's within 3 %, and Theorem 2 holds with the
    written gains on it."""
    import numpy as np
    v = P.merged_values(P.load_param_files([PAPER, CONFIG / "sensors_raw_realistic.yaml", CONFIG / "identify.yaml"]))
    v.update({f"actual.{k}": x for k, x in UNSEEN.items()})
    run = simulate(P.closed_loop(v, controller="dscndo", duration=15.0))
    assert not run.fallen
    for k in ("theta_w", "theta_b", "dtheta_w", "dtheta_b", "theta_w_hat", "theta_b_hat", "dtheta_w_hat",
              "dtheta_b_hat"):
        run.columns[k] = np.full_like(run.columns[k], np.nan)   # nothing but the raw samples and the torque
    csv, out = tmp_path / "raw.csv", tmp_path / "gains.yaml"
    write_csv(run, csv)
    assert identify.main([str(csv), "--params", str(PAPER), "--raw", "--retune", "--maxiter", "2", "--popsize", "3",
                          "--out", str(out)]) == 0, capsys.readouterr().err
    assert "Theorem 2 holds on the identified model" in capsys.readouterr().out
    doc = P.load_param_file(out).sections
    for k, truth in UNSEEN.items():
        assert doc["/**"][f"nominal.{k}"] == pytest.approx(truth, rel=0.03), k
    assert margin([PAPER, out], "dscndo") > 0
