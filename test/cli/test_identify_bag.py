"""mwip_identify BAG --raw: the raw sensors of a bag (mwip_ros.cli.identify_bag), as a robot records them.

A lockstep recording of the graph gives the offline CSV's result to the bit (graph tier); bags written here from an
offline run, message by message as the plant publishes them, check each refusal (unit tier)."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from graphproc import Graph, REPO
from mwip_ros import params as P
from mwip_ros.cli import identify
from mwip_ros.cli.identify_bag import read_raw_bag
from mwip_ros.core.closed_loop.sim import simulate
from mwip_ros.runs import write_csv

CONFIG = REPO / "config"
FILES = [CONFIG / "paper.yaml", CONFIG / "sensors_raw_realistic.yaml", CONFIG / "identify.yaml"]
ROBOT = {"m_b": 280.0, "I_b": 58.0, "l": 0.29}   # not the paper's robot
DURATION = 15.0
RAW = ("gyro", "accel_x", "accel_z", "encoder", "encoder_rate")
_runs: dict = {}


def values(**over):
    v = P.merged_values(P.load_param_files(FILES))
    v.update({f"actual.{k}": x for k, x in ROBOT.items()})
    v.update({"duration_s": DURATION, "excitation.duration_s": DURATION})
    v.update(over)
    return v


def run(**over):
    """The offline run of the identification experiment on ROBOT (``over``: merged values), cached."""
    key = tuple(sorted(over.items()))
    if key not in _runs:
        _runs[key] = simulate(P.closed_loop(values(**over), controller="dscndo"))
    return _runs[key]


def write_bag(path: Path, r, twice=False, drop=(), change=None) -> Path:
    """A bag of ``r``'s raw samples as the plant publishes them: row k's imu/data_raw and wheel_encoder stamped
    k h (the encoder's effort: the torque that acted over the previous period); ``twice``: every message written
    again; ``drop``: rows whose wheel_encoder is lost; ``change``: a row whose encoder is written again, other."""
    from mwip_ros.bag import BagWriter
    from mwip_ros.msgs import layouts as L
    c = r.columns
    with BagWriter(path) as bag:
        bag.add_topic("/imu/data_raw", "sensor_msgs/msg/Imu")
        bag.add_topic("/wheel_encoder", "sensor_msgs/msg/JointState")
        for k in range(len(r)):
            stamp = k * 5_000_000
            u_prev = float(c["u_applied"][k - 1]) if k else 0.0
            imu = L.encode_imu(stamp, c["gyro"][k], c["accel_x"][k], c["accel_z"][k])
            enc = L.encode_encoder(stamp, c["encoder"][k], c["encoder_rate"][k], u_prev)
            for _ in range(2 if twice else 1):
                bag.write("/imu/data_raw", imu, stamp + 1000)
                if k not in drop:
                    bag.write("/wheel_encoder", enc, stamp + 2000)
            if k == change:
                bag.write("/wheel_encoder", L.encode_encoder(stamp, c["encoder"][k] + 1e-3, c["encoder_rate"][k],
                                                             u_prev), stamp + 3000)
    return path


def refused(argv, capsys) -> str:
    code = identify.main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith("mwip_identify: error: "), err
    return err


def fitted(text: str) -> list:
    """The printed lines of mwip_identify --raw's fit: each global with its deviation, and the residuals."""
    return [ln for ln in text.splitlines() if ln.startswith("  ")]


@pytest.mark.unit
def test_a_bag_of_the_run_reads_as_its_csv(tmp_path):
    """The reader gives the CSV's raw columns to the bit, the torque of period k from sample k + 1."""
    r = run()
    log = read_raw_bag(write_bag(tmp_path / "bag", r))
    csv = tmp_path / "run.csv"
    write_csv(r, csv)
    cols, notes = identify._load_raw(identify._parser().parse_args([str(csv), "--raw", "--out", "x.yaml"]))
    assert notes == [] and (log.duplicates, log.unpaired, log.missing_torque) == (0, 0, 0)
    for c in ("t", *RAW):
        assert np.array_equal(log.columns[c], cols[c]), c
    assert np.array_equal(log.columns["u_applied"][:-1], cols["u_applied"][:-1])
    assert math.isnan(log.columns["u_applied"][-1])   # no sample follows the last: its torque is unknown
    assert cols["t"][1] == 0.005 and cols["t"][-1] == DURATION


@pytest.mark.unit
def test_a_bag_cut_short_is_refused(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", run())
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) * 2 // 3])   # a recorder killed: no summary, the last chunk cut
    out = tmp_path / "o.yaml"
    err = refused([str(bag), "--raw", "--out", str(out)], capsys)
    assert "cut short" in err and "mwip_bag_repair" in err and not out.exists()


@pytest.mark.unit
def test_a_log_without_excitation_is_refused(tmp_path, capsys):
    """Balancing at rest (no chirp, from upright): the fit leaves the body unresolved, and says which value."""
    bag = write_bag(tmp_path / "bag", run(**{"excitation.type": "none", "initial.theta_b": 0.0}))
    out = tmp_path / "o.yaml"
    err = refused([str(bag), "--raw", "--window", "0", "5", "--out", str(out)], capsys)
    assert "not excited enough" in err and "unresolved" in err and not out.exists()


@pytest.mark.unit
def test_a_drive_saturated_throughout_is_refused(tmp_path, capsys):
    """A 15 N m torque limit from the paper's tilt: the drive sits at its limit every period until the fall."""
    r = run(torque_limit=15.0)
    assert r.fallen
    err = refused([str(write_bag(tmp_path / "bag", r)), "--raw", "--out", str(tmp_path / "o.yaml")], capsys)
    assert "saturated drive" in err and "+-15 N m" in err and "(100 %)" in err


@pytest.mark.unit
def test_every_sample_twice_counts_once_and_two_different_ones_are_refused(tmp_path, capsys):
    r = run()
    argv = ["--raw", "--window", "0", "8", "--params", str(FILES[0])]
    assert identify.main([str(write_bag(tmp_path / "once", r)), *argv, "--out", str(tmp_path / "a.yaml")]) == 0
    once = capsys.readouterr().out
    assert identify.main([str(write_bag(tmp_path / "twice", r, twice=True)), *argv,
                          "--out", str(tmp_path / "b.yaml")]) == 0
    twice = capsys.readouterr().out
    assert f"{2 * len(r)} sample(s) recorded twice counted once" in twice
    assert fitted(twice) == fitted(once) and len(fitted(once)) == 8   # the globals and the residual line
    err = refused([str(write_bag(tmp_path / "other", r, change=700)), *argv, "--out", str(tmp_path / "c.yaml")],
                  capsys)
    assert "two different wheel_encoder samples with the stamp 3500000000 ns" in err


@pytest.mark.unit
def test_a_raw_csv_with_every_row_twice_gives_its_own_result(tmp_path, capsys):
    """The same rule for a CSV: a row repeated with its values counts once (and the tool says how many)."""
    csv = tmp_path / "once.csv"
    write_csv(run(), csv)
    lines = csv.read_text().splitlines()
    twice = tmp_path / "twice.csv"
    twice.write_text("\n".join([lines[0]] + [ln for ln in lines[1:] for _ in range(2)]) + "\n")
    argv = ["--raw", "--window", "0", "12", "--params", str(FILES[0])]
    outs = []
    for log in (csv, twice):
        assert identify.main([str(log), *argv, "--out", str(tmp_path / f"{log.stem}.yaml")]) == 0
        outs.append(capsys.readouterr().out)
    assert f"({len(lines) - 1} repeated row(s) counted once)" in outs[1]
    assert fitted(outs[0]) == fitted(outs[1]) and len(fitted(outs[0])) == 8


@pytest.mark.unit
def test_periods_without_a_torque_are_left_out_of_the_fit_windows(tmp_path, capsys):
    """Three encoder samples lost at rows 700-702 (t = 3.5 s): those rows have no encoder, row 699 no torque (the
    next sample is three periods on); the window holding them is left out, the body still identified."""
    r = run()
    bag = write_bag(tmp_path / "bag", r, drop=(700, 701, 702))
    log = read_raw_bag(bag)
    assert (log.unpaired, log.missing_torque) == (3, 1) and len(log.columns["t"]) == len(r) - 3
    assert math.isnan(log.columns["u_applied"][699]) and np.isfinite(log.columns["u_applied"][:699]).all()
    out = tmp_path / "o.yaml"
    assert identify.main([str(bag), "--raw", "--window", "0", "12", "--params", str(FILES[0]), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "3 sample(s) without the other sensor's left out; 1 period(s) without a reported torque left out" in text
    assert "46 windows of 0.25 s" in text   # 47 windows in 12 s, less the one with row 699
    got = P.load_param_file(out).sections["/**"]
    for k, truth in ROBOT.items():
        assert got[f"nominal.{k}"] == pytest.approx(truth, rel=0.03), k


@pytest.mark.graph
def test_a_lockstep_bag_gives_the_offline_csvs_result_to_the_bit(tmp_path):
    """The lockstep graph with raw sensors and the recorder, 15 s of the chirp on ROBOT: the bag's raw columns are
    mwip_sim's CSV's to the bit, and so is the fit (every global, its deviation, the residuals); the CLI prints the
    same values, the body within 1 %."""
    from mwip_ros.core.identification.identify_raw import identify_raw
    robot = tmp_path / "robot.yaml"
    robot.write_text("plant_sim:\n  ros__parameters:\n    duration_s: 15.0\n    actual: {m_b: 280.0, I_b: 58.0, "
                     "l: 0.29}\ndscndo_controller:\n  ros__parameters:\n    excitation: {duration_s: 15.0}\n")
    files, bag = [*FILES, robot], tmp_path / "bag"
    with Graph(tmp_path) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", "-p", "use_sim_time:=true", params=None)
        for node in ("state_estimator", "disturbance_observer", "dscndo_controller"):
            g.start(node, "-p", "use_sim_time:=true", params=files)
        plant = g.start("plant_sim", "-p", "expected_subscribers:=3", params=files)
        assert plant.wait(120) == 0, plant.output()
        assert rec.stop(timeout=20) == 0, rec.output()
    csv = tmp_path / "sim.csv"
    write_csv(run(), csv)   # what mwip_sim --params FILES robot.yaml --controller dscndo --csv writes
    argv = ["--raw", "--params", str(FILES[0])]
    args = identify._parser().parse_args([str(csv), *argv, "--out", "x.yaml"])
    from_csv = identify._load_raw(args)[0]
    from_bag = identify._load_raw(identify._parser().parse_args([str(bag), *argv, "--out", "x.yaml"]))[0]
    assert len(from_bag["t"]) == len(from_csv["t"]) == 3001
    for c in ("t", *RAW):
        assert np.array_equal(from_bag[c], from_csv[c]), c
    assert np.array_equal(from_bag["u_applied"][:-1], from_csv["u_applied"][:-1])
    known = P.physical(P.merged_values(P.load_param_files([FILES[0]])), "nominal")
    a, b = (identify_raw(c["t"], *(c[k] for k in RAW), c["u_applied"], known=known, start=known, imu_offset=0.3)
            for c in (from_bag, from_csv))
    assert a.values == b.values and a.std == b.std and a.residual_rms == b.residual_rms
    for k, truth in ROBOT.items():
        assert a.values[k] == pytest.approx(truth, rel=0.01), k


@pytest.mark.alone
@pytest.mark.graph
def test_a_realtime_bag_identifies_the_robot(tmp_path, capsys):
    """The realtime graph with raw sensors and the recorder (wall-clock stamps, jitter, late periods), 10 s of the
    chirp on ROBOT: the bag alone identifies the body within 3 % (measured on 15 s: 280.99 kg, 57.977 kg m^2,
    0.29316 m)."""
    robot = tmp_path / "robot.yaml"
    robot.write_text("plant_sim:\n  ros__parameters:\n    duration_s: 10.0\n    actual: {m_b: 280.0, I_b: 58.0, "
                     "l: 0.29}\ndscndo_controller:\n  ros__parameters:\n    excitation: {duration_s: 10.0}\n")
    files, bag = [*FILES, robot], tmp_path / "bag"
    with Graph(tmp_path) as g:
        rec = g.start("mcap_recorder", "-p", f"output:={bag}", params=None)
        nodes = {node: g.start(node, "-p", "mode:=realtime", params=files)
                 for node in ("state_estimator", "disturbance_observer", "dscndo_controller")}
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "expected_subscribers:=3", params=files)
        assert plant.wait(60) == 0, plant.output()
        assert rec.stop(timeout=20) == 0, rec.output()
        assert nodes["state_estimator"].stop(timeout=20) == 0, nodes["state_estimator"].output()
    assert "upright" in plant.output()
    log = read_raw_bag(bag)
    # the bag holds every estimate the estimator made (a late wake of the realtime plant skips the periods it
    # missed: 17 of 2,002 after one 65 ms stall, so their count is the plant's, not a constant), and most periods
    estimated = re.search(r"estimated (\d+) samples", nodes["state_estimator"].output())
    assert estimated and len(log.columns["t"]) == int(estimated[1]) >= 1960, nodes["state_estimator"].output()
    assert log.columns["t"][0] == 0.0   # t from the first stamp, not the clock's
    out = tmp_path / "identified.yaml"
    assert identify.main([str(bag), "--raw", "--params", str(FILES[0]), "--out", str(out)]) == 0, \
        capsys.readouterr().err
    got = P.load_param_file(out).sections["/**"]
    for k, truth in ROBOT.items():
        assert got[f"nominal.{k}"] == pytest.approx(truth, rel=0.03), k
