"""Nodes without an optional package (mwip_ros/optional.py; test/without.py): the controller runs every law but
mpc without daqp and refuses mpc in one line (exit 2), at start-up and at run time; foxglove_server without the
foxglove SDK answers --help and refuses to start in one line (exit 2).

A process of its own (``env_without``: the package cannot be imported there at all) shows that the node's whole
import chain runs without it; the refusals' words are checked in this process, the package made unimportable for
the test (``sys.modules[name] = None``, as test/without.py's shim does)."""
import sys

import pytest

from graphproc import Graph
from without import env_without


def _one_line(out: str, *words: str) -> None:
    assert "Traceback" not in out and len(out.strip().splitlines()) == 1, out
    for w in words:
        assert w in out, (w, out)


@pytest.mark.graph
def test_the_controller_runs_dscndo_without_daqp_and_refuses_a_switch_to_mpc_naming_it(tmp_path):
    from injector import Injector, ParamSetter
    with Graph(tmp_path) as g:
        g.env = env_without(tmp_path, "daqp", base=g.env)
        ctl = g.start("dscndo_controller")
        assert ctl.wait_for_output("DSCNDO ready", timeout=60), ctl.output()
        with Injector(g.domain_id, name="test_param_client") as inj:
            params = ParamSetter(inj)
            mpc = params.set("dscndo_controller", "law", "mpc")
            lqr = params.set("dscndo_controller", "law", "lqr")
        assert not mpc.successful and "parameter 'law'" in mpc.reason and "python3-daqp-pip" in mpc.reason, mpc
        assert lqr.successful and ctl.wait_for_output("law now LQR", timeout=30), ctl.output()
        assert ctl.stop() == 0, ctl.output()


@pytest.mark.node
def test_the_controller_refuses_mpc_at_start_up_without_daqp_in_one_line(monkeypatch):
    from nodeharness import node_class, refused
    monkeypatch.setitem(sys.modules, "daqp", None)
    line = refused(node_class("dscndo_controller"), "-p", "law:=mpc")
    _one_line(line, "parameter 'law'", "the law mpc_ndo needs the Python package daqp", "pip install 'daqp'",
              "python3-daqp-pip")


@pytest.mark.graph
def test_foxglove_server_without_the_sdk_refuses_to_start_in_one_line(tmp_path):
    with Graph(tmp_path) as g:
        g.env = env_without(tmp_path, "foxglove", base=g.env)
        refused = g.start("foxglove_server", params=None, label="start")
        assert refused.wait(60) == 2, refused.output()
        _one_line(refused.output(), "foxglove_server (the live view) needs the Python package foxglove-sdk",
                  "pip install 'foxglove-sdk'", "python3-foxglove-sdk-pip")


@pytest.mark.unit
def test_foxglove_server_without_the_sdk_answers_help(monkeypatch, capsys):
    from mwip_ros.nodes.tools import foxglove_server
    monkeypatch.setitem(sys.modules, "foxglove", None)
    assert foxglove_server.main(["foxglove_server", "--help"]) == 0
    assert capsys.readouterr().out.startswith("usage: foxglove_server")
