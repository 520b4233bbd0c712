"""A lockstep recording started by hand is complete, in any start order, without counting the recorder.

The four nodes are started as a user would (``ros2 run`` each, no ``expected_subscribers``), recorder first and in
the reverse order, beside a process that keeps a core busy, several times. Every run must end with one message per
state on every topic of the loop (a resend counted once), and the recorder saying so. Before the package's
discovery profile (mwip_ros.nodes.runtime.discovery) a recorder started first missed the plant's topics in some runs:
its one answer to the plant's first announcement was lost and the plant found it only 3 s later, after its short run
(docs/recording.md). A recording that does lack messages still says so, in its log and in the bag's metadata
(test/nodes/test_mcap_recorder.py and test/bag/test_ledger.py, in-process).
"""
import re
import sys

import pytest
import yaml

from bagcheck import decoded_messages
from graphproc import Graph
from mwip_ros.bag.ledger import GAPS_KEY

pytestmark = pytest.mark.graph

LOOP_TOPICS = ("/joint_states", "/clock", "/wheel_torque_cmd", "/disturbance_estimate", "/lumped_disturbance",
               "/controller_internals")
RUNS = 3


def _stamp(topic, msg):
    if topic == "/clock":
        return msg.clock.sec, msg.clock.nanosec
    if topic == "/wheel_torque_cmd":
        return None
    return msg.header.stamp.sec, msg.header.stamp.nanosec


def _start_cost_s(plant_log: str) -> float:
    """Seconds from the plant's first line to its first state ('starting lockstep run'), from the log stamps."""
    times = re.findall(r"\[(\d+\.\d+)\] \[plant_sim\]: (.*)", plant_log)
    t0 = float(times[0][0])
    return next(float(t) for t, text in times if "starting lockstep run" in text) - t0


@pytest.mark.parametrize("order", ["user", "reverse", "user, split"])
def test_every_lockstep_run_is_recorded_whole(tmp_path, order):
    """``split``: the recorder splits its bag every simulated second (max_bagfile_duration, log time from /clock):
    the ledger judges the whole recording, and the files read as one run. No run counts the recorder in the plant's
    expected_subscribers (scripts/run_experiment.sh still does, as a belt to these braces)."""
    results = []
    split = ("-p", "max_bagfile_duration:=1") if order.endswith("split") else ()
    for run in range(RUNS if not split else 1):
        bag = tmp_path / f"bag{run}"
        with Graph(tmp_path) as g:
            g.start("busy", label=f"busy{run}", params=None,
                    cmd=[sys.executable, "-c", "import time\nend = time.time() + 120\nwhile time.time() < end: pass"])
            starts = [("mcap_recorder", ("-p", f"output:={bag}", "-p", "use_sim_time:=true", *split)),
                      ("disturbance_observer", ()), ("dscndo_controller", ()),
                      ("plant_sim", ("-p", "duration_s:=5.0"))]
            if order == "reverse":
                starts.reverse()
            procs = {name: g.start(name, *args, label=f"{name}{run}") for name, args in starts}
            assert procs["plant_sim"].wait(120) == 0, procs["plant_sim"].output()
            for name in ("disturbance_observer", "dscndo_controller", "mcap_recorder"):
                assert procs[name].stop() == 0, procs[name].output()
            plant_log, rec_log = procs["plant_sim"].output(), procs["mcap_recorder"].output()
        states = int(re.search(r"lockstep run: (\d+) periods", plant_log).group(1))
        stamps = {t: set() for t in LOOP_TOPICS}
        counts = {t: 0 for t in LOOP_TOPICS}
        for topic, _type, _t, msg in decoded_messages(bag):
            if topic in counts:
                counts[topic] += 1
                stamps[topic].add(_stamp(topic, msg))
        unique = {t: (len(stamps[t]) if t != "/wheel_torque_cmd" else counts[t]) for t in LOOP_TOPICS}
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        if split:
            assert meta["relative_file_paths"] == [f"{bag.name}_{i}.mcap" for i in range(len(meta["files"]))]
            assert len(meta["files"]) >= 4, meta["files"]   # 5 s simulated
            splits = re.findall(r"split: now writing (\S+) \(file (\d+);", rec_log)   # each split said (and trimmed)
            assert splits == [(f"{bag.name}_{i}.mcap", str(i + 1)) for i in range(1, len(meta["files"]))], rec_log
            from mwip_ros.runs import read_bag_run
            run = read_bag_run(bag)   # bag -> trajectory (mwip_report, mwip_identify): every file, one run
            assert len(run) == states and run.t[0] == 0.0 and run.t[-1] == pytest.approx((states - 1) * 0.005)
        flagged = GAPS_KEY in (meta.get("custom_data") or {})
        complete = all(n == states for n in unique.values())
        results.append((order, run, states, unique, counts, flagged, round(_start_cost_s(plant_log), 2)))
        assert complete and not flagged and "lockstep recording complete" in rec_log, (unique, states, rec_log[-2000:])
    print("\n".join(map(str, results)))
