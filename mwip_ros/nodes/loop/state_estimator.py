"""``state_estimator``: the raw IMU and encoder of a ``sensors.model: raw`` plant to the state (theory 6.4), a node.

Subscribes ``imu/data_raw`` and ``wheel_encoder``, pairs the two samples of one stamp (``imu_sync: stamp``; with
``imu_sync: latest`` each encoder sample takes the newest IMU sample instead, below), runs the configured
estimator (``method``: complementary or kalman, :mod:`mwip_ros.core.estimators`; ``imu_offset`` and the
method's own parameters) and publishes ``joint_states`` in the layout of section 7 (the estimate's positions
and velocities, effort = the torque the encoder's driver reported) with the sample's stamp; when the plant_sim
sections of its parameter files choose ``backend: mujoco``, a third joint ``yaw`` carries the IMU's z gyro
(angular_velocity.z), the yaw stage's input (docs/theory.md 6.13).

In lockstep each stamp is answered once; a repeated stamp (the plant resending a sample nobody answered) is
answered again with the same message and integrated nothing.  A sample it cannot use (malformed, non-finite,
implausible: ``mwip_ros.msgs.layouts.RAW_LIMITS``, a wrong joint name or frame_id; a stamp outside the stream's
window or older than the last: :mod:`.guards`) is rejected, counted and logged, and never integrated; a sample
whose partner of the other stream has not come when a later pair is complete, or within ``PAIR_WAIT_S`` of wall
time, is dropped and counted.  In realtime the two raw subscriptions carry a DDS content filter
(``layouts.RAW_FILTERS``, :mod:`mwip_ros.nodes.runtime.content_filter`): a sample with a wrong frame or joint, a
value outside ``RAW_LIMITS`` or bytes that cannot be deserialized is dropped by the middleware before the reader's
queue (a flood of them cannot displace genuine samples, issue 30) and is not counted; the log and
``/diagnostics`` (``content_filter``) say so.  A sample moves its stream's time only when its pair is estimated,
so a lone sample ahead of the stream costs nothing.  A stream that restarted (a plant's ``~/reset``, a new plant: stamps
that agree away from the stream, :mod:`.guards`) re-initialises the estimator, but only while the topic has one
publisher: stamps from a second publisher never restart it.  The estimator integrates over the time the stamps
give (two periods after a lost pair; at most ``MAX_GAP_S``, a longer gap re-initialises it).
Its health (innovation, normalized innovation squared and its running mean, diverged) is on
``/diagnostics``: ERROR while the estimator says it diverged, published at once when it changes (and once a
second); a diverged estimate is never published on ``joint_states`` (withheld and counted).  With ``csv`` set
(when the schema has the parameter) it writes the samples and the estimates (``t``, ``gyro``, ``accel_x``,
``accel_z``, ``encoder``, ``encoder_rate``, ``theta_w_hat``, ``theta_b_hat``, ``dtheta_w_hat``, ``dtheta_b_hat``:
mwip_sim's raw columns) as it goes.

**An IMU with its own driver** (``imu_sync: latest``, docs/hardware.md): on a robot whose IMU is read by its own ROS
driver (a moteus robot: the emulator's IMU at 400 Hz on its own clock) the IMU's stamps never meet the wheel driver's.
The estimator then does what a ROS controller does with a sensor topic of another rate: it keeps the newest IMU
message (a realtime buffer of one) and, at each encoder sample, runs one step with it, so the estimate comes at the
encoders' rate and stamp.  The IMU sample is at most one IMU period older than the encoder's (2.5 ms at 400 Hz,
plus its transport); one further than ``imu_max_age_s`` from the encoder's stamp (older, or ahead of it) is not
used: the encoder sample is dropped and counted, so an IMU that stopped stops the estimates (the controller then
gets no state, and the driver's watchdog stops the robot).  A repeated encoder stamp (a lockstep resend) is
answered again.  ``imu_sync: stamp`` stays the default and is unchanged: the lockstep oracle's pairs, bit for bit.
"""
from __future__ import annotations

import sys
import time

from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from mwip_ros import params as P
from mwip_ros.core.plants.raw_sensors import RawSample
from mwip_ros.core.closed_loop.trajectory import ESTIMATE_COLUMNS, RAW_COLUMNS
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import qos_for
from mwip_ros.nodes.runtime.content_filter import filter_readers
from mwip_ros.nodes.runtime.diagnostics import ERROR, OK
from mwip_ros.nodes.runtime.guards import (NEW, REPEAT, RESTART, STAMP_WINDOW_PERIODS, PublisherWatch, Rejects,
                                           StampGuard,
                                           sole_publisher)
from mwip_ros.nodes.runtime.params import declare, plant_file_values
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node
from mwip_ros.runs import CsvStream

NAME = "state_estimator"
IMU_TOPIC, ENCODER_TOPIC = "imu/data_raw", "wheel_encoder"
PARTNER = {IMU_TOPIC: ENCODER_TOPIC, ENCODER_TOPIC: IMU_TOPIC}
PAIR_WAIT_S = 1.0       # wall time a sample waits for its partner of the other stream before it is dropped
_MAX_PENDING = 64       # samples of one stream waiting for their partner, at most
MAX_GAP_S = 1.0         # the longest time between two estimated pairs integrated over; longer re-initialises
_CSV_COLUMNS = ("t", *RAW_COLUMNS, *ESTIMATE_COLUMNS)


class StateEstimatorNode(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.h = P.period(self.v)
        self.period_ns = round(self.h * 1e9)
        nominal = P.physical(self.v, "nominal")
        self.config = P.typed.estimator(self.v)   # the method, its parameters, the IMU offset it believes
        # a spatial plant (its files' backend mujoco): the IMU's z gyro goes on as the yaw joint (theory 6.13)
        self.spatial = plant_file_values(argv, ("backend",)).get("backend") == "mujoco"
        try:
            self.est = self.config.make(self.h, nominal.r, nominal.g)
        except (KeyError, ValueError) as exc:   # the schema checked them; a plug-in estimator's own check
            raise P.ParamError("method", str(exc).strip("'\"")) from None
        window = STAMP_WINDOW_PERIODS * self.period_ns
        self.stamp_guards = {t: StampGuard(window, f"{t} stamp", sole_publisher(self, t))
                             for t in (IMU_TOPIC, ENCODER_TOPIC)}
        self.pending = {IMU_TOPIC: {}, ENCODER_TOPIC: {}}   # topic -> {stamp: (parsed, arrival, restarted)}
        self.latest = self.v["imu_sync"] == "latest"   # the IMU at its own rate: the newest sample held (module doc)
        self.imu_max_age_ns = round(self.v["imu_max_age_s"] * 1e9)
        self.newest_imu = None    # imu_sync latest: (stamp, parsed, restarted) of the newest IMU sample
        self.imu_stale = 0        # encoder samples dropped for want of an IMU sample within imu_max_age_s
        self.answered = None      # the stamp of the last sample pair answered
        self.last_msg = None      # its joint_states message (answered again for a resent sample)
        self.count = 0
        self.unpaired = 0
        self.was_diverged = False
        self.withheld = 0         # diverged estimates not published
        self.rejects = Rejects(self.get_logger())
        csv_path = self.v.get("csv") or ""
        self.csv_path = csv_path
        self.written = CsvStream(csv_path, _CSV_COLUMNS) if csv_path else None   # streamed, a row per sample
        pub_qos, in_qos = qos_for(self.v["mode"])   # msgs.qos: lockstep loses nothing, realtime keeps the newest
        self.pub = self.create_publisher(JointState, "joint_states", pub_qos)
        subs = {IMU_TOPIC: self.create_subscription(Imu, IMU_TOPIC, self._on_imu, in_qos, raw=True),
                ENCODER_TOPIC: self.create_subscription(JointState, ENCODER_TOPIC, self._on_encoder, in_qos, raw=True)}
        self.filtered = self.v["mode"] == "realtime" and self._filter(subs)
        self.watch = PublisherWatch(self, [IMU_TOPIC, ENCODER_TOPIC, "joint_states"])
        own = ", ".join(f"{k} = {v!r}" for k, v in self.est.values.items())
        sync = (f"the newest IMU sample at each encoder sample (within {self.v['imu_max_age_s'] * 1e3:g} ms)"
                if self.latest else "IMU and encoder samples paired by stamp")
        self.get_logger().info(f"{self.est.title} state estimator ready: imu_offset = {self.config.imu_offset:g} m, "
                               f"h = {self.h * 1e3:.3f} ms, {sync}{'; ' + own if own else ''}")

    def _filter(self, subs) -> bool:
        """Realtime: a DDS content filter on each raw subscription (layouts.RAW_FILTERS), so that a flood of
        samples with a wrong frame, joint or value is dropped by the middleware, in C++, and cannot displace a
        genuine sample in the reader's queue (issue 30).  What it drops is not counted; the parsers still judge
        (and count) what passes.  Lockstep keeps every message for the parsers to count."""
        return filter_readers(self.get_logger(), {t: (s, L.RAW_FILTERS[t]) for t, s in subs.items()},
                              "a message with a wrong frame_id or joint, or values outside RAW_LIMITS (NaN too), or "
                              "that cannot be deserialized,")

    # --- inputs ---------------------------------------------------------------------------------------
    def _on_imu(self, data: bytes) -> None:
        self._take(IMU_TOPIC, lambda d: L.parse_imu(d, yaw=True), data)

    def _on_encoder(self, data: bytes) -> None:
        self._take(ENCODER_TOPIC, L.parse_encoder, data)

    def _take(self, topic: str, parse, data) -> None:
        try:
            parsed = parse(data)
        except BadMessage as exc:
            self.rejects(topic, str(exc))
            return
        stamp = parsed[0]
        guard = self.stamp_guards[topic]
        last = guard.last
        if self.latest:
            self._take_latest(topic, parsed, guard)
            return
        verdict = guard.check(stamp, commit=False)   # committed when its pair is estimated
        if verdict == REPEAT:
            # a resent sample: its pair answered, answer it again (once per resend: on the IMU's copy)
            if topic == IMU_TOPIC and stamp == self.answered and self.last_msg is not None:
                self.pub.publish(self.last_msg)
            return
        if verdict == RESTART:
            self.get_logger().warning(f"{topic} restarted at t = {stamp * 1e-9:.3f} s (the last sample was "
                                      f"t = {last * 1e-9:.3f} s)")
            self._drop(topic, self.pending[topic], "its stream restarted")
        elif verdict != NEW:
            self.rejects(topic, verdict)
            return
        self.pending[topic][stamp] = (parsed, time.monotonic(), verdict == RESTART)
        self._pair(stamp)

    def _take_latest(self, topic: str, parsed, guard) -> None:
        """``imu_sync: latest`` (module doc): an IMU sample becomes the newest held; an encoder sample is estimated
        with it, if it is within ``imu_max_age_s`` of the encoder's stamp."""
        stamp = parsed[0]
        last = guard.last
        verdict = guard.check(stamp)   # each stream's time moves with its own samples
        if verdict not in (NEW, REPEAT, RESTART):
            self.rejects(topic, verdict)
            return
        if verdict == RESTART:
            self.get_logger().warning(f"{topic} restarted at t = {stamp * 1e-9:.3f} s (the last sample was "
                                      f"t = {last * 1e-9:.3f} s)")
        if topic == IMU_TOPIC:
            if verdict != REPEAT:
                self.newest_imu = (stamp, parsed, verdict == RESTART)
            return
        if verdict == REPEAT:   # a resent encoder sample: its estimate again, nothing integrated
            if stamp == self.answered and self.last_msg is not None:
                self.pub.publish(self.last_msg)
            return
        imu = self.newest_imu
        if imu is None or abs(stamp - imu[0]) > self.imu_max_age_ns:
            self.imu_stale += 1
            said = ("none has come" if imu is None else
                    f"the newest is {(stamp - imu[0]) * 1e-6:+.1f} ms from it")
            self.rejects(ENCODER_TOPIC, f"the sample of t = {stamp * 1e-9:.6f} s has no imu/data_raw sample within "
                                        f"imu_max_age_s = {self.imu_max_age_ns * 1e-6:g} ms ({said}); dropped, not "
                                        "integrated")
            return
        restart = verdict == RESTART or imu[2] or (self.answered is not None and stamp <= self.answered)
        self.newest_imu = (imu[0], imu[1], False)
        self._estimate(stamp, imu[1], parsed, restart, commit=False)

    def _drop(self, topic: str, stamps, why: str) -> None:
        """Drop the waiting samples of ``topic`` at ``stamps`` (counted: rejected on ``topic``)."""
        waiting = self.pending[topic]
        for s in list(stamps):
            if waiting.pop(s, None) is not None:
                self.unpaired += 1
                self.rejects(topic, f"the sample of t = {s * 1e-9:.6f} s had no {PARTNER[topic]} sample ({why}); "
                                    "dropped, not integrated")

    def _expire(self) -> None:
        """The bounded wait for a partner: at most PAIR_WAIT_S of wall time, at most _MAX_PENDING samples."""
        now = time.monotonic()
        for topic, waiting in self.pending.items():
            if waiting:
                old = [s for s, (_p, at, _r) in waiting.items() if now - at > PAIR_WAIT_S]
                if old:
                    self._drop(topic, old, f"none within {PAIR_WAIT_S:g} s")
                if len(waiting) > _MAX_PENDING:
                    self._drop(topic, sorted(waiting)[:len(waiting) - _MAX_PENDING],
                               f"more than {_MAX_PENDING} samples waiting")

    def _pair(self, stamp: int) -> None:
        imu = self.pending[IMU_TOPIC].get(stamp)
        enc = self.pending[ENCODER_TOPIC].get(stamp)
        if imu is None or enc is None:
            self._expire()
            return
        del self.pending[IMU_TOPIC][stamp], self.pending[ENCODER_TOPIC][stamp]
        for topic, waiting in self.pending.items():   # a later pair is complete: an older sample's partner is lost
            if waiting:
                self._drop(topic, [s for s in waiting if s < stamp], "a later pair came first")
        restart = imu[2] or enc[2] or (self.answered is not None and stamp <= self.answered)
        self._estimate(stamp, imu[0], enc[0], restart)

    # --- the core's step ------------------------------------------------------------------------------
    def _estimate(self, stamp: int, imu, enc, restart: bool, commit: bool = True) -> None:
        _s, gyro, accel_x, accel_z, gyro_z = imu
        _s, phi, phi_rate, torque = enc
        sample = RawSample(gyro, accel_x, accel_z, phi, phi_rate)
        snap = self.est.snapshot()
        gap = None if self.answered is None else stamp - self.answered
        if gap is not None and not restart and gap > MAX_GAP_S * 1e9:
            self.get_logger().warning(f"no sample pair for {gap * 1e-9:.3f} s (more than {MAX_GAP_S:g} s) before "
                                      f"t = {stamp * 1e-9:.3f} s")
            restart = True
        # the time since the last pair: h when none was lost (bit for bit the offline loop's), else the stamps'
        dt = None if restart or gap is None or gap == self.period_ns else gap * 1e-9
        if restart:
            self.get_logger().warning(f"the raw samples restarted at t = {stamp * 1e-9:.3f} s: re-initialising the "
                                      f"{self.est.title} estimator")
            self.est.reset()
        try:
            x = self.est.step(sample, dt)
            L.check_state(x, torque)   # what the observer and the controller would refuse, never published
            problem = None
        except BadMessage as exc:
            problem = str(exc)
        except (ArithmeticError, ValueError) as exc:
            problem = f"the step failed ({exc})"
        if problem is not None:
            self.est.restore(snap)
            self.rejects(IMU_TOPIC, f"the estimate for t = {stamp * 1e-9:.3f} s is not usable: {problem}; the "
                                    "sample is not integrated, nothing published")
            return
        if commit:   # (imu_sync latest: each stream's guard moved with its own samples)
            for guard in self.stamp_guards.values():
                guard.commit(stamp)
        self.answered = stamp
        self.count += 1
        if self.written is not None:
            self.written.row((stamp * 1e-9, *sample, *x))
        diverged = self.est.health.diverged
        if diverged:   # integrated (it may recover), never published as a state
            self.withheld += 1
            self.last_msg = None
        if diverged != self.was_diverged:
            self.was_diverged = diverged
            self.report_health_now()   # the plant faults on the ERROR (estimator_unhealthy) within a period
            health = self.est.health
            if diverged:
                self.get_logger().error(f"the {self.est.title} estimator diverged at t = {stamp * 1e-9:.3f} s "
                                        f"(innovation {health.innovation:.3g}, NIS mean {health.nis_mean:.3g}); its "
                                        "estimates are withheld from joint_states while it is")
            else:
                self.get_logger().warning(f"the {self.est.title} estimator recovered at t = {stamp * 1e-9:.3f} s")
        if diverged:
            return
        self.last_msg = L.encode_state(stamp, x, torque, gyro_z if self.spatial else None)
        self.pub.publish(self.last_msg)

    def spin_step(self, executor) -> None:
        super().spin_step(executor)
        self._expire()

    # --- health (nodes.runtime.diagnostics) -------------------------------------------------------------------
    def diagnostic_count(self) -> int:
        return self.count

    def diagnostic_status(self):
        hl = self.est.health
        values = {"method": self.est.name, "estimates": self.count, "unpaired_dropped": self.unpaired,
                  "imu_sync": self.v["imu_sync"], "imu_stale_dropped": self.imu_stale,
                  "content_filter": "on: messages outside the limits are dropped by DDS, not counted"
                  if self.filtered else "off",
                  "withheld_diverged": self.withheld,
                  "innovation": f"{hl.innovation:.6g}", "nis": f"{hl.nis:.4g}", "nis_mean": f"{hl.nis_mean:.4g}",
                  "diverged": str(hl.diverged).lower()}
        if hl.diverged:
            return ERROR, f"the {self.est.title} estimator diverged (NIS mean {hl.nis_mean:.3g})", values
        return OK, f"{self.est.title} estimating", values

    def on_shutdown(self) -> None:
        waiting = sum(len(w) for w in self.pending.values())
        self.get_logger().info(f"estimated {self.count} samples ({self.est.title}); unpaired dropped: "
                               f"{self.unpaired} (+{waiting} still waiting at the end); no IMU sample within "
                               f"imu_max_age_s: {self.imu_stale}; withheld diverged: "
                               f"{self.withheld}; rejected: "
                               f"{self.rejects.summary()}")
        if self.written is not None:
            self.written.close()
            self.get_logger().info(f"wrote {self.csv_path}")


def main(argv=None) -> int:
    return run_node(StateEstimatorNode, argv)


if __name__ == "__main__":
    sys.exit(main())
