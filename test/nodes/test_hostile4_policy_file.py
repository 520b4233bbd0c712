"""A file-valued parameter set at run time cannot block the controller (issue 46 item 3): the realtime graph with
the law ``policy`` (MWIP_ROS_LAWS=mwip_ros.policy_law), and ``mwip_ctl param set dscndo_controller policy.file`` to a
FIFO, then to /dev/zero: each is refused at once (not a regular file, nothing read), and the robot balances on.
Before, set_parameters never answered: the executor blocked on the FIFO's open (on /dev/zero's read), the watchdog
faulted and the robot fell."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from graphproc import PARAMS, Graph

pytestmark = pytest.mark.graph

MWIP_CTL = Path(sys.executable).with_name("mwip_ctl")
RUN_S = 8.0


@pytest.mark.alone
def test_policy_file_set_at_run_time_to_a_fifo_or_a_device_is_refused_and_the_loop_goes_on(tmp_path):
    policy = tmp_path / "p.json"
    policy.write_text(json.dumps({"policy": "linear", "features": ["theta_b", "dtheta_b", "dtheta_w"],
                                  "w": [9.609, 1.246, -0.0438], "scale": 256.0}))
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    law = tmp_path / "law.yaml"
    law.write_text(f"dscndo_controller:\n  ros__parameters:\n    law: policy\n    use_observer: false\n"
                   f"    policy:\n      file: {policy}\n")
    files = [PARAMS, law]
    answers = []
    try:
        with Graph(tmp_path) as g:
            g.env["MWIP_ROS_LAWS"] = "mwip_ros.policy_law"
            g.start("disturbance_observer", "-p", "mode:=realtime", params=files)
            ctl = g.start("dscndo_controller", "-p", "mode:=realtime", params=files)
            plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", f"duration_s:={RUN_S}", params=files)
            assert ctl.wait_for_output("policy ready", 60), ctl.output()
            assert plant.wait_for_output("starting realtime run", 60), plant.output()
            for target in (fifo, "/dev/zero"):
                r = subprocess.run([str(MWIP_CTL), "param", "set", "dscndo_controller", "policy.file", str(target),
                                    "--timeout", "30"], capture_output=True, text=True, env=g.env, timeout=90)
                answers.append(r)
            code = plant.wait(120 + RUN_S)
            g.close()
    finally:
        try:   # a reader blocked on the FIFO (the old code) is let go
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass
    for r in answers:
        assert r.returncode == 1 and "not a regular file" in r.stderr + r.stdout, (r.stdout, r.stderr)
    out = plant.output()
    assert code == 0, out   # upright, the run complete
    assert "watchdog" not in out, out
    assert "policy ready" in ctl.output() and "law now" not in ctl.output()
