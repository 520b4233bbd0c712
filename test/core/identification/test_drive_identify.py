"""Identification of the drive (theory.md 6.9, the drive of 6.7): drives that are not the default, driven into both
limits by an LQR-balanced robot with a speed ramp and a fast chirp, give K_t, R, I_max back with V_max known."""
import math
from dataclasses import replace

import numpy as np
import pytest

from mwip_ros.core.plants.drive import MotorConfig, motor_torque
from mwip_ros.core.identification.drive_identify import DriveIdentificationError, identify_drive
from mwip_ros.core.identification.excitation import Excitation, ExcitationConfig
from mwip_ros.core.control.lqr import lqr_gain, lqr_u
from mwip_ros.core.plants.model import Sinusoid, State
from mwip_ros.core.plants.plant import PlantSim
from test_identify import BASE, ROBOT, VALUES

pytestmark = pytest.mark.unit

DRIVES = [MotorConfig(True, 1.5, 0.2, 24.0, 50.0), MotorConfig(True, 3.0, 0.3, 36.0, 30.0),
          MotorConfig(True, 2.5, 0.25, 36.0, 40.0)]   # none is config/motor_realistic.yaml's (2, 0.15, 48, 60)


def record(motor: MotorConfig, excite=True, duration=20.0):
    """ROBOT balanced by an LQR that tracks a triangle of wheel speed peaking at 10 s, 1 rad/s above the speed where
    the voltage binds at full current, (V_max - R I_max) / K_t, plus a 2-5 Hz chirp of twice the peak torque until
    the peak (fast: it moves the body little); then the reference ramps down unexcited.  Columns u (the command),
    u_applied (the torque that acted), dtheta_w, dtheta_b."""
    cfg = replace(BASE, actual=ROBOT, tau_ext1=Sinusoid(0.0, 2.0, math.pi / 2), tau_ext2=Sinusoid(0.0, 1.0, 0.0),
                  initial=State(0.0, 0.0, 0.0, 0.0), motor=motor)
    K = lqr_gain(BASE.nominal, cfg.h, VALUES["lqr.Q"], VALUES["lqr.R"])
    v_peak = (motor.voltage_limit - motor.resistance * motor.current_limit) / motor.torque_constant + 1.0
    amp = 2.0 * motor.torque_constant * motor.current_limit if excite else 0.0
    ex = Excitation(ExcitationConfig("chirp", amp, 2.0, 5.0, duration), cfg.h)
    plant = PlantSim(cfg)
    rows = []
    for k in range(int(round(duration / cfg.h)) + 1):
        t, x = plant.t, plant.x
        v = v_peak * max(0.0, 1.0 - abs(t - 10.0) / 10.0)
        u = lqr_u(K, (0.0, x[1], x[2] - v, x[3])) + (ex.at(k) if t < 10.0 else 0.0)
        plant.step(u)
        assert not plant.fallen, t
        rows.append((u, plant.u_prev, x[2], x[3]))
    return np.array(rows).T


@pytest.mark.parametrize("motor", DRIVES, ids=["24V-50A", "36V-30A", "36V-40A"])
def test_identifies_the_drive_within_5_percent(motor):
    res = identify_drive(*record(motor), voltage_limit=motor.voltage_limit)
    for name in ("torque_constant", "resistance", "current_limit"):
        assert getattr(res, name) == pytest.approx(getattr(motor, name), rel=0.05), name
        assert getattr(res, name) == pytest.approx(getattr(motor, name), rel=2e-3), name   # measured: 5e-4 at most
    assert res.peak_torque == pytest.approx(motor.torque_constant * motor.current_limit, rel=1e-3)
    assert res.periods[1] >= 20 and res.periods[2] >= 20      # both limits bound
    assert res.residual_rms < 0.01


def test_the_four_constants_need_one_known():
    """(K_t, R, V_max, I_max) and (c K_t, c^2 R, c V_max, I_max / c) give the same torque everywhere: hence V_max."""
    rng = np.random.default_rng(0)
    c = 1.7
    for u, w in rng.uniform([-300, -30], [300, 30], size=(2000, 2)):
        a = motor_torque(u, w, 1.5, 0.2, 24.0, 50.0)[0]
        b = motor_torque(u, w, 1.5 * c, 0.2 * c * c, 24.0 * c, 50.0 / c)[0]
        assert a == pytest.approx(b, rel=1e-12, abs=1e-12)


def test_a_log_that_never_saturates_is_refused():
    with pytest.raises(DriveIdentificationError, match="not saturated") as err:
        identify_drive(*record(DRIVES[0], excite=False), voltage_limit=24.0)
    assert err.value.cause == "not_saturated"


def test_a_wrong_voltage_is_bad_data():
    with pytest.raises(DriveIdentificationError, match="motor.voltage_limit") as err:
        identify_drive([1.0, 2.0], [1.0, 2.0], [0.0, 0.0], [0.0, 0.0], voltage_limit=-1.0)
    assert err.value.cause == "bad_data"
