"""The MuJoCo plant backend (core.plants.mujoco_plant, docs/theory.md 6.10): a model built from the parameters, the
cross-check against eq. (1)'s RK4 (the issue's criteria), per-wheel drive, and divergence as a fault."""
import dataclasses
import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

from graphproc import REPO  # noqa: E402
from mwip_ros import params as P  # noqa: E402
from mwip_ros.core.closed_loop import metrics   # noqa: E402
from mwip_ros.core.closed_loop.loop import PlantSide  # noqa: E402
from mwip_ros.core.plants.mujoco_plant import MujocoPlant, mjcf  # noqa: E402
from mwip_ros.core.plants.plant import PlantDiverged, make_plant  # noqa: E402
from mwip_ros.core.closed_loop.sim import simulate  # noqa: E402
from mwip_ros.params.paths import default_params_file  # noqa: E402

pytestmark = pytest.mark.unit

LAWS = ("dsc", "dscndo", "lqr", "lqr_ndo", "smc", "smc_ndo", "mpc", "mpc_ndo")
PAPER = P.merged_values(P.load_param_file(default_params_file()))


def _values(**over):
    return dict(PAPER, backend="mujoco", **over)


def _pair(law, duration, **over):
    """(the rk4 run, the mujoco run, the yaw of every mujoco period) of ``law`` in the paper's scenario."""
    v = _values(**over)
    mj = P.closed_loop(v, controller=law, duration=duration)
    rk = dataclasses.replace(mj, plant=dataclasses.replace(mj.plant, backend="rk4", mujoco=None))
    yaws = []
    advance = PlantSide.advance

    def recording(self, u, extra=(0.0, 0.0)):
        advance(self, u, extra)
        yaws.append(self.plant.pose.yaw)

    PlantSide.advance = recording
    try:
        b = simulate(mj)
    finally:
        PlantSide.advance = advance
    return simulate(rk), b, np.array(yaws)


def test_the_model_is_built_from_the_parameters():
    """Masses, inertias, the wheels' places, damping and the physics step are the parameter file's (no number of
    the robot is written in the model by hand): change them and the MuJoCo model changes with them."""
    v = _values(**{"actual.m_b": 123.0, "actual.I_w": 0.8, "actual.D_b": 0.3, "actual.track_width": 0.7,
                   "actual.I_b_roll": 40.0, "actual.I_b_yaw": 30.0, "actual.l": 0.4, "mujoco.timestep": 0.002})
    p = make_plant(P.plant_config(v))
    assert isinstance(p, MujocoPlant)
    m = p.model
    body, left, right = (m.body(n) for n in ("body", "wheel_left", "wheel_right"))
    assert body.mass[0] == 123.0 and left.mass[0] == right.mass[0] == 29.0 / 2
    np.testing.assert_allclose(body.inertia, [40.0, 65.0, 30.0])
    np.testing.assert_allclose(body.ipos, [0.0, 0.0, 0.4])
    assert left.inertia[1] == right.inertia[1] == 0.4                       # I_w / 2 about the axle
    assert left.pos[1] == 0.35 and right.pos[1] == -0.35
    np.testing.assert_allclose(m.dof_damping[6:8], [0.15, 0.15])           # D_b / 2 per wheel
    assert m.geom("ground").friction[0] == 2.0
    assert p.n == 3 and m.opt.timestep == pytest.approx(0.005 / 3)         # ceil(h / timestep) equal steps
    assert "310.6" not in mjcf(P.plant_config(v))


def test_the_initial_state_is_the_parameter_files():
    v = _values(**{"initial.theta_w": 0.3, "initial.theta_b": 0.2, "initial.dtheta_w": 0.5,
                   "initial.dtheta_b": -0.4})
    p = make_plant(P.plant_config(v))
    np.testing.assert_allclose(p.x, (0.3, 0.2, 0.5, -0.4), atol=1e-12)
    assert p.pose.yaw == 0.0 and p.pose.roll == 0.0
    assert p.pose.wheel_left == pytest.approx(0.3) and p.pose.wheel_right == pytest.approx(0.3)
    # the wheel's centre a radius up, less the contact's sink at rest (1 - d0) g (dmax tc)^2 / d0 with the time
    # constant tc of 4 physics steps (theory 6.10): 4.0e-5 m at the default step, 5 ms, one step a period
    sink = (1 - 0.99) * 9.81 * (0.999 * 4 * 0.005) ** 2 / 0.99
    assert p.n == 1 and p.pose.x == pytest.approx(0.254 * 0.3) and p.pose.z == pytest.approx(0.254 - sink, abs=1e-7)


@pytest.mark.parametrize("law", LAWS)
def test_every_law_agrees_with_rk4_at_every_step_over_the_first_second(law):
    """The issue's first criterion over a short horizon: theta_b within 1e-3 rad at every step (measured 1.6e-5 at
    worst over 10 s), and the robot drives straight: the yaw stays ~0."""
    a, b, yaw = _pair(law, 1.0)
    assert len(a) == len(b) == 201 and not b.fallen
    assert np.max(np.abs(a["theta_b"] - b["theta_b"])) < 1e-3
    assert np.max(np.abs(a["theta_w"] - b["theta_w"])) < 1e-2
    assert np.max(np.abs(yaw)) < 1e-9


def test_the_paper_figure_agrees_with_rk4_over_ten_seconds():
    """The paper's run (Fig. 3), DSC and DSCNDO for 10 s: theta_b within 1e-3 rad at every step, its RMS over
    [5, 10] s within 1 %, the DSCNDO / DSC peak-to-peak ratio within 3 %."""
    m = {}
    for law in ("dsc", "dscndo"):
        a, b, _ = _pair(law, 10.0)
        assert np.max(np.abs(a["theta_b"] - b["theta_b"])) < 1e-3, law
        m[law] = [metrics.compute(r.columns, (5.0, 10.0), PAPER["fall_angle"]) for r in (a, b)]
        assert m[law][1].theta_b_rms == pytest.approx(m[law][0].theta_b_rms, rel=0.01), law
    ratios = [m["dscndo"][i].theta_b_p2p / m["dsc"][i].theta_b_p2p for i in (0, 1)]
    assert ratios[1] == pytest.approx(ratios[0], rel=0.03)
    page = " ".join((REPO / "docs" / "real-robot.md").read_text().split())   # the page's words, lines joined
    assert (f"peak-to-peak ratio is {ratios[1]:.5f} against rk4's {ratios[0]:.5f} "
            f"({100 * (ratios[1] / ratios[0] - 1):+.3f} %)") in page


def test_the_motor_acts_per_wheel_as_the_one_motor_of_eq1():
    """Each wheel's drive is half the motor (K_t, 2 R, V_max, I_max / 2) with half the command: the two sum to the
    one drive of eq. (1), saturations included (the current limit binds over the first half second)."""
    a, b, _ = _pair("dscndo", 1.0, **{"motor.enabled": True})
    assert np.nansum(a["drive_saturation"] > 0) > 50                         # the limit binds: a real check
    np.testing.assert_array_equal(b["drive_saturation"], a["drive_saturation"])
    assert np.max(np.abs(a["theta_b"] - b["theta_b"])) < 1e-3
    np.testing.assert_allclose(b["u_applied"], a["u_applied"], atol=0.5)


def test_the_accelerations_a_raw_sample_reads_are_mujocos_and_agree_with_eq1():
    """sample_accel and the true tau_d are MuJoCo's accelerations and agree with eq. (1)'s: the wheels start sunk
    where the contact holds them at rest (started on the surface they fall onto the ground in the first ms, and
    the first sample reads 9x eq. 1's wheel acceleration); the soft contact takes a few ms to carry the torque's
    step (the first tau_d is 1.2 % off), then follows to 0.5 %, and to 0.1 % from the sixth period.  At a physics
    step of 1 ms: the contact's time constant is 4 steps (theory 6.10), 5x longer at the default 5 ms."""
    pc = P.plant_config(_values(**{"mujoco.timestep": 0.001}))
    rk, mj = make_plant(dataclasses.replace(pc, backend="rk4")), make_plant(pc)
    np.testing.assert_allclose(mj.sample_accel(), rk.sample_accel(), rtol=1e-2)
    np.testing.assert_allclose(mj.lumped_disturbance(20.0), rk.lumped_disturbance(20.0), rtol=2e-2)
    for k in range(40):
        rk.step(20.0)
        mj.step(20.0)
        rtol = 5e-3 if k < 5 else 1e-3
        np.testing.assert_allclose(mj.sample_accel(), rk.sample_accel(), rtol=rtol)
        np.testing.assert_allclose(mj.lumped_disturbance(20.0), rk.lumped_disturbance(20.0), rtol=rtol)


def test_both_backends_draw_the_same_friction_sequence():
    pc = P.plant_config(_values())
    rk, mj = make_plant(dataclasses.replace(pc, backend="rk4")), make_plant(pc)
    draws = []
    for _ in range(30):
        draws.append((rk.D_w, mj.D_w))
        rk.step(0.0)
        mj.step(0.0)
    assert len({d for d, _ in draws}) > 1 and all(a == b for a, b in draws)


def test_a_torque_mujoco_refuses_is_a_fault_naming_the_period_and_the_cause():
    """MuJoCo resets a state it finds bad to the initial one and goes on, silently: the plant turns its warning
    into a fault; it never hands the loop a reset (or NaN) state as the next one."""
    p = make_plant(P.plant_config(_values()))
    for _ in range(4):
        p.step(10.0)
    with pytest.raises(PlantDiverged, match=r"diverged in \[0\.02, 0\.025\] s: mjWARN_BADCTRL"):
        p.step(float("nan"))


def test_a_state_that_blows_up_is_a_fault():
    p = make_plant(P.plant_config(_values()))
    p.step(0.0)
    p.data.qvel[4] = 1e12   # what a diverging integration leaves behind
    with pytest.raises(PlantDiverged, match=r"diverged in \[0\.005, 0\.01\] s: mjWARN_BADQVEL"):
        p.step(0.0)


def test_a_non_finite_state_is_fallen():
    p = make_plant(P.plant_config(_values()))
    p.x = p.x._replace(theta_b=math.nan)
    assert p.fallen


@pytest.mark.parametrize("roll", [0.0, 0.3, -1.2])
@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.5, 3.0])
@pytest.mark.parametrize("pitch", [0.0, -0.1745, 1.2, 2.8, -3.0])
def test_the_pose_of_a_yawed_rolled_and_pitched_body(yaw, pitch, roll):
    """theta_b is the pitch about the axle over the whole circle, whatever the heading and the roll
    (R = Rz(yaw) Rx(roll) Ry(pitch), composed by MuJoCo), and true_pose's quaternion is that rotation."""
    import mujoco

    from mwip_ros.core.plants.markers import pose_angles, pose_quaternion
    q, qz_qx = np.zeros(4), np.zeros(4)
    mujoco.mju_mulQuat(qz_qx, np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]),
                       np.array([math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0]))
    mujoco.mju_mulQuat(q, qz_qx, np.array([math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0]))
    got = pose_angles(*q)
    assert got[0] == pytest.approx(pitch, abs=1e-12) and got[1] == pytest.approx(yaw, abs=1e-12)
    assert got[2] == pytest.approx(roll, abs=1e-12)
    x, y, z, w = pose_quaternion(yaw, pitch, roll)   # ROS order (x, y, z, w); MuJoCo's is (w, x, y, z)
    np.testing.assert_allclose(np.array([w, x, y, z]) * np.sign(w * q[0] or 1.0), q, rtol=0, atol=1e-12)
