"""Hostile YAML: every YAML the project reads goes through one bounded loader (mwip_ros.yamlio).

Alias bombs ("billion laughs"), files of gigabytes, documents of millions of nodes or thousands of levels,
integers of 100,000 digits: each is refused with one line (exit 2 for the tools and the nodes), fast and
with little memory (the heavy cases run in a subprocess that reports its own peak RSS)."""
from __future__ import annotations

import os
import stat
import time

import pytest
import yaml

from mwip_ros import params as P
from mwip_ros.bag.errors import BagError
from mwip_ros.bag.metadata import parse_qos_yaml
from mwip_ros.bag.reader import read_metadata
from mwip_ros import yamlio
from mwip_ros.sweep.spec import SpecError, load_spec

from hostile import PAPER, assert_refused, laughs, measured, param_bomb, spec_bomb  # noqa: E402  (test/hostile.py)


# --- the loader -----------------------------------------------------------------------------------------

@pytest.mark.unit
def test_an_alias_is_refused_at_once_in_text_and_files(tmp_path):
    """At once: the CPU time of the refusals (process_time: a loaded machine stretches the wall, not the work)."""
    t0 = time.process_time()
    with pytest.raises(yamlio.YamlRefused, match=r"YAML aliases \(\*l0\) are not supported"):
        yamlio.load_yaml(laughs(5))
    with pytest.raises(yaml.YAMLError):   # callers that catch YAML errors catch the refusal
        yamlio.load_yaml(param_bomb(tmp_path / "b.yaml", 5))
    with pytest.raises(yamlio.YamlRefused, match="aliases"):   # a merge key needs an alias
        yamlio.load_yaml("a: &a {x: 1}\nb:\n  <<: *a\n")
    assert time.process_time() - t0 < 2.0


@pytest.mark.unit
def test_the_composer_refuses_aliases_even_without_libyaml(monkeypatch):
    monkeypatch.setattr(yamlio, "_prescan", lambda text: None)
    with pytest.raises(yamlio.YamlRefused, match="aliases"):
        yamlio.load_yaml(laughs(5))
    monkeypatch.setattr(yamlio, "MAX_NODES", 1000)   # the pure-Python composer is slow: a smaller bound
    assert len(yamlio.load_yaml("[" + ",".join(["0"] * 999) + "]")) == 999
    with pytest.raises(yamlio.YamlRefused, match="more than 1,000 YAML nodes"):
        yamlio.load_yaml("[" + ",".join(["0"] * 1000) + "]")
    with pytest.raises(yamlio.YamlRefused, match="nested deeper than 64"):
        yamlio.load_yaml("[" * 65 + "]" * 65)


@pytest.mark.unit
def test_nodes_depth_and_huge_integers_are_bounded():
    t0 = time.process_time()
    with pytest.raises(yamlio.YamlRefused, match="more than 200,000 YAML nodes"):
        yamlio.load_yaml("a: [" + ",".join(["0"] * 1_000_000) + "]")
    with pytest.raises(yamlio.YamlRefused, match="nested deeper than 64 levels"):
        yamlio.load_yaml("a: " + "[" * 100_000 + "]" * 100_000)
    with pytest.raises(yamlio.YamlRefused, match="an integer of more than 4,300 digits"):
        yamlio.load_yaml("a: " + "9" * 100_000)
    assert time.process_time() - t0 < 5.0
    assert yamlio.load_yaml("[" * 64 + "]" * 64) is not None   # at the bound: accepted
    assert yamlio.load_yaml("a: &x 1\nb: 2\n") == {"a": 1, "b": 2}   # an anchor alone costs nothing
    assert yamlio.load_yaml("x: 1e-1\nn: 200") == {"x": 0.1, "n": 200}   # ROS 2's numbers


@pytest.mark.unit
def test_a_file_is_sized_before_it_is_read(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "wb") as f:   # sparse: 1 GiB on paper, nothing on disk
        f.truncate(1 << 30)
    t0 = time.process_time()
    with pytest.raises(yamlio.YamlRefused, match=r"the parameter file is 1024.0 MiB; at most 4.0 MiB is read"):
        yamlio.load_yaml(big, "parameter file")
    with pytest.raises(P.ParamError, match=r"big.yaml: parameter '<file>': refused: the parameter file is 1024.0 MiB"):
        P.load_param_file(big)
    assert time.process_time() - t0 < 1.0
    edge = tmp_path / "edge.yaml"
    edge.write_text("a: 1\n" + "#" * (yamlio.MAX_BYTES - 6) + "\n")
    assert edge.stat().st_size == yamlio.MAX_BYTES and yamlio.load_yaml(edge) == {"a": 1}


@pytest.mark.unit
def test_a_file_that_grows_after_the_stat_is_read_only_up_to_the_bound(tmp_path, monkeypatch):
    f = tmp_path / "grows.yaml"
    with open(f, "wb") as fh:
        fh.truncate(1 << 30)
    real_fdopen, reads = os.fdopen, []

    class Small:   # what fstat said a moment before the file grew (a regular file of 10 bytes)
        st_size = 10
        st_mode = stat.S_IFREG | 0o644

    monkeypatch.setattr(yamlio.os, "fstat", lambda fd: Small)

    def counting_fdopen(fd, mode="r", *a, **k):
        fh = real_fdopen(fd, mode, *a, **k)

        class Counting:   # the file object, its reads counted
            def __init__(self):
                self.fileno, self.close = fh.fileno, fh.close

            def read(self, n=-1):
                reads.append(n)
                return fh.read(n)

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                fh.close()
        return Counting()

    monkeypatch.setattr(yamlio.os, "fdopen", counting_fdopen)
    with pytest.raises(yamlio.YamlRefused, match="more than 4.0 MiB"):
        yamlio.read_text(f, "parameter file")
    assert reads and all(0 < n <= yamlio.MAX_BYTES + 1 for n in reads)


@pytest.mark.unit
def test_shown_bounds_a_repr():
    assert yamlio.shown([1.0, 2.0]) == "[1.0, 2.0]"
    assert yamlio.shown("fast") == "'fast'"
    assert len(yamlio.shown(list(range(1_000_000)))) <= yamlio.MAX_SHOWN
    assert len(yamlio.shown("x" * 1_000_000)) <= yamlio.MAX_SHOWN


# --- where the project reads YAML -------------------------------------------------------------------------

@pytest.mark.unit
def test_a_parameter_file_bomb_is_refused_naming_the_file(tmp_path):
    bomb = param_bomb(tmp_path / "bomb.yaml", 5)
    with pytest.raises(P.ParamError, match=r"bomb.yaml: parameter '<file>': refused: YAML aliases") as exc:
        P.load_param_file(bomb)
    assert "\n" not in str(exc.value)


@pytest.mark.unit
def test_a_huge_value_makes_a_short_message(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("plant_sim:\n  ros__parameters:\n    mode: " + "x" * 1_000_000 + "\n")
    with pytest.raises(P.ParamError) as exc:
        P.load_param_file(f)
    assert "plant_sim.mode" in str(exc.value) and len(str(exc.value)) < 1000
    spec = tmp_path / "s.yaml"
    spec.write_text(f"base: {PAPER}\nduration_s: [" + ",".join(["1.0"] * 5_000) + "]\n")
    with pytest.raises(SpecError) as exc:
        load_spec(spec)
    assert exc.value.key == "duration_s" and len(str(exc.value)) < 1000


@pytest.mark.unit
def test_a_spec_bomb_and_a_base_bomb_are_refused(tmp_path):
    spec = spec_bomb(tmp_path / "spec.yaml", 5)
    with pytest.raises(SpecError, match=r"spec.yaml: <spec>: refused: YAML aliases") as exc:
        load_spec(spec)
    assert len(str(exc.value)) < 300
    param_bomb(tmp_path / "bomb.yaml", 5)
    spec.write_text("base: bomb.yaml\nsamples: 1\n")
    with pytest.raises(P.ParamError, match=r"bomb.yaml: parameter '<file>': refused: YAML aliases"):
        load_spec(spec)
    with open(tmp_path / "huge.yaml", "wb") as f:
        f.truncate(1 << 30)
    spec.write_text("base: huge.yaml\n")
    t0 = time.process_time()
    with pytest.raises(P.ParamError, match=r"huge.yaml: parameter '<file>': refused: the parameter file is 1024.0 MiB"):
        load_spec(spec)
    assert time.process_time() - t0 < 1.0


@pytest.mark.unit
def test_a_missing_base_names_the_spec_key(tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text("base: nowhere.yaml\n")
    with pytest.raises(P.ParamError, match=r"parameter 'base': no such file: .*nowhere.yaml"):
        load_spec(spec)


@pytest.mark.unit
def test_bag_metadata_is_bounded(tmp_path):
    (tmp_path / "metadata.yaml").write_text(laughs(5) + "rosbag2_bagfile_information: {files: *l4}\n")
    with pytest.raises(BagError, match=r"metadata.yaml refused: YAML aliases"):
        read_metadata(tmp_path)
    with open(tmp_path / "metadata.yaml", "wb") as f:
        f.truncate(1 << 30)
    t0 = time.process_time()
    with pytest.raises(BagError, match=r"refused: the metadata.yaml is 1024.0 MiB"):
        read_metadata(tmp_path)
    assert time.process_time() - t0 < 1.0
    with pytest.raises(BagError, match="offered_qos_profiles refused: YAML aliases"):
        parse_qos_yaml(laughs(5) + "- *l4\n")
    assert parse_qos_yaml("- history: keep_last\n  depth: 10\n")[0]["depth"] == 10


@pytest.mark.unit
def test_a_p_rule_with_an_alias_is_refused():
    from mwip_ros.nodes.runtime.params import parse_rule
    with pytest.raises(P.ParamError, match="aliases"):
        parse_rule("seed:=[&a [1], *a]")


# --- the tools and the nodes: exit 2, one line, fast, low memory ------------------------------------------

@pytest.mark.cli
def test_mwip_sim_refuses_a_bomb(tmp_path):
    assert_refused(measured("mwip_ros.cli.sim", ["--params", param_bomb(tmp_path / "bomb.yaml"), "-q"]),
                   "mwip_sim: error:", "bomb.yaml", "YAML aliases")


@pytest.mark.cli
def test_mwip_sweep_refuses_a_spec_bomb_and_a_base_bomb(tmp_path):
    spec = spec_bomb(tmp_path / "spec.yaml", base=PAPER)
    assert spec.stat().st_size < 700
    assert_refused(measured("mwip_ros.cli.sweep", [spec, "--out", tmp_path / "o", "--workers", "1"]),
                   "mwip_sweep: error:", "spec.yaml", "YAML aliases")
    param_bomb(tmp_path / "bomb.yaml")
    spec.write_text("base: bomb.yaml\n")
    assert_refused(measured("mwip_ros.cli.sweep", [spec, "--out", tmp_path / "o", "--workers", "1"]),
                   "bomb.yaml", "YAML aliases")
    assert not (tmp_path / "o").exists()


@pytest.mark.graph
def test_plant_sim_refuses_a_bomb_before_rcl_parses_it(tmp_path):
    bomb = param_bomb(tmp_path / "bomb.yaml")
    assert bomb.stat().st_size < 900
    assert_refused(measured("mwip_ros.nodes.loop.plant_sim", ["--ros-args", "--params-file", bomb], node=True),
                   "plant_sim", "bomb.yaml", "YAML aliases")
