"""Sensor noise a measurement can survive: a standard deviation that would publish implausible values (which
the observer and the controller refuse, mwip_ros.msgs.layouts.LIMITS) is a configuration error, refused at
start-up naming the key, not a fault found during the run."""
from __future__ import annotations

import math

import pytest

from hostile import PAPER, assert_refused, measured
from mwip_ros import params as P
from mwip_ros.core.plants.model import State
from mwip_ros.core.plants.sensing import SensingConfig, Sensors
from mwip_ros.msgs.layouts import LIMITS
from mwip_ros.params import schema

CHANNELS = {"theta_w": "theta_w", "theta_b": "theta_b", "dtheta_w": "rate", "dtheta_b": "rate"}


@pytest.mark.unit
def test_the_schema_knows_the_messages_limits():
    assert schema.MEASURED_LIMITS == {k: LIMITS[k] for k in ("theta_b", "theta_w", "rate")}
    specs = P.specs_for("plant_sim")
    for ch, limit in CHANNELS.items():
        spec = specs[f"sensors.noise_std.{ch}"]
        assert (spec.lo, spec.hi, spec.lo_open) == (0.0, LIMITS[limit] / schema.NOISE_LIMIT_FRACTION, False)


@pytest.mark.unit
def test_noise_at_the_old_maximum_is_refused_naming_the_key():
    spec = P.specs_for("plant_sim")["sensors.noise_std.theta_b"]
    with pytest.raises(P.ParamError, match=r"parameter 'sensors.noise_std.theta_b': must be <= 0.314159"):
        spec.validate(3.14159, "sensors.noise_std.theta_b")
    for ch in ("dtheta_w", "dtheta_b"):
        with pytest.raises(P.ParamError, match="must be <= 100"):
            P.specs_for("plant_sim")[f"sensors.noise_std.{ch}"].validate(1e3, ch)


@pytest.mark.unit
def test_theta_b_noise_must_leave_room_above_the_fall_angle(tmp_path):
    base = P.merged_values(P.load_param_file(PAPER))
    most = (math.pi - base["fall_angle"]) / schema.NOISE_SIGMAS
    P.check_derived(dict(base, **{"sensors.noise_std.theta_b": most * 0.999}))
    with pytest.raises(P.ParamError, match=r"parameter 'sensors.noise_std.theta_b': 0.3 rad would publish "
                                           r"implausible pitches.*at most 0.2618 rad"):
        P.check_derived(dict(base, **{"sensors.noise_std.theta_b": 0.3}))
    with pytest.raises(P.ParamError, match="sensors.noise_std.theta_b"):   # a wider fall angle leaves less room
        P.check_derived(dict(base, **{"sensors.noise_std.theta_b": 0.05, "fall_angle": 3.0}))
    f = tmp_path / "noisy.yaml"
    f.write_text("plant_sim:\n  ros__parameters:\n    sensors:\n      noise_std:\n        theta_b: 0.3\n")
    with pytest.raises(P.ParamError, match=r"noisy.yaml: parameter 'sensors.noise_std.theta_b'"):
        P.merged_values(P.load_param_files([PAPER, f]))
    P.merged_values(P.load_param_files([PAPER, PAPER.parent / "sensing_realistic.yaml"]))   # shipped: fine


@pytest.mark.unit
def test_the_largest_accepted_noise_publishes_plausible_pitches():
    fall = 1.0472
    sd = (math.pi - fall) / schema.NOISE_SIGMAS
    sensors = Sensors.for_plant(SensingConfig(noise_std=(0.0, sd, 0.0, 0.0)), seed=3)
    worst = max(abs(sensors.sample(State(0.0, fall, 0.0, 0.0), 0.0)[0][1]) for _ in range(100_000))
    assert worst <= LIMITS["theta_b"]
    assert worst > fall + 3 * sd   # the noise is real


@pytest.mark.graph
def test_plant_sim_refuses_implausible_noise_at_start_up():
    assert_refused(measured("mwip_ros.nodes.loop.plant_sim",
                            ["--ros-args", "-p", "plant_sim:sensors.noise_std.theta_b:=3.14159"], node=True),
                   "plant_sim", "sensors.noise_std.theta_b")
    assert_refused(measured("mwip_ros.nodes.loop.plant_sim",
                            ["--ros-args", "-p", "plant_sim:sensors.noise_std.theta_b:=0.3"], node=True),
                   "parameter 'sensors.noise_std.theta_b': 0.3 rad would publish implausible pitches")
