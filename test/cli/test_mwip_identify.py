"""mwip_identify on CSVs of the real plant written in a tmp dir (docs/theory.md 6.9)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from mathfixtures import P_FILE
from mwip_ros import params as P
from mwip_ros.cli.identify import main
from mwip_ros.core.identification.excitation import Excitation, ExcitationConfig
from mwip_ros.core.control.lqr import lqr_gain, lqr_u
from mwip_ros.core.plants.model import Sinusoid
from mwip_ros.core.plants.plant import PlantSim
from mwip_ros.core.closed_loop.trajectory import Trajectory
from mwip_ros.runs import write_csv

pytestmark = pytest.mark.unit

VALUES = P.merged_values(P.load_param_files([P_FILE]))
BASE = P.plant_config(VALUES)
ROBOT = replace(BASE.actual, m_b=250.0, I_b=12.0, l=0.15)


def write_log(path, exc, duration=12.0, extra=None):
    """An LQR-balanced run of ROBOT with ``exc`` on the command and no tau_ext, as mwip_sim's CSV columns."""
    cfg = replace(BASE, actual=ROBOT, tau_ext1=Sinusoid(0.0, 2.0, math.pi / 2), tau_ext2=Sinusoid(0.0, 1.0, 0.0),
                  initial=BASE.initial._replace(theta_b=0.0))
    K = lqr_gain(BASE.nominal, cfg.h, VALUES["lqr.Q"], VALUES["lqr.R"])
    ex, plant, rows = Excitation(exc, cfg.h), PlantSim(cfg), []
    for k in range(int(round(duration / cfg.h)) + 1):
        u = lqr_u(K, plant.x) + ex.at(k)
        rows.append((plant.t, *plant.x, u))
        plant.step(u)
    a = np.array(rows).T
    cols = dict(zip(("t", "theta_w", "theta_b", "dtheta_w", "dtheta_b", "u"), a))
    if extra:   # columns beyond the trajectory table's (u_applied, which the lead's plant adds): written here
        cols.update(extra(cols))
        np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
                   fmt="%.17g")
    else:
        write_csv(Trajectory("ident", cols, False, cfg.h), path)
    return path


CHIRP = ExcitationConfig("chirp", 20.0, 0.1, 5.0, 12.0)


@pytest.fixture(scope="module")
def chirp_csv(tmp_path_factory):
    return write_log(tmp_path_factory.mktemp("ident") / "ident.csv", CHIRP)


def test_identifies_and_writes_the_overlay(chirp_csv, tmp_path, capsys):
    out = tmp_path / "identified.yaml"
    assert main([str(chirp_csv), "--params", str(P_FILE), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for word in ("m_b", "I_b", "l ", "95 % CI", "residual RMS", "row 1", "row 2", "condition number", "D_w", "D_b",
                 "G_b check", "'u'", f"wrote {out}"):
        assert word in text, word
    doc = P.load_param_file(out)
    assert set(doc.sections) == {"/**"}
    got = doc.sections["/**"]
    assert set(got) == {"nominal.m_b", "nominal.I_b", "nominal.l"}
    assert got["nominal.m_b"] == pytest.approx(250.0, rel=0.03)
    assert got["nominal.I_b"] == pytest.approx(12.0, rel=0.03)
    assert got["nominal.l"] == pytest.approx(0.15, rel=0.03)
    merged = P.merged_values(P.load_param_files([P_FILE, out]))   # the overlay over the base
    assert merged["nominal.m_b"] == got["nominal.m_b"] and merged["nominal.m_w"] == 29.0


def test_u_applied_is_preferred(tmp_path, capsys):
    """A CSV with the torque that acted in u_applied: the command u (here wrong on purpose) is not used."""
    log = write_log(tmp_path / "motor.csv", CHIRP, extra=lambda c: {"u_applied": c["u"], "u": 0.5 * c["u"]})
    out = tmp_path / "o.yaml"
    assert main([str(log), "--out", str(out)]) == 0
    assert "'u_applied'" in capsys.readouterr().out
    assert P.load_param_file(out).sections["/**"]["nominal.m_b"] == pytest.approx(250.0, rel=0.03)


def _refused(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("mwip_identify: error: ")
    return err


def test_a_log_without_excitation_is_refused(tmp_path, capsys):
    log = write_log(tmp_path / "rest.csv", ExcitationConfig(), duration=5.0)
    out = tmp_path / "o.yaml"
    assert "not excited" in _refused([str(log), "--out", str(out)], capsys)
    assert not out.exists()


def test_a_short_log_is_refused(tmp_path, capsys):
    log = write_log(tmp_path / "short.csv", CHIRP, duration=1.0)
    assert "too short" in _refused([str(log), "--out", str(tmp_path / "o.yaml")], capsys)


def test_a_window_too_short_is_refused(chirp_csv, tmp_path, capsys):
    assert "too short" in _refused([str(chirp_csv), "--window", "0", "1", "--out", str(tmp_path / "o.yaml")],
                                   capsys)


def test_an_existing_out_needs_force(chirp_csv, tmp_path, capsys):
    out = tmp_path / "o.yaml"
    out.write_text("keep me\n")
    err = _refused([str(tmp_path / "missing.csv"), "--out", str(out)], capsys)   # refused before the log is read
    assert "exists" in err and "--force" in err and out.read_text() == "keep me\n"
    assert main([str(chirp_csv), "--out", str(out), "--force"]) == 0
    assert "nominal" in out.read_text()


def test_bad_inputs_are_one_line(tmp_path, capsys):
    assert "no such file" in _refused([str(tmp_path / "missing.csv"), "--out", str(tmp_path / "o.yaml")], capsys)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x\n0,1\n")
    assert "theta_w" in _refused([str(bad), "--out", str(tmp_path / "o.yaml")], capsys)


def test_help_is_complete(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    for word in ("BAG_OR_CSV", "--params", "--out", "--force", "--window", "--run", "--cutoff", "u_applied",
                 "exit status"):
        assert word in text, word


def test_a_log_with_every_row_twice_gives_the_logs_own_result(chirp_csv, tmp_path, capsys):
    """Repeated periods count once: the same m_b line as the log itself, and the count said (old code: the
    interval shrank, the rows counted as independent periods)."""
    assert main([str(chirp_csv), "--params", str(P_FILE), "--out", str(tmp_path / "a.yaml")]) == 0
    once = capsys.readouterr().out
    lines = chirp_csv.read_text().splitlines()
    twice = tmp_path / "twice.csv"
    twice.write_text("\n".join([lines[0]] + [ln for ln in lines[1:] for _ in range(2)]) + "\n")
    assert main([str(twice), "--params", str(P_FILE), "--out", str(tmp_path / "b.yaml")]) == 0
    text = capsys.readouterr().out
    n = len(lines) - 1
    assert f"({n} repeated row(s) counted once)" in text
    m_b = [ln for ln in once.splitlines() if ln.strip().startswith("m_b")]
    assert len(m_b) == 1 and m_b[0] in text.splitlines()


def test_the_g_b_check_gives_no_verdict_from_nan():
    """'within' / 'OUTSIDE' its 95 % interval is a verdict: not from a NaN difference or interval (issue 30)."""
    from mwip_ros.cli.identify import g_b_verdict
    from mwip_ros.core.identification.identify import Estimate
    assert g_b_verdict(Estimate(0.1, 1.0)) == "within" and g_b_verdict(Estimate(5.0, 1.0)) == "OUTSIDE"
    for chk in (Estimate(math.nan, 1.0), Estimate(0.1, math.nan), Estimate(0.1, math.inf)):
        assert g_b_verdict(chk) == "with no verdict (not a number)", chk


@pytest.mark.parametrize("drive", [None, {"torque_constant": 2.5, "resistance": 0.2, "current_limit": 48.0}],
                         ids=["motor_realistic", "other-drive"])
def test_the_shipped_drive_experiment_identifies_the_drive(drive, tmp_path, capsys):
    """config/identify_drive.yaml on the paper's robot under DSCNDO stays upright, reaches both limits and
    mwip_identify --drive gives K_t, R, I_max within 5 % (V_max from the base files), written as plant_sim's motor.*"""
    import yaml
    from graphproc import REPO
    from mwip_ros.core.closed_loop.sim import simulate
    files = [REPO / "config" / f for f in ("paper.yaml", "motor_realistic.yaml")]
    if drive:
        overlay = tmp_path / "drive_truth.yaml"
        overlay.write_text(yaml.safe_dump({"plant_sim": {"ros__parameters": {"motor": drive}}}))
        files.append(overlay)
    experiment = [REPO / "config" / "identify_drive.yaml"]
    if drive:   # the top speed 1 rad/s above (V_max - R I_max) / K_t of this drive, as the config's comment says
        top = round(0.254 * ((48.0 - drive["resistance"] * drive["current_limit"]) / drive["torque_constant"] + 1), 2)
        speed = tmp_path / "speed.yaml"
        speed.write_text(yaml.safe_dump({"dscndo_controller": {"ros__parameters": {"motion": {
            "max_speed": top, "max_accel": top / 10, "profile": [0.0, top, 10.0, 0.0]}}}}))
        experiment.append(speed)
    v = P.merged_values(P.load_param_files([*files, *experiment]))
    traj = simulate(P.closed_loop(v, controller="dscndo"))
    csv = tmp_path / "drive.csv"
    write_csv(traj, csv)
    assert not traj.fallen and len(traj) == 4801 and np.max(np.abs(traj["theta_b"])) < 0.5   # 24 s, upright
    out = tmp_path / "drive.yaml"
    assert main([str(csv), "--params", *map(str, files), "--drive", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "on the current limit" in text and "on the voltage limit" in text
    got = yaml.safe_load(out.read_text())["plant_sim"]["ros__parameters"]["motor"]
    for k in ("torque_constant", "resistance", "current_limit"):
        assert got[k] == pytest.approx(v[f"motor.{k}"], rel=0.05), k
    assert got["voltage_limit"] == v["motor.voltage_limit"]


def test_validate_on_another_log(chirp_csv, tmp_path, capsys):
    """--validate: the model identified on the chirp predicts a PRBS run's pitch (open loop, 1 s windows) far better
    than the paper's nominal model it started from, and within 0.5 deg RMS."""
    import re
    log2 = write_log(tmp_path / "prbs.csv", ExcitationConfig("prbs", 20.0, f1=5.0, duration_s=12.0, seed=4))
    out = tmp_path / "identified.yaml"
    assert main([str(chirp_csv), "--params", str(P_FILE), "--out", str(out), "--validate", str(log2)]) == 0
    text = capsys.readouterr().out
    assert "over 12 windows of 1 s" in text
    pattern = r"(identified|nominal) +pitch error RMS \S+ rad \((\S+) deg\), worst \S+ rad \((\S+) deg"
    got = {m[0]: (float(m[1]), float(m[2])) for m in re.findall(pattern, text)}
    assert set(got) == {"identified", "nominal"}
    assert got["identified"][0] < 0.5 and got["identified"][0] < 0.1 * got["nominal"][0]
    assert got["identified"][1] < got["nominal"][1]


def test_validate_refuses_a_missing_log(chirp_csv, tmp_path, capsys):
    out = tmp_path / "identified.yaml"
    assert main([str(chirp_csv), "--params", str(P_FILE), "--out", str(out), "--validate",
                 str(tmp_path / "nothing.csv")]) == 2
    assert "--validate" in capsys.readouterr().err


def test_raw_identifies_from_the_raw_sensors_alone(tmp_path, capsys):
    """--raw on a CSV of the realistic raw sensors (a robot that is not the paper's, its IMU lower and its bias
    negative), 15 s of the shipped chirp: the overlay is the true body to 3 %, and the tool never reads the state:
    the CSV has no estimate and its state columns are not a number."""
    from graphproc import REPO
    from mwip_ros.core.closed_loop.sim import simulate
    files = [REPO / "config" / f for f in ("paper.yaml", "sensors_raw_realistic.yaml", "identify.yaml")]
    v = P.merged_values(P.load_param_files(files))
    v.update({"actual.m_b": 250.0, "actual.I_b": 50.0, "actual.l": 0.25, "sensors.imu.offset": 0.2,
              "sensors.imu.gyro_bias": -0.01})
    c = simulate(P.closed_loop(v, controller="dscndo")).columns
    names = ("t", "gyro", "accel_x", "accel_z", "encoder", "encoder_rate", "u_applied")
    hidden = ("theta_w", "theta_b", "dtheta_w", "dtheta_b", "u")    # a run's CSV has them: not a number here
    csv = tmp_path / "raw.csv"
    table = np.column_stack([c[k] for k in names] + [np.full(len(c["t"]), np.nan)] * len(hidden))
    np.savetxt(csv, table, delimiter=",", header=",".join(names + hidden), comments="", fmt="%.17g")
    out = tmp_path / "identified.yaml"
    assert main([str(csv), "--params", str(files[0]), "--raw", "--window", "0", "15", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    for word in ("raw sensors only", "gyro_bias", "imu_offset", "residual RMS: gyro"):
        assert word in text, word
    got = P.load_param_file(out).sections["/**"]
    for k, truth in (("m_b", 250.0), ("I_b", 50.0), ("l", 0.25)):
        assert got[f"nominal.{k}"] == pytest.approx(truth, rel=0.03), k
    cond = float(text.split("condition number ")[1].split()[0])
    assert 1.0 < cond < 100.0, text        # the chirp tells the seven apart (about 7 on these robots)
    assert main([str(csv), "--params", str(files[0]), "--raw", "--window", "0", "15", "--max-condition", "2",
                 "--out", str(tmp_path / "strict.yaml"), "--force"]) == 2
    assert f"ill-conditioned: the condition number of the body's and sensors' columns is {cond:.4g}" in \
        capsys.readouterr().err and not (tmp_path / "strict.yaml").exists()


def test_raw_validate_on_another_raw_log(tmp_path, capsys):
    """--raw --validate: a robot that is not the paper's (heavy, its IMU high, a negative bias) identified from 15 s of
    its raw chirp log predicts its own 12 s PRBS run over 1 s windows, each start fitted to the window's first 0.2 s
    of raw samples: within 0.5 deg RMS of the true pitch (core.identification.identify_validate.raw_prediction_errors)
    and, in the tool against the log's estimated pitch, far better than the paper's nominal body."""
    import re

    from graphproc import REPO
    from mwip_ros.core.identification.identify_raw import identify_raw
    from mwip_ros.core.identification.identify_validate import raw_prediction_errors
    from mwip_ros.core.closed_loop.sim import simulate
    from mwip_ros.runs import write_csv
    files = [REPO / "config" / f for f in ("paper.yaml", "sensors_raw_realistic.yaml", "identify.yaml")]
    robot = {"actual.m_b": 360.0, "actual.I_b": 80.0, "actual.l": 0.35, "sensors.imu.offset": 0.45,
             "sensors.imu.gyro_bias": -0.02}
    logs, cols = {}, {}
    for name, over in (("chirp", {"duration_s": 15.0}),
                       ("prbs", {"duration_s": 12.0, "excitation.type": "prbs", "excitation.duration_s": 12.0,
                                 "excitation.seed": 4, "seed": 9})):
        v = dict(P.merged_values(P.load_param_files(files)), **robot, **over)
        run = simulate(P.closed_loop(v, controller="dscndo"))
        assert not run.fallen
        logs[name], cols[name] = tmp_path / f"{name}.csv", run.columns
        write_csv(run, logs[name])
    raw = ("gyro", "accel_x", "accel_z", "encoder", "encoder_rate", "u_applied")
    paper = P.physical(P.merged_values(P.load_param_file(files[0])), "nominal")
    c, d = cols["chirp"], cols["prbs"]
    fit = identify_raw(c["t"], *(c[k] for k in raw), known=paper, start=paper, imu_offset=0.3)
    g = fit.values
    truth = {name: raw_prediction_errors(d["t"], *(d[k] for k in raw), d["theta_b"], p, g["D_w"], g["D_b"],
                                         g["gyro_bias"], g["imu_offset"])
             for name, p in (("identified", fit.physical()), ("nominal", paper))}
    assert np.degrees(truth["identified"].rms) < 0.5 < np.degrees(truth["nominal"].rms), truth   # 0.28 / 7.8 deg
    assert main([str(logs["chirp"]), "--params", str(files[0]), "--raw", "--out", str(tmp_path / "o.yaml"),
                 "--validate", str(logs["prbs"])]) == 0
    text = capsys.readouterr().out
    assert "over 12 windows of 1 s, each from a start fitted to its first 0.2 s of raw samples" in text
    pattern = r"(identified|nominal) +pitch error RMS \S+ rad \((\S+) deg\), worst \S+ rad \((\S+) deg"
    got = {m[0]: (float(m[1]), float(m[2])) for m in re.findall(pattern, text)}
    assert set(got) == {"identified", "nominal"}
    assert got["identified"][0] < got["nominal"][0] / 3 and got["identified"][1] < got["nominal"][1], got


def test_raw_needs_the_raw_columns(chirp_csv, tmp_path, capsys):
    assert main([str(chirp_csv), "--params", str(P_FILE), "--raw", "--out", str(tmp_path / "o.yaml")]) == 2
    assert "--raw is for a log of the raw sensors" in capsys.readouterr().err
