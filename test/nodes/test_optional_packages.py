"""Nodes without an optional package (mwip_ros/optional.py; test/without.py): the controller runs every law but
mpc without daqp and refuses mpc in one line (exit 2); foxglove_server without the foxglove SDK answers --help
and refuses to start in one line (exit 2)."""
import sys

import pytest

from graphproc import Graph
from without import env_without

pytestmark = pytest.mark.graph


def _one_line(out: str, *words: str) -> None:
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    for w in words:
        assert w in out, (w, out)


def test_the_controller_runs_dscndo_without_daqp_and_refuses_mpc_in_one_line(tmp_path):
    with Graph(tmp_path) as g:
        g.env = env_without(tmp_path, "daqp", base=g.env)
        ok = g.start("dscndo_controller", label="dscndo")
        refused = g.start("dscndo_controller", "-p", "law:=mpc", label="mpc")
        assert refused.wait(60) == 2, refused.output()
        _one_line(refused.output(), "parameter 'law'", "the law mpc_ndo needs the Python package daqp",
                  "pip install 'daqp'", "python3-daqp-pip")
        assert ok.wait_for_output("DSCNDO ready", timeout=60), ok.output()
        assert ok.stop() == 0, ok.output()


def test_a_switch_to_mpc_at_run_time_without_daqp_is_refused_naming_it(tmp_path):
    from injector import Injector, ParamSetter
    with Graph(tmp_path) as g:
        g.env = env_without(tmp_path, "daqp", base=g.env)
        ctl = g.start("dscndo_controller", "-p", "use_observer:=false")
        assert ctl.wait_for_output("DSC ready", timeout=60), ctl.output()
        with Injector(g.domain_id, name="test_param_client") as inj:
            params = ParamSetter(inj)
            mpc = params.set("dscndo_controller", "law", "mpc")
            lqr = params.set("dscndo_controller", "law", "lqr")
        assert not mpc.successful and "parameter 'law'" in mpc.reason and "python3-daqp-pip" in mpc.reason, mpc
        assert lqr.successful and ctl.wait_for_output("law now LQR", timeout=30), ctl.output()
        assert ctl.stop() == 0, ctl.output()


def test_foxglove_server_without_the_sdk_answers_help_and_refuses_to_start_in_one_line(tmp_path):
    with Graph(tmp_path) as g:
        g.env = env_without(tmp_path, "foxglove", base=g.env)
        helped = g.start("foxglove_server", label="help", params=None,
                         cmd=[sys.executable, "-m", "mwip_ros.nodes", "foxglove_server", "--help"])
        refused = g.start("foxglove_server", params=None, label="start")
        assert helped.wait(60) == 0 and "usage: foxglove_server" in helped.output(), helped.output()
        assert refused.wait(60) == 2, refused.output()
        _one_line(refused.output(), "foxglove_server (the live view) needs the Python package foxglove-sdk",
                  "pip install 'foxglove-sdk'", "python3-foxglove-sdk-pip")
