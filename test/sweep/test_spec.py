"""The sweep spec: what it accepts, and every mistake refused with the key named before anything runs."""
import pytest

from mwip_ros.params.paths import default_params_file
from mwip_ros.sweep.spec import SpecError, parse_spec

pytestmark = pytest.mark.unit

BASE = str(default_params_file())


def spec(**over):
    doc = {"base": BASE, "controllers": ["dsc", "dscndo"], "duration_s": 2.0, "metrics_window_s": [1.0, 2.0],
           "seed": 1, "samples": 3, "vary": {"plant_sim.actual.m_b": {"scale": [0.7, 1.3]}}}
    doc.update(over)
    return parse_spec(doc, "spec.yaml")


def refused(**over):
    with pytest.raises(SpecError) as e:
        spec(**over)
    return e.value


def test_keys_resolve_to_their_sections_and_count_the_scenarios():
    s = spec(vary={"plant_sim.actual.m_b": {"scale": [0.7, 1.3]},
                   "plant_sim.tau_ext1.amplitude": {"grid": [0, 15, 30, 45]},
                   "plant_sim.initial.theta_b": {"linspace": [-0.6, 0.6, 25]},
                   "dscndo_controller.k1": {"uniform": [2.0, 10.0]},
                   "nominal.m_b": {"values": [210.6]},
                   "disturbance_observer.X": {"values": [[50.0, 0.0, 0.0, 50.0], [100.0, 0.0, 0.0, 100.0]]},
                   "plant_sim.substeps": {"grid": [5, 10]}})
    where = {a.key: (a.section, a.name) for a in s.axes}
    assert where["plant_sim.actual.m_b"] == ("plant_sim", "actual.m_b")
    assert where["nominal.m_b"] == ("/**", "nominal.m_b")
    assert where["dscndo_controller.k1"] == ("dscndo_controller", "k1")
    assert s.n_scenarios == 4 * 25 * 1 * 2 * 2 * 3   # grid points x samples
    assert [a.key for a in s.random_axes] == ["plant_sim.actual.m_b", "dscndo_controller.k1"]
    amp = next(a for a in s.axes if a.name == "tau_ext1.amplitude")
    assert amp.args == (0.0, 15.0, 30.0, 45.0) and all(isinstance(v, float) for v in amp.args)


def test_without_random_axes_samples_do_not_multiply():
    assert spec(samples=50, vary={"dscndo_controller.k2": {"grid": [3.0, 6.0]}}).n_scenarios == 2


@pytest.mark.parametrize("vary, key, words", [
    ({"plant_sim.actual.mb": {"grid": [1.0]}}, "vary.plant_sim.actual.mb", "did you mean 'actual.m_b'"),
    ({"plant_sim.k1": {"grid": [1.0]}}, "vary.plant_sim.k1", "belongs under dscndo_controller"),
    ({"k1": {"grid": [1.0]}}, "vary.k1", "write 'dscndo_controller.k1'"),
    ({"plant_sim.nominal.m_b": {"grid": [1.0]}}, "vary.plant_sim.nominal.m_b", "without a prefix"),
    ({"nominal.mb": {"grid": [1.0]}}, "vary.nominal.mb", "did you mean 'nominal.m_b'"),
    ({"mcap_recorder.chunk_size": {"grid": [1]}}, "vary.mcap_recorder.chunk_size", "not part of the simulated"),
    ({"plant_sim.duration_s": {"grid": [1.0]}}, "vary.plant_sim.duration_s", "spec's duration_s"),
    ({"dscndo_controller.use_observer": {"grid": [True]}}, "vary.dscndo_controller.use_observer", "controllers"),
    ({"dscndo_controller.k1": {"grid": []}}, "vary.dscndo_controller.k1", "non-empty list"),
    ({"dscndo_controller.k1": {"uniform": [10.0, 2.0]}}, "vary.dscndo_controller.k1", "low < high"),
    ({"dscndo_controller.k1": {"uniform": [-1.0, 2.0]}}, "vary.dscndo_controller.k1", "must be > 0"),
    ({"dscndo_controller.k1": {"normal": [6.0, 0.0]}}, "vary.dscndo_controller.k1", "deviation > 0"),
    ({"dscndo_controller.k1": {"uniforn": [1.0, 2.0]}}, "vary.dscndo_controller.k1", "did you mean 'uniform'"),
    ({"dscndo_controller.k1": {"linspace": [1.0, 2.0]}}, "vary.dscndo_controller.k1", "[start, stop, count]"),
    ({"dscndo_controller.k1": {"linspace": [1.0, 2.0, 0]}}, "vary.dscndo_controller.k1", "integer >= 1"),
    ({"plant_sim.actual.m_b": {"scale": [-0.5, 1.3]}}, "vary.plant_sim.actual.m_b", "factors must be > 0"),
    ({"plant_sim.substeps": {"uniform": [1.0, 9.0]}}, "vary.plant_sim.substeps", "use grid or values"),
    ({"plant_sim.substeps": {"grid": [0]}}, "vary.plant_sim.substeps", ">= 1"),
    ({"dscndo_controller.k1": {"grid": ["six"]}}, "vary.dscndo_controller.k1", "expected a number"),
    ({"dscndo_controller.k1": [1.0, 2.0]}, "vary.dscndo_controller.k1", "expected one distribution"),
])
def test_a_bad_axis_is_refused_naming_the_key(vary, key, words):
    e = refused(vary=vary)
    assert e.key == key and words in e.reason, str(e)


@pytest.mark.parametrize("over, key, words", [
    ({"sample": 3}, "sample", "did you mean 'samples'"),
    ({"controllers": ["dscnd"]}, "controllers", "did you mean 'dscndo'"),
    ({"controllers": []}, "controllers", "non-empty"),
    ({"duration_s": -1.0}, "duration_s", "> 0"),
    ({"metrics_window_s": [1.0, 3.0]}, "metrics_window_s", "t1 <= duration_s"),
    ({"samples": 0}, "samples", ">= 1"),
    ({"seed": -2}, "seed", ">= 0"),
])
def test_a_bad_top_level_entry_is_refused(over, key, words):
    e = refused(**over)
    assert e.key == key and words in e.reason, str(e)


def test_a_missing_base_file_names_the_file(tmp_path):
    from mwip_ros.params import ParamError
    with pytest.raises(ParamError) as e:
        spec(base=str(tmp_path / "nope.yaml"))
    assert "nope.yaml" in str(e.value)
