"""A flood on the loop's side inputs cannot starve the control period (issue 46 item 2): the realtime graph (the rk4
plant, DSCNDO, motion on), flooded by one process (test/side_flooder.py, as fast as it can publish) on ``cmd_vel``
(NaN and valid Twists in turn), ``emergency_stop`` (false) and ``external_wrench`` (zero) at once, keeps its period:
the robot stays up, the driver never faults, the controller answers every state and the plant's period stays its own.

Before, each of those messages was an event in the node's executor queue, ahead of the plant's tick and the
controller's states: the plant's ticks stalled for seconds (an e-stop flood: p99 325 ms, 3.5 s at worst) and the
robot fell.  Now they are read once a period (nodes.runtime.rclpy_compat.PolledInput).  BENCHMARKS.md, "Input
floods", has the long runs (``scripts/bench_input_flood.py``).
"""
import re
import sys
from pathlib import Path

import pytest

from graphproc import PARAMS, Graph

pytestmark = pytest.mark.graph

FLOODER = Path(__file__).resolve().parents[1] / "side_flooder.py"
FLOOD_S, RUN_S = 3.0, 5.0


@pytest.mark.alone
def test_a_flood_on_every_side_input_leaves_the_realtime_loop_its_period(tmp_path):
    cfg = tmp_path / "drive.yaml"
    cfg.write_text("dscndo_controller:\n  ros__parameters:\n    motion: {enabled: true, cmd_vel_timeout_s: 0.5}\n")
    files = [PARAMS, cfg]
    with Graph(tmp_path) as g:
        g.start("disturbance_observer", "-p", "mode:=realtime", params=files)
        ctl = g.start("dscndo_controller", "-p", "mode:=realtime", params=files)
        flood = g.start("side_flooder", cmd=[sys.executable, str(FLOODER), "cmd_vel,emergency_stop,external_wrench",
                                             str(FLOOD_S), "100"], params=None, as_given=True)
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", f"duration_s:={RUN_S}", params=files)
        code = plant.wait(120 + RUN_S)
        assert flood.wait(60) == 0, flood.output()
        g.close()
    out, c_out = plant.output(), ctl.output()
    sent = int(flood.output().split("flooded ")[1].split()[0])
    assert sent > 20_000, flood.output()    # a flood, not a trickle (a loaded machine's flooder: 40-70 k/s)
    assert code == 0, out                    # upright, the run complete
    assert "fault" not in "".join(line for line in out.splitlines() if "driver:" in line), out
    periods = round(RUN_S * 200)
    answered = int(c_out.split("answered ")[1].split()[0])
    stale = int(out.split("stale-command substitutions = ")[1].split()[0])
    p99, longest = (float(x) for x in re.search(r"period between wakes p50 = [\d.]+ ms, p99 = ([\d.]+) ms, max = "
                                                r"([\d.]+) ms", out).groups())
    wall = float(re.search(r"simulated in ([\d.]+) s wall", out).group(1))
    print(f"side-input flood: {sent} sent; answered {answered} of {periods + 1}; stale {stale}; plant period p99 "
          f"{p99:.1f} ms, longest {longest:.1f} ms; {RUN_S:g} s simulated in {wall:.2f} s")
    assert answered >= 0.97 * periods, (answered, c_out[-2000:])
    # the starved plant's ticks stalled for seconds (4.4 s and 5.2 s: 5 s simulated in 10.5 s of wall time); a loaded
    # machine (load average 15-20 here) stretches them by a tenth or two, flood or not
    assert longest < 1000.0, longest
    assert wall < 1.5 * RUN_S, wall
    assert stale <= 0.25 * periods, stale      # a starved controller leaves most periods without a fresh command
