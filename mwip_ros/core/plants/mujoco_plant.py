"""The true plant in MuJoCo: a second, independent physics (``plant_sim: backend: mujoco``; docs/theory.md 6.10).

The robot is a 3D model generated from the :class:`~.plant.PlantConfig` (``actual.*`` and :class:`MujocoConfig`;
:func:`mjcf`): a body on a free joint with its mass ``m_b`` at (0, 0, l) and the inertia (I_b_roll, I_b, I_b_yaw),
two wheels hinged to it about its y axis at y = +-track_width / 2, each with half of ``m_w``, ``I_w`` and ``D_b``
(the hinge's damping), drawn as a cylinder of radius ``r`` and width w = r / 5.  Each wheel touches the ground at
one point, the lowest of its mid-plane (a sphere of radius r: the rim's circle), with the sliding friction mu and
the torsional friction mu w / 4 of its contact line (docs/theory.md 6.10, "Contact", eq. C1), Coulomb's cone
enforced by MuJoCo's NoSlip pass.  Each wheel's motor is an actuator on its hinge: u_i on the wheel, -u_i on the
body, u_L = u_R = u / 2 (no yaw command).  The rest of eq. (1) acts as generalized forces (theory 6.10):

    Q_phi_i = -D_w / 2 theta_w_i' + tau_ext1 / 2           on wheel i's hinge
    Q_pitch = Q_phi_L + Q_phi_R + tau_ext2 - tau_ext1       on the body's pitch axis (body y)

A free joint's angular velocity and generalized force are in the body's own frame, so the pitch axis is body y.
The ground (``ground.slope``, ``ground.bumps``; :func:`mjcf`) is a plane tilted about y and steps across the path as
boxes; ``external_wrench``'s force.y and torque.z act on the body at its centre of gravity (:meth:`MujocoPlant._push`).
The laws see the planar :class:`~.model.State`: theta_b the body's pitch, theta_w the mean of the two wheels'
absolute angles; :attr:`MujocoPlant.pose` is the 3D pose. The true tau_d is eq. (6-7) on those coordinates with
MuJoCo's accelerations and u = u_L + u_R, defined while both wheels touch the ground (NaN otherwise: theory 6.10).
``D_w`` is drawn per period from the same seeded generator as :class:`~.plant.PlantSim`'s (both extend
:class:`~.plant_base.PlantBase`), so both backends see the same friction sequence. A simulation that diverges (a
MuJoCo warning, a state that is not finite) raises :class:`PlantDiverged` naming the time and the cause: it never
hands a NaN state or MuJoCo's silent reset to the loop. ``mujoco`` is imported when the backend is built, not
before (:func:`mujoco_module`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Optional, Tuple

from .drive import motor_torque
from .markers import pose_angles
from .model import State, lumped_disturbance
from .plant_base import MujocoConfig, PlantBase, PlantDiverged, Pose, gated_drive
from mwip_ros.optional import required

__all__ = ["MujocoConfig", "MujocoPlant", "PlantDiverged", "Pose", "mjcf", "mujoco_module"]


def mujoco_module():
    """``import mujoco``, or one line naming the package (:class:`mwip_ros.optional.MissingPackage`)."""
    with required("mujoco"):
        import mujoco
    if mujoco.get_mju_user_warning() is None:   # no MUJOCO_LOG.TXT in the user's directory: the plant reports
        mujoco.set_mju_user_warning(_unlogged)   # MuJoCo's warnings itself (PlantDiverged)
    return mujoco


def _unlogged(text: str) -> None:
    """MuJoCo's warning handler: nothing (the plant turns the warning counts into :class:`PlantDiverged`)."""


_D0, _DMAX = 0.99, 0.999   # the contact's impedance (solimp) at rest and deep in
FRICTION_TIMECONST = 0.2   # s: the friction rows' reference (solreffriction) in MuJoCo's main solve (theory 6.10)
NOSLIP_ITERATIONS = 3      # MuJoCo's NoSlip pass: Coulomb's cone on the friction forces ...
NOSLIP_TOLERANCE = 1e-12   # ... all of its sweeps (the two wheels, solved one after the other, agree to 6e-9 rad)


def wheel_width(r: float) -> float:
    """A wheel's width w [m] for its radius ``r``: r / 5 (the drawn cylinder, the URDF's, the torsional friction's
    line; docs/theory.md 6.10)."""
    return r / 5.0


def torsional_friction(mu: float, r: float) -> float:
    """The torsional friction coefficient [m] of a wheel's contact (docs/theory.md 6.10, eq. C1): mu w / 4, the
    Coulomb torque per newton of normal force of a contact line of width w = :func:`wheel_width` under uniform
    pressure pivoting about its middle, the integral of mu (N / w) |y| over y in [-w/2, w/2]."""
    return mu * wheel_width(r) / 4.0


def scrub_torque(mu: float, r: float, weight: float) -> float:
    """The yaw torque [N m] both wheels' contacts resist a turn in place with on flat ground (theory 6.10, eq. C2):
    each wheel's normal force times :func:`torsional_friction`, summed (``weight`` = (m_b + m_w) g [N])."""
    return torsional_friction(mu, r) * weight


def mjcf(cfg) -> str:
    """The MJCF model of the :class:`~.plant.PlantConfig` ``cfg`` at its initial state (module docstring)."""
    p, mc = cfg.actual, cfg.mujoco or MujocoConfig()
    n = max(1, math.ceil(cfg.h / mc.timestep - 1e-9))
    th_w, th_b = cfg.initial[0], cfg.initial[1]
    half = mc.track_width / 2.0
    # a stiff contact (time constant 4 physics steps, impedance 0.99..0.999): the wheel sinks 1.6e-6 m at 1 ms, so it
    # rolls on its radius r as eq. (1) has it (MuJoCo's defaults sink it 0.4 mm); the elliptic cone is Coulomb's
    tc = 4.0 * cfg.h / n
    contact = f'friction="{mc.friction!r} 0 0" solref="{tc!r} 1" solimp="{_D0} {_DMAX} 0.001"'
    # each wheel touches the ground at one point (theory 6.10, "Contact"): the pairs below, wheel with each ground geom
    mu, mu_t = mc.friction, torsional_friction(mc.friction, p.r)
    pair = (f'condim="4" friction="{mu!r} {mu!r} {mu_t!r} 0 0" solref="{tc!r} 1" solimp="{_D0} {_DMAX} 0.001" '
            f'solreffriction="{FRICTION_TIMECONST!r} 1"')
    # the wheels start where the contact holds them at rest: MuJoCo's soft contact at rest sinks by
    # (1 - d0) g / (d0 k), k = 1 / (dmax tc)^2 (its reference acceleration, damping ratio 1): no transient at t = 0
    z0 = p.r - (1.0 - _D0) * p.g * (_DMAX * tc) ** 2 / _D0
    a = mc.slope   # the wheel's centre: r theta_w along the slope, z0 above it (the plane's normal)
    along = p.r * th_w
    cx, cz = (along, z0) if a == 0.0 else (along * math.cos(a) - z0 * math.sin(a),
                                           along * math.sin(a) + z0 * math.cos(a))
    wheels = "".join(
        f'<body name="wheel_{side}" pos="0 {y!r} 0">'
        f'<joint name="wheel_{side}" type="hinge" axis="0 1 0" damping="{cfg.D_b / 2.0!r}" ref="0"/>'
        f'<inertial pos="0 0 0" mass="{p.m_w / 2.0!r}" diaginertia="{p.I_w / 4.0!r} {p.I_w / 2.0!r} {p.I_w / 4.0!r}"/>'
        f'<geom type="cylinder" size="{p.r!r} {wheel_width(p.r) / 2.0!r}" zaxis="0 1 0" contype="0" conaffinity="0"/>'
        f'<geom name="contact_{side}" type="sphere" size="{p.r!r}" contype="0" conaffinity="0" group="3"/>'
        f'</body>' for side, y in (("left", half), ("right", -half)))
    grounds = _ground_names(mc)
    pairs = "".join(f'<pair geom1="contact_{side}" geom2="{g}" {pair}/>' for side in ("left", "right") for g in grounds)
    # raw sensors (theory 6.4): MuJoCo's own gyro and accelerometer at the IMU, (0, 0, offset) on the body, to
    # cross-check core.plants.raw_sensors' model (read after Plant.sample_accel, which computes the instant t_k^-)
    imu_site = imu_sensors = ""
    if cfg.raw is not None:
        imu_site = f'<site name="imu" pos="0 0 {cfg.raw.offset!r}"/>'
        imu_sensors = '<sensor><gyro name="gyro" site="imu"/><accelerometer name="accel" site="imu"/></sensor>'
    return (
        '<mujoco model="mwip"><compiler angle="radian" autolimits="true"/>'
        f'<option timestep="{cfg.h / n!r}" integrator="RK4" cone="elliptic" noslip_iterations="{NOSLIP_ITERATIONS}" '
        f'noslip_tolerance="{NOSLIP_TOLERANCE!r}" gravity="0 0 {-p.g!r}"/>'
        '<worldbody>'
        f'{_ground(mc, contact)}'
        f'<body name="body" pos="{cx!r} 0 {cz!r}" quat="{math.cos(th_b / 2)!r} 0 {math.sin(th_b / 2)!r} 0">'
        '<freejoint name="base"/>'
        f'<inertial pos="0 0 {p.l!r}" mass="{p.m_b!r}" diaginertia="{mc.I_b_roll!r} {p.I_b!r} {mc.I_b_yaw!r}"/>'
        f'{wheels}{imu_site}</body></worldbody>'
        f'<contact>{pairs}</contact>'
        '<actuator><motor name="wheel_left" joint="wheel_left"/><motor name="wheel_right" joint="wheel_right"/>'
        f'</actuator>{imu_sensors}</mujoco>')


def _ground_names(mc: MujocoConfig) -> Tuple[str, ...]:
    """The names of the ground's geoms :func:`_ground` makes: the plane and each step of height > 0."""
    xs, hs = mc.bumps[0::2], mc.bumps[1::2]
    return ("ground",) + tuple(f"step_{i}" for i, h in enumerate(hs) if h > 0.0 and i < len(xs))


def _ground(mc: MujocoConfig, contact: str) -> str:
    """The ground's geoms: a plane tilted by ``mc.slope`` about y (uphill ahead), and each step of ``mc.bumps`` a box
    across the path from x_i to the next step (the last 100 m long), h_i high, 0.1 m deep, in the plane's frame."""
    a = mc.slope
    tilt = "" if a == 0.0 else f' quat="{math.cos(a / 2)!r} 0 {-math.sin(a / 2)!r} 0"'
    out = [f'<geom name="ground" type="plane" size="0 0 1"{tilt} {contact}/>']
    xs, hs = mc.bumps[0::2], mc.bumps[1::2]
    for i, (x, h) in enumerate(zip(xs, hs)):
        if h <= 0.0:
            continue
        end = xs[i + 1] if i + 1 < len(xs) else x + 100.0
        px, pz = 0.5 * (x + end), 0.5 * (h - 0.1)   # the box's centre in the plane's frame
        wx, wz = px * math.cos(a) - pz * math.sin(a), px * math.sin(a) + pz * math.cos(a)
        out.append(f'<geom name="step_{i}" type="box" size="{0.5 * (end - x)!r} {mc.track_width + 1.0!r} '
                   f'{0.5 * (h + 0.1)!r}" pos="{wx!r} 0 {wz!r}"{tilt} {contact}/>')
    return "".join(out)


@dataclass
class MujocoPlant(PlantBase):
    """The :class:`~.plant.Plant` of a MuJoCo model (module docstring), a :class:`~.plant.SpatialPlant`; the D_w
    generator, the clock and the bookkeeping of the previous period are :class:`~.plant_base.PlantBase`'s."""

    pose: Optional[Pose] = None   # a field here (3D); PlantSim's (planar) is the class's None
    wheels_prev: Optional[Tuple[float, float]] = None   # the yaw stage's (u_L, u_R) that acted (theory 6.13)
    wheels_cmd_prev: Optional[Tuple[float, float]] = None   # ... and what was commanded (the motor's inputs)
    _mj: Any = field(default=None, repr=False)   # the mujoco module
    _pushed: bool = False   # external_wrench's force.y or torque.z acts on the body (xfrc_applied, :meth:`_push`)
    spatial: ClassVar[bool] = True   # a 3D pose (Pose, core.plants.plant)

    def __post_init__(self):
        super().__post_init__()
        mj = self._mj = mujoco_module()
        c = self.cfg
        self.model = mj.MjModel.from_xml_string(mjcf(c))
        self.data = mj.MjData(self.model)
        self.n = max(1, math.ceil(c.h / (c.mujoco or MujocoConfig()).timestep - 1e-9))   # physics steps per period
        d = self.data   # dofs: free joint 0-2 (world velocity), 3-5 (body-frame rates, 4 the pitch); wheels 6, 7
        self._qpos, self._qvel, self._ctrl, self._qfrc = d.qpos, d.qvel, d.ctrl, d.qfrc_applied   # live views
        self._qacc = d.qacc
        self._step, self._forward = mj.mj_step, mj.mj_forward   # looked up once: a period calls each once or more
        self._warnings = d.warning.number                                    # MuJoCo's warning counts, live
        self._wheel_geoms = {self.model.geom(f"contact_{side}").id for side in ("left", "right")}
        x0 = self.x
        d.qpos[7] = d.qpos[8] = x0[0] - x0[1]                                 # phi_i = theta_w - theta_b
        slope = (c.mujoco or MujocoConfig()).slope
        d.qvel[0] = c.actual.r * x0[2] * math.cos(slope)                    # rolling along the slope, no slip
        d.qvel[2] = c.actual.r * x0[2] * math.sin(slope)
        d.qvel[4] = x0[3]                                                    # the pitch rate, body y
        d.qvel[6] = d.qvel[7] = x0[2] - x0[3]
        mj.mj_forward(self.model, d)
        self._read()

    @property
    def integration(self) -> str:
        steps = "1 RK4 step" if self.n == 1 else f"{self.n} RK4 steps"
        return f"MuJoCo {self._mj.__version__}, {steps} of {self.cfg.h / self.n * 1e3:g} ms"

    def _read(self, q=None, v=None) -> None:
        """:attr:`x` and :attr:`pose` from MuJoCo's state (``q``, ``v``: qpos and qvel as lists, if read already)."""
        if q is None:
            q, v = self._qpos.tolist(), self._qvel.tolist()
        pitch, yaw, roll = pose_angles(q[3], q[4], q[5], q[6])
        wl, wr = pitch + q[7], pitch + q[8]
        self.x = State(0.5 * (wl + wr), pitch, v[4] + 0.5 * (v[6] + v[7]), v[4])
        self.pose = Pose(q[0], q[1], q[2], yaw, pitch, roll, wl, wr)

    def imu_reading(self) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
        """MuJoCo's own gyro and accelerometer at the IMU site (the model has them with raw sensors, theory 6.4): the
        angular velocity and the specific force in the body frame, ((x, y, z), (x, y, z)), as of the last
        ``mj_forward``: after :meth:`sample_accel`, at t_k^- as the raw sample (docs/theory.md 6.4)."""
        v = self.data.sensordata.tolist()
        return tuple(v[:3]), tuple(v[3:6])

    @property
    def yaw_rate(self) -> float:
        """The body's angular rate about its own z axis at t_k [rad/s]: what a gyro on the body reads as yaw rate
        (cos(theta_b) psi' when the body turns at psi' about the vertical; docs/theory.md 6.13)."""
        return float(self._qvel[5])

    @property
    def wheel_rates(self) -> Tuple[float, float]:
        """Each wheel's absolute angular rate at t_k [rad/s] (left, right): the body's pitch rate plus its hinge's;
        their mean is theta_w' (:meth:`_read`)."""
        v = self._qvel
        return float(v[4] + v[6]), float(v[4] + v[7])

    @property
    def fallen(self) -> bool:
        x = self.x   # NaN or an infinity in a sum of the components makes it not finite: one check, not four
        return not (abs(x[1]) <= self.cfg.fall_angle and math.isfinite(x[0] + x[2] + x[3]))

    def _apply(self, t: float, ul: float, ur: float, D_w: float, extra) -> None:
        """The inputs at time ``t``: the wheels' torques ``ul``, ``ur``, D_w's and tau_ext's generalized forces from
        the current velocities (module docstring).  Element by element: a slice assignment costs numpy more."""
        c, f, ctrl = self.cfg, self._qfrc, self._ctrl
        e1, e2 = c.tau_ext1(t) + extra[0], c.tau_ext2(t) + extra[1]
        pitch_rate, _, wl, wr = self._qvel[4:8].tolist()   # the pitch rate (body y), the wheels' hinges
        ql = -0.5 * D_w * (pitch_rate + wl) + 0.5 * e1
        qr = -0.5 * D_w * (pitch_rate + wr) + 0.5 * e1
        ctrl[0] = ul
        ctrl[1] = ur
        f[4] = ql + qr + e2 - e1
        f[6] = ql
        f[7] = qr
        if len(extra) > 2 and (extra[2] or extra[3] or self._pushed):   # external_wrench's force.y, torque.z
            self._push(extra[2], extra[3])

    def _push(self, fy: float, tz: float) -> None:
        """external_wrench's lateral force ``fy`` [N] at the body's centre of gravity, along the robot's heading
        frame's y (REP-103: left), and its yaw torque ``tz`` [N m] about the vertical (docs/theory.md 6.10)."""
        w, x, y, z = self._qpos[3:7].tolist()
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        self.data.xfrc_applied[1, :] = (-math.sin(yaw) * fy, math.cos(yaw) * fy, 0.0, 0.0, 0.0, tz)
        self._pushed = bool(fy or tz)

    def _accel(self, u: float, D_w: float, extra, wheels=None) -> Tuple[float, float]:
        """(theta_w'', theta_b'') at the current state with the torque ``u`` (u / 2 per wheel, or the pair
        ``wheels``), MuJoCo's."""
        ul, ur = (0.5 * u, 0.5 * u) if wheels is None else wheels
        self._apply(self.k * self.cfg.h, ul, ur, D_w, extra)
        self._forward(self.model, self.data)
        a4, _, a6, a7 = self._qacc[4:8].tolist()
        return a4 + 0.5 * (a6 + a7), a4

    def lumped_disturbance(self, u: float, extra=(0.0, 0.0), wheels=None) -> Tuple[float, float]:
        """The true tau_d of eq. (6-7) at t_k on the planar coordinates (theta_w the wheels' mean, theta_b the pitch)
        with MuJoCo's accelerations and the torque ``u`` = u_L + u_R: (NaN, NaN) while a wheel is off the ground,
        where eq. (1)'s rolling x = r theta_w does not hold and there is no planar disturbance to estimate
        (docs/theory.md 6.10, "The true disturbance on the 3D plant")."""
        ddq = self._accel(u, self.D_w, extra, wheels)
        if not self.on_ground():
            return math.nan, math.nan
        return lumped_disturbance(self.cfg.nominal, self.x, ddq, u)

    def on_ground(self) -> bool:
        """Both wheels touch the ground (a contact of each with the plane or a step) as of the last ``mj_forward``."""
        d = self.data
        if d.ncon < 2:
            return False
        return self._wheel_geoms <= set(d.contact.geom[:d.ncon].ravel().tolist())

    def sample_accel(self) -> Tuple[float, float]:
        c = self.cfg
        u, wheels, cmd = self.u_prev, self.wheels_prev, self.wheels_cmd_prev
        if c.motor.enabled and self.k > 0 and self.enabled_prev:
            if wheels is not None and cmd is not None:   # the yaw stage's pair (the two are set together): each
                # wheel's half motor at its own rate
                half = self._half_motor(c.motor_constants)
                wheels = (motor_torque(cmd[0], float(self._qvel[6]), *half)[0],
                          motor_torque(cmd[1], float(self._qvel[7]), *half)[0])
                u = wheels[0] + wheels[1]
            else:
                u = motor_torque(self.u_cmd_prev, self.x[2] - self.x[3], *c.motor_constants)[0]
        return self._accel(u, self.D_w_prev, self.extra_prev, wheels)

    @staticmethod
    def _half_motor(motor):
        """One wheel's drive: half the lumped motor (K_t, 2 R, V_max, I_max / 2; theory 6.10)."""
        return (motor[0], 2.0 * motor[1], motor[2], 0.5 * motor[3])

    def step(self, u: float, extra=(0.0, 0.0), enabled: bool = True, wheels=None) -> None:
        """Integrate t_k -> t_{k+1}: :attr:`n` MuJoCo steps, each wheel's torque and the generalized forces held over
        each (tau_ext at its midpoint, D_w's term from its start); with the motor model, each wheel's drive is
        half the motor (K_t, 2 R, V_max, I_max / 2: the two sum to the one of eq. 1) with half the command.
        ``wheels``: the yaw stage's commands (u_L, u_R) (docs/theory.md 6.13) instead of u / 2 each.

        A period's Python is kept to a few microseconds (BENCHMARKS.md, "The lockstep graph with the MuJoCo plant"):
        MuJoCo's arrays are read as lists once (``tolist``) and written element by element, the divergence check is
        one sum, and its message is formatted only when it is raised (:meth:`_diverged`)."""
        c, m, d, n = self.cfg, self.model, self.data, self.n
        u, motor = gated_drive(u, c.motor_constants, enabled)
        if wheels is not None and not enabled:
            wheels = (0.0, 0.0)
        driven = motor[0] > 0.0
        cl, cr = (0.5 * u, 0.5 * u) if wheels is None else wheels
        t, dt, D_w, mj_step = self.k * c.h, c.h / n, self.D_w, self._step   # t = self.t
        acted = acted_l = acted_r = 0.0
        sat = 0
        if driven:
            half = self._half_motor(motor)
            for i in range(n):
                wl, wr = self._qvel[6:8].tolist()
                ul, sl = motor_torque(cl, wl, *half)
                ur, sr = motor_torque(cr, wr, *half)
                sat = max(sat, sl, sr)
                acted += ul + ur
                acted_l += ul
                acted_r += ur
                self._apply(t + (i + 0.5) * dt, ul, ur, D_w, extra)
                mj_step(m, d)
        else:
            for i in range(n):
                self._apply(t + (i + 0.5) * dt, cl, cr, D_w, extra)
                mj_step(m, d)
        q, v = self._qpos.tolist(), self._qvel.tolist()
        if any(self._warnings.tolist()) or not math.isfinite(sum(q) + sum(v)):
            self._diverged()   # x and pose stay those of t_k: no state that is not finite leaves the plant
        self._read(q, v)
        self.k += 1
        self.saturation = sat
        self.u_prev, self.u_cmd_prev, self.enabled_prev = (acted / n if driven else u), u, bool(enabled)
        if wheels is not None:
            self.wheels_prev = (acted_l / n, acted_r / n) if driven else (cl, cr)
            self.wheels_cmd_prev = (cl, cr)
            if not driven:
                self.u_prev = cl + cr
        self.D_w_prev, self.extra_prev = D_w, tuple(map(float, extra))
        self.D_w = self._draw_D_w()

    def lie(self) -> None:
        """A period of a fallen robot lying where it fell (:meth:`.plant.PlantSim.lie`): MuJoCo's velocities zeroed
        too (its wheels' and body's: the state, ``true_wheel_states`` and the IMU read them), no torque, no wrench."""
        self._qvel[:] = 0.0
        self._ctrl[:] = 0.0
        self._qfrc[:] = 0.0
        if self._pushed:
            self._push(0.0, 0.0)
        self._read()
        self.k += 1
        self.u_prev = self.u_cmd_prev = 0.0
        self.saturation, self.enabled_prev = 0, False
        self.extra_prev = (0.0,) * len(self.extra_prev)
        if self.wheels_prev is not None:
            self.wheels_prev = self.wheels_cmd_prev = (0.0, 0.0)

    def _diverged(self) -> None:
        """After the period [t_k, t_k+1], on a MuJoCo warning (on a diverged state MuJoCo warns and resets it to the
        model's initial one, silently) or a state that is not finite (a sum of qpos and qvel that is not: NaN and
        infinities propagate through it): raise :class:`PlantDiverged` naming the time and the cause."""
        where = f"the MuJoCo simulation diverged in [{self.t:.6g}, {self.t + self.cfg.h:.6g}] s"
        if any(self._warnings.tolist()):
            names = [self._mj.mjtWarning(i).name for i, n in enumerate(self._warnings.tolist()) if n]
            raise PlantDiverged(f"{where}: {', '.join(f'{n} ({_WHY.get(n, n)})' for n in names)}")
        raise PlantDiverged(f"{where}: a state that is not finite")


_WHY = {"mjWARN_BADQACC": "accelerations not finite or beyond 1e10",
        "mjWARN_BADQPOS": "a position not finite or beyond 1e10",
        "mjWARN_BADQVEL": "a velocity not finite or beyond 1e10",
        "mjWARN_BADCTRL": "a torque that is not finite or beyond 1e10",
        "mjWARN_CONTACTFULL": "too many contacts", "mjWARN_CNSTRFULL": "too many constraints",
        "mjWARN_INERTIA": "an inertia matrix is not positive definite"}
