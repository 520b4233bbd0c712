"""Upkie behind the project's :class:`~mwip_ros.robot.backend.Backend`, through the ``upkie`` package's own backends
(SPEC section 16; docs/hardware-upkie.md).

Upkie (upkie/upkie, PyPI ``upkie``) is a wheeled biped: two legs (hip and knee, mjbots qdd100 servos) end in wheels
(mj5208 motors driven by moteus controllers). In its pendulum posture the legs are held straight and the robot is an
MWIP. Its Python agent talks to one small interface, ``upkie.envs.backends.Backend`` (``get_spine_observation``,
``reset``, ``step``, ``close``), with three implementations: ``PyBulletBackend`` (a simulation, headless here),
``SpineBackend`` (the robot's spine over shared memory: what a user runs on the robot; it cannot be run here) and
``MockBackend``. :class:`UpkieBackend` wraps the first two.

**The action** (moteus semantics, SPEC 16: ``tau = feedforward_torque + kd_scale kd (velocity - v) + kp_scale kp
(position - p)``, clipped to ``maximum_torque``):

- each leg joint (hips, knees) is held at position 0 (legs straight) by the servo's PD, with ``kp_scale =
  leg_kp_scale``, ``kd_scale = leg_kd_scale`` and ``maximum_torque = leg_maximum_torque`` (:class:`UpkieConfig` says
  how the scales were chosen);
- each wheel is in pure torque control: ``position`` NaN, ``velocity`` 0, ``kp_scale = kd_scale = 0``,
  ``feedforward_torque`` the wheel's torque, ``maximum_torque = wheel_maximum_torque``;
- a stop (``step(None)``): every servo at zero torque (all gains 0, ``maximum_torque`` 0): no torque, as a moteus
  stop is.

**Wheel signs** (SPEC 16): with ``upkie.model.Model().left_wheeled`` true (Upkie v1, v2), forward rolling is +phi_L and
-phi_R: the left wheel's servo position, velocity and torque are taken as they are and the right one's negated, and
a command's torques go out as +u_L on the left joint and -u_R on the right one; ``left_wheeled`` false flips both.

**The IMU** (SPEC 16): the observation's ``imu.angular_velocity`` (rad/s) and ``imu.raw_linear_acceleration`` (the
proper acceleration, m/s^2) are in the IMU link's axes; both are rotated into REP-145's ``imu_link`` (REP-103: x
forward, y left, z up along the body), the planar model's body frame, whose z_b points from the axle to the body's
centre of mass (:attr:`~.planar_model.PlanarModel.imu_rotation`, from the URDF: Upkie's IMU link is the base turned
by pi about y, and the body frame is the base pitched by the model's ``com_angle``).

**The truth** (PyBullet only, :meth:`UpkieBackend.true_state`): eq. (1)'s theta_b is the lean of the line from the
axle (the tyres' mean centre) to the body's centre of mass (every link but the wheel sets), measured in the robot's
heading plane (REP-103: > 0 leaning forward), and theta_b' its rate, both from PyBullet's link states: so the legs'
bending, which moves the centre of mass against the base, is in it. theta_w = phi + theta_b and theta_w' = phi' +
theta_b' (phi the mean of both wheels in the forward sense), as the estimator forms them. (The base's pitch plus
``com_angle`` is the same lean for straight, rigid legs; the legs' PD lets them bend by milliradians under the body's
weight and by more under the wheels' reaction.)

**Time and stepping** (PyBullet): ``PyBulletBackend(dt)`` integrates ``nb_substeps`` physics steps of ``dt /
nb_substeps`` per :meth:`UpkieBackend.step` (default ``int(1000 dt)``: 1 kHz, 5 steps under a 5 ms period), the
wheels' torque recomputed by the moteus law at every sub-step, the action held over the period. It advances only
when stepped (``setRealTimeSimulation(False)``): a lockstep driver steps it on demand, a realtime one paces it to the
wall clock. In DIRECT mode (``gui=False``) nothing draws and nothing is random (the backend draws noise only when
``JointProperties`` asks for it, and it does not here). The first reset places the robot and saves the world
(``saveState``); every later one restores it (``restoreState``), contacts and solver included, so two runs give the
same numbers to the bit. (Placing the robot again instead keeps the contact solver's state from the last run, and
restoring a world saved before the placement leaves the wheels nearly stuck: both were measured.) PyBullet keeps
one physics server per connection, and Upkie's backend calls PyBullet without a client id (the first connection):
one :class:`UpkieBackend` on PyBullet per process at a time (a second is refused).

The IMU's acceleration is Upkie's own finite difference of the IMU link's velocity over ``dt`` at each observation,
so the backend reads the simulation once per period (:meth:`UpkieBackend.observe` returns that read; reading it
again would difference over no time). PyBullet loads the URDF without ``URDF_USE_INERTIA_FROM_FILE``: it recomputes
each link's inertia from its collision shapes (:func:`pybullet_inertias`), so the robot it simulates has another
I_w and I_b than the URDF's inertial tags say (docs/hardware-upkie.md).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import ClassVar, Dict, Mapping, Optional, Tuple

import numpy as np

from ..core.plants.plant import Pose
from .backend import Backend, BackendError, Command, Imu, Observation, Wheel
from .planar_model import UPKIE_WHEEL_JOINTS, PlanarModel, upkie_planar_model

__all__ = ["LEG_JOINTS", "WHEEL_JOINTS", "UpkieConfig", "UpkieBackend", "spine_action", "observation_from_spine",
           "pybullet_inertias", "UPKIE_KINDS"]

LEG_JOINTS = ("left_hip", "left_knee", "right_hip", "right_knee")
WHEEL_JOINTS = UPKIE_WHEEL_JOINTS   # Upkie's wheel joints (robot.planar_model)
UPKIE_KINDS = ("pybullet", "spine")
NO_JOYSTICK = "/dev/null/no-joystick"   # a path that cannot exist: Upkie's backends then read no gamepad


@dataclass(frozen=True)
class UpkieConfig:
    """How :class:`UpkieBackend` drives Upkie.

    Attributes
    ----------
    dt : float
        The control period [s] (200 Hz: 0.005).
    leg_kp_scale, leg_kd_scale : float
        ``kp_scale`` and ``kd_scale`` of the hips and knees (their PD holds them at 0; PyBullet's kp is 20 N m/rad and
        kd 1 N m s/rad per joint, scaled by these). SPEC 16 found the legs' compliance inside the balance loop's
        bandwidth; 12.6 and 4.0 were chosen with the law and the estimator in PyBullet (docs/hardware-upkie.md, "The
        legs", has the scan: kd too low or too high for the kp and the robot falls; the legs' static bend, and the
        lean the robot stands with, fall as kp grows). On the robot the scales multiply its moteus configuration's
        gains.
    leg_maximum_torque : float
        The legs' ``maximum_torque`` [N m]: 16, the qdd100's limit in the URDF.
    wheel_maximum_torque : float
        Each wheel's ``maximum_torque`` [N m], the servo's own clip (the lumped limit is the caller's
        ``torque_limit``; docs/hardware-upkie.md): 1.7, the mj5208's limit in the URDF.
    initial_pitch : float
        Eq. (1)'s theta_b at :meth:`UpkieBackend.reset` [rad] (PyBullet: the robot is placed leaning so, at rest,
        its tyres on the ground).
    substeps : int
        PyBullet's physics steps per period; 0: ``int(1000 dt)`` (1 kHz, Upkie's spine rate).
    shm_name : str
        The spine's shared memory (``SpineBackend``).
    """

    dt: float = 0.005
    leg_kp_scale: float = 12.6
    leg_kd_scale: float = 4.0
    leg_maximum_torque: float = 16.0
    wheel_maximum_torque: float = 1.7
    initial_pitch: float = 0.0
    substeps: int = 0
    shm_name: str = "/upkie"

    def checked(self) -> "UpkieConfig":
        """Itself, or ValueError naming the first value out of range."""
        for key, value, ok in (("dt", self.dt, 0.0 < self.dt <= 1.0),
                               ("leg_kp_scale", self.leg_kp_scale, 0.0 <= self.leg_kp_scale <= 100.0),
                               ("leg_kd_scale", self.leg_kd_scale, 0.0 <= self.leg_kd_scale <= 100.0),
                               ("leg_maximum_torque", self.leg_maximum_torque, 0.0 <= self.leg_maximum_torque <= 100.0),
                               ("wheel_maximum_torque", self.wheel_maximum_torque,
                                0.0 <= self.wheel_maximum_torque <= 100.0),
                               ("initial_pitch", self.initial_pitch, abs(self.initial_pitch) < 1.0),
                               ("substeps", self.substeps, 0 <= self.substeps <= 1000)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and ok):
                raise ValueError(f"upkie: {key} = {value!r} is out of range")
        return self


def spine_action(command: Optional[Command], config: UpkieConfig, left_wheeled: bool) -> Dict[str, dict]:
    """The spine action (Upkie's ``{"servo": {joint: {...}}}``) for ``command`` (module docstring, "The action").

    Parameters
    ----------
    command : Command or None
        Each wheel's torque in the robot's forward sense [N m]; None: a stop (no torque on any servo).
    config : UpkieConfig
        The legs' gains and every servo's torque cap.
    left_wheeled : bool
        ``upkie.model.Model().left_wheeled``: forward rolling is + on the left joint and - on the right one.

    Returns
    -------
    dict
        The action dictionary ``step`` takes.
    """
    servo: Dict[str, dict] = {}
    if command is None:
        for name in LEG_JOINTS + WHEEL_JOINTS:
            servo[name] = {"position": math.nan, "velocity": 0.0, "feedforward_torque": 0.0, "kp_scale": 0.0,
                           "kd_scale": 0.0, "maximum_torque": 0.0}
        return {"servo": servo}
    for name in LEG_JOINTS:
        servo[name] = {"position": 0.0, "velocity": 0.0, "feedforward_torque": 0.0,
                       "kp_scale": config.leg_kp_scale, "kd_scale": config.leg_kd_scale,
                       "maximum_torque": config.leg_maximum_torque}
    sign = 1.0 if left_wheeled else -1.0
    for name, torque in (("left_wheel", sign * command.left), ("right_wheel", -sign * command.right)):
        servo[name] = {"position": math.nan, "velocity": 0.0, "feedforward_torque": float(torque), "kp_scale": 0.0,
                       "kd_scale": 0.0, "maximum_torque": config.wheel_maximum_torque}
    return {"servo": servo}


def _wheel(servo: Mapping[str, float], sign: float) -> Wheel:
    return Wheel(sign * float(servo["position"]), sign * float(servo["velocity"]), sign * float(servo["torque"]))


def observation_from_spine(obs: Mapping[str, dict], t: float, left_wheeled: bool,
                           body_from_imu: np.ndarray) -> Observation:
    """One :class:`~.backend.Observation` from a spine observation dictionary (module docstring).

    Parameters
    ----------
    obs : mapping
        Upkie's spine observation (``servo``, ``imu``, ``base_orientation``, ...).
    t : float
        Its time [s].
    left_wheeled : bool
        ``upkie.model.Model().left_wheeled``.
    body_from_imu : 3x3 array
        The rotation of the IMU link's axes into ``imu_link``'s (:attr:`PlanarModel.imu_rotation`).

    Returns
    -------
    Observation
        The wheels in the forward sense, the IMU in ``imu_link`` axes, a servo's fault (a nonzero moteus ``fault``
        code, or a servo missing from the observation) named in ``fault``.
    """
    servos = obs.get("servo", {})
    missing = [name for name in WHEEL_JOINTS + LEG_JOINTS if name not in servos]
    faults = [f"{name}: moteus fault {int(servos[name]['fault'])}" for name in WHEEL_JOINTS + LEG_JOINTS
              if name in servos and int(servos[name].get("fault", 0) or 0) != 0]
    fault = None
    if missing:
        fault = f"upkie: no reply from servo(s) {', '.join(missing)}"
    elif faults:
        fault = "upkie: " + "; ".join(faults)
    sign = 1.0 if left_wheeled else -1.0
    if "left_wheel" in servos and "right_wheel" in servos:
        left, right = _wheel(servos["left_wheel"], sign), _wheel(servos["right_wheel"], -sign)
    else:
        left = right = Wheel(math.nan, math.nan, math.nan)
    imu = None
    raw = obs.get("imu")
    if raw is not None and "angular_velocity" in raw and "raw_linear_acceleration" in raw:
        w = body_from_imu @ np.asarray(raw["angular_velocity"], dtype=float)
        f = body_from_imu @ np.asarray(raw["raw_linear_acceleration"], dtype=float)
        imu = Imu(tuple(float(v) for v in w), tuple(float(v) for v in f))
    return Observation(time=t, left=left, right=right, imu=imu, fault=fault)


def pybullet_inertias(robot_id: int, client: int = 0) -> Dict[str, np.ndarray]:
    """The inertia tensor PyBullet simulates for each link of a body, about the link's centre of mass in the link's own
    frame (what :func:`~.planar_model.planar_model`'s ``inertias`` takes): ``getDynamicsInfo``'s principal moments
    rotated by its local inertial orientation.

    Parameters
    ----------
    robot_id : int
        The body's PyBullet id.
    client : int
        The physics client.

    Returns
    -------
    dict
        Link name (the base link's too) -> 3x3 array [kg m^2].
    """
    import pybullet
    out = {}
    names = {-1: pybullet.getBodyInfo(robot_id, physicsClientId=client)[0].decode()}
    for i in range(pybullet.getNumJoints(robot_id, physicsClientId=client)):
        names[i] = pybullet.getJointInfo(robot_id, i, physicsClientId=client)[12].decode()
    for i, name in names.items():
        info = pybullet.getDynamicsInfo(robot_id, i, physicsClientId=client)
        rot = np.array(pybullet.getMatrixFromQuaternion(info[4])).reshape(3, 3)
        out[name] = rot @ np.diag(info[2]) @ rot.T
    return out


class UpkieBackend(Backend):
    """Upkie through one of the ``upkie`` package's backends (module docstring).

    Build it with :meth:`pybullet` (a simulation, :attr:`simulated`) or :meth:`spine` (the robot: not testable here).
    (Upkie's ``MockBackend`` is not offered: its IMU has no ``raw_linear_acceleration`` and it mirrors a servo's
    ``position``, ``velocity`` and ``torque`` keys, not the ``feedforward_torque`` a torque command sends.)"""

    name: ClassVar[str] = "upkie"
    simulated: ClassVar[bool] = False
    _pybullet_open: ClassVar[bool] = False

    def __init__(self, inner, kind: str, config: UpkieConfig, model: Optional[PlanarModel] = None,
                 left_wheeled: bool = True):
        """Wrap ``inner``, an ``upkie.envs.backends.Backend`` of ``kind`` (one of :data:`UPKIE_KINDS`), driven as
        ``config`` says; ``model`` the planar model (default: :func:`~.planar_model.upkie_planar_model`),
        ``left_wheeled`` the wheel signs."""
        if kind not in UPKIE_KINDS:
            raise ValueError(f"upkie backend kind {kind!r}: one of {', '.join(UPKIE_KINDS)}")
        self.inner, self.kind, self.config = inner, kind, config.checked()
        self.model = model if model is not None else upkie_planar_model()
        self.left_wheeled = bool(left_wheeled)
        self.simulated = kind == "pybullet"   # type: ignore[misc]  (per instance: the kind decides)
        self._body_from_imu = self.model.body_from_imu()
        self._k = 0
        self._last: Optional[Observation] = None
        self._closed = False
        self._masses = None   # PyBullet: the body links, their masses, the tyres (true_state)
        self._snapshot = None   # PyBullet: the world at t = 0 (saveState at the first reset), restored at every reset
        self._pushed = False
        self._indices: Dict[Tuple[int, str], int] = {}   # PyBullet's link and joint indices by name

    # construction ---------------------------------------------------------------------------------------------------

    @classmethod
    def pybullet(cls, config: UpkieConfig = UpkieConfig(), model: Optional[PlanarModel] = None) -> "UpkieBackend":
        """Upkie in its own PyBullet simulation, headless (DIRECT), stepped on demand."""
        if cls._pybullet_open:
            raise BackendError("upkie: a PyBullet Upkie is open in this process already (one physics client at a time)")
        try:
            from upkie.envs.backends import PyBulletBackend
            from upkie.model import Model
        except ImportError as exc:
            raise BackendError(f"upkie: the packages upkie and pybullet are needed ({exc})") from exc
        config = config.checked()
        up = Model()
        inner = PyBulletBackend(dt=config.dt, gui=False, js_path=NO_JOYSTICK,
                                nb_substeps=config.substeps or None, model=up)
        cls._pybullet_open = True
        return cls(inner, "pybullet", config, model, up.left_wheeled)

    @classmethod
    def spine(cls, config: UpkieConfig = UpkieConfig(), model: Optional[PlanarModel] = None) -> "UpkieBackend":
        """Upkie's spine (``SpineBackend`` on ``config.shm_name``): the robot, or Upkie's own Bullet spine. Not tested
        here (no spine runs on this machine); a spine that does not answer is a :class:`BackendError`."""
        try:
            from upkie.envs.backends import SpineBackend
            from upkie.model import Model
        except ImportError as exc:
            raise BackendError(f"upkie: the package upkie is needed ({exc})") from exc
        up = Model()
        try:
            inner = SpineBackend(shm_name=config.shm_name, model=up)
        except Exception as exc:   # noqa: BLE001 - upkie's SpineError, a missing shared memory, ...: one line
            raise BackendError(f"upkie: no spine at {config.shm_name} ({type(exc).__name__}: {exc})") from exc
        return cls(inner, "spine", config, model, up.left_wheeled)

    # the interface ---------------------------------------------------------------------------------------------------

    def _time(self) -> float:
        return self._k * self.config.dt if self.simulated else time.monotonic()

    def _convert(self, obs: Mapping[str, dict]) -> Observation:
        read = observation_from_spine(obs, self._time(), self.left_wheeled, self._body_from_imu)
        if self.simulated:
            read = replace(read, truth=self.true_state(read))
        self._last = read
        return read

    def observe(self) -> Observation:
        """The last read (a simulator's current sample; PyBullet's IMU is differenced between reads, so it is read
        once a period), or on a device a new query."""
        self._open()
        if self.simulated and self._last is not None:
            return self._last
        return self._convert(self.inner.get_spine_observation())

    def reset(self) -> Observation:
        """PyBullet: the robot placed at rest, leaning ``config.initial_pitch`` (eq. 1's theta_b), its tyres on the
        ground, legs straight; the spine: stopped and started again; and the first read."""
        self._open()
        self._k = 0
        if not self.simulated:
            return self._convert(self.inner.reset())
        import pybullet
        if self._pushed:
            self.push(0.0)
        if self._snapshot is None:   # the robot placed, one physics step: the state every reset returns to
            self.inner.reset(self._initial_state())
            self._snapshot = pybullet.saveState()
        else:
            pybullet.restoreState(self._snapshot)
        # Upkie differences the IMU's velocity between reads: the first read syncs it, so the second's acceleration
        # spans no time (the robot at rest: the IMU reads gravity alone); and no torque acted before t = 0
        self.inner.get_spine_observation()
        read = self._convert(self.inner.get_spine_observation())
        zero = [replace(w, torque=0.0) for w in (read.left, read.right)]
        self._last = replace(read, left=zero[0], right=zero[1])
        return self._last

    def step(self, command: Optional[Command]) -> Observation:
        """Write ``command`` (None: a stop) and return the next read (PyBullet: one period integrated first). A command
        that is not finite is refused (ValueError) and nothing is written."""
        self._open()
        if command is not None and not all(math.isfinite(v) for v in (command.left, command.right)):
            raise ValueError(f"upkie: a command that is not finite ({command}) is not written")
        obs = self.inner.step(spine_action(command, self.config, self.left_wheeled))
        self._k += 1
        return self._convert(obs)

    def close(self) -> None:
        """A stop (no torque on any servo), then the inner backend closed (PyBullet disconnected, the spine stopped).
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.kind != "pybullet":
                self.inner.step(spine_action(None, self.config, self.left_wheeled))
        finally:
            self.inner.close()
            if self.kind == "pybullet":
                type(self)._pybullet_open = False

    def _open(self) -> None:
        if self._closed:
            raise BackendError(f"upkie ({self.kind}): the backend is closed")

    # the simulator's privileges (PyBullet) ---------------------------------------------------------------------------

    def _initial_state(self):
        """Upkie's ``RobotState`` leaning ``initial_pitch``: the base pitched by theta_b - com_angle about the axle,
        the axle one tyre radius (plus 0.5 mm) above the ground."""
        from scipy.spatial.transform import Rotation
        from upkie.utils.robot_state import RobotState
        beta = self.config.initial_pitch - self.model.com_angle
        up = self._base_above_axle()
        pos = np.array([up * math.sin(beta), 0.0, self.model.r + 5e-4 + up * math.cos(beta)])
        return RobotState(orientation_base_in_world=Rotation.from_euler("y", beta), position_base_in_world=pos)

    def _base_above_axle(self) -> float:
        import pybullet
        rid = self.inner.robot_id
        tyres = [self._link_index(name) for name in ("left_wheel_tire", "right_wheel_tire")]
        base, _ = pybullet.getBasePositionAndOrientation(rid)
        pybullet.resetBasePositionAndOrientation(rid, base, (0.0, 0.0, 0.0, 1.0))
        for name in LEG_JOINTS + WHEEL_JOINTS:
            pybullet.resetJointState(rid, self._joint_index(name), 0.0, 0.0)
        z = [pybullet.getLinkState(rid, i, computeForwardKinematics=True)[4][2] for i in tyres]
        base, _ = pybullet.getBasePositionAndOrientation(rid)
        return float(base[2] - 0.5 * (z[0] + z[1]))

    def _index(self, name: str, field: int, what: str) -> int:
        """PyBullet's index of the link (``field`` 12) or joint (1) ``name``, looked up once."""
        key = (field, name)
        if key not in self._indices:
            import pybullet
            rid = self.inner.robot_id
            found = [i for i in range(pybullet.getNumJoints(rid))
                     if pybullet.getJointInfo(rid, i)[field].decode() == name]
            if not found:
                raise BackendError(f"upkie: the simulated robot has no {what} {name!r}")
            self._indices[key] = found[0]
        return self._indices[key]

    def _link_index(self, name: str) -> int:
        return self._index(name, 12, "link")

    def _joint_index(self, name: str) -> int:
        return self._index(name, 1, "joint")

    def _simulator(self) -> None:
        self._open()
        if not self.simulated:
            raise BackendError(f"upkie ({self.kind}): only the PyBullet simulation has this")

    def _body_masses(self):
        """(link indices, masses) of the body's links (every link but the wheel sets; -1 the base), read once."""
        if self._masses is None:
            import pybullet
            rid = self.inner.robot_id
            wheel = set(self.model.wheel_links)
            idx = [-1] + [i for i in range(pybullet.getNumJoints(rid))
                          if pybullet.getJointInfo(rid, i)[12].decode() not in wheel]
            self._masses = (idx, np.array([pybullet.getDynamicsInfo(rid, i)[0] for i in idx]),
                            [self._link_index(n) for n in ("left_wheel_tire", "right_wheel_tire")])
        return self._masses

    def true_state(self, read: Observation) -> Tuple[float, float, float, float]:
        """The true planar state (theta_w, theta_b, theta_w', theta_b') of the simulation now (module docstring, "The
        truth"): the body's centre of mass against the axle in the heading plane, with ``read``'s wheels."""
        self._simulator()
        import pybullet
        rid = self.inner.robot_id
        idx, m, tyres = self._body_masses()
        base_p, base_q = pybullet.getBasePositionAndOrientation(rid)
        base_v, _ = pybullet.getBaseVelocity(rid)
        states = pybullet.getLinkStates(rid, idx[1:], computeLinkVelocity=1)
        pos = np.array([base_p] + [s[0] for s in states])
        vel = np.array([base_v] + [s[6] for s in states])
        com, dcom = m @ pos / m.sum(), m @ vel / m.sum()
        tyre = pybullet.getLinkStates(rid, tyres, computeLinkVelocity=1)
        axle = 0.5 * (np.array(tyre[0][0]) + np.array(tyre[1][0]))
        daxle = 0.5 * (np.array(tyre[0][6]) + np.array(tyre[1][6]))
        yaw = pybullet.getEulerFromQuaternion(base_q)[2]
        fwd = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        d, dd = com - axle, dcom - daxle
        x, z, dx, dz = float(fwd @ d), float(d[2]), float(fwd @ dd), float(dd[2])
        theta_b = math.atan2(x, z)
        dtheta_b = (z * dx - x * dz) / (x * x + z * z)
        return read.phi + theta_b, theta_b, read.phi_rate + dtheta_b, dtheta_b

    def axle_position(self) -> Tuple[float, float]:
        """The axle's centre in the world's x-y plane [m] (PyBullet): the mean of both tyres' centres."""
        self._simulator()
        import pybullet
        rid = self.inner.robot_id
        p = [pybullet.getLinkState(rid, self._link_index(n), computeForwardKinematics=True)[4]
             for n in ("left_wheel_tire", "right_wheel_tire")]
        return 0.5 * (p[0][0] + p[1][0]), 0.5 * (p[0][1] + p[1][1])

    def true_pose(self) -> Optional[Pose]:
        """The robot's pose at the last read (PyBullet; None on the spine): the axle's centre (x, y, z) [m], the base's
        yaw and roll [rad] (PyBullet's Euler angles), eq. (1)'s theta_b as the pitch (the truth's) and each wheel's
        angle, phi + theta_b [rad]."""
        if not self.simulated or self._last is None or self._last.truth is None:
            return None
        import pybullet
        rid = self.inner.robot_id
        p = [pybullet.getLinkState(rid, self._link_index(n), computeForwardKinematics=True)[4]
             for n in ("left_wheel_tire", "right_wheel_tire")]
        roll, _pitch, yaw = pybullet.getEulerFromQuaternion(pybullet.getBasePositionAndOrientation(rid)[1])
        th = self._last.truth[1]
        return Pose(0.5 * (p[0][0] + p[1][0]), 0.5 * (p[0][1] + p[1][1]), 0.5 * (p[0][2] + p[1][2]), yaw, th, roll,
                    self._last.left.position + th, self._last.right.position + th)

    def push(self, force_x: float, force_y: float = 0.0, link: str = "torso") -> None:
        """Hold a horizontal force [N] on ``link``'s centre of mass, in the world frame, from the next step until the
        next call (0, 0: let go). Upkie's torso's centre is 0.307 m above the axle, 0.026 m above the body's."""
        self._simulator()
        from upkie.utils.external_force import ExternalForce
        self.inner.set_external_forces({link: ExternalForce([float(force_x), float(force_y), 0.0])})
        self._pushed = True

    def simulated_model(self) -> PlanarModel:
        """The planar model of the robot PyBullet simulates: the URDF's geometry and masses with PyBullet's own inertia
        tensors (:func:`pybullet_inertias`)."""
        self._simulator()
        from upkie.model import Model
        from .planar_model import UPKIE_IMU_LINK, planar_model
        return planar_model(Model().urdf_path, UPKIE_WHEEL_JOINTS, imu_link=UPKIE_IMU_LINK,
                            inertias=pybullet_inertias(self.inner.robot_id))
