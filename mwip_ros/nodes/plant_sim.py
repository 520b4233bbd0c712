"""``plant_sim``: the true MWIP (SPEC sections 1, 4 and 7) as a node.

lockstep: publish /clock and state k, wait for the command that answers it,
publish the true lumped disturbance at t_k, integrate to t_{k+1}, repeat.  The
graph then reproduces ``mwip_sim`` sample by sample.
realtime: a wall-clock timer at ``control_rate_hz``; the last command is held; a
command older than ``stale_command_periods`` periods is replaced by zero torque.

Exit code 0 when the run completed (or, with ``duration_s: 0``, was stopped), 3 when
the robot fell, 1 on a lockstep timeout, 2 on bad parameters, 128 + the signal (130,
143) when SIGINT/SIGTERM stopped it before ``duration_s``.
"""
from __future__ import annotations

import json
import math
import sys
import time
from array import array
from typing import Optional

import numpy as np
from geometry_msgs.msg import Wrench, WrenchStamped
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros import metrics
from mwip_ros.nodes import _msgs as M
from mwip_ros.nodes._params import declare
from mwip_ros.nodes._runtime import EXIT_ERROR, EXIT_FALLEN, GracefulNodeMixin, run_node
from mwip_ros.plant import PlantSim, config_from_values, saturate
from mwip_ros.sim import TRAJECTORY_COLUMNS, SimResult

NAME = "plant_sim"
NCOL = len(TRAJECTORY_COLUMNS)
SETTLE_S = 0.3  # lockstep: after our own subscriptions matched, let the other nodes (e.g. a recorder) match too
RESEND_S = 0.5  # lockstep: resend a state nobody answered (only lost before the graph was matched)


class PlantSimNode(Node, GracefulNodeMixin):
    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        self.cfg = config_from_values(self.v)
        self.plant = PlantSim(self.cfg)
        self.mode = self.v["mode"]
        self.h = self.cfg.h
        self.period_ns = round(self.h * 1e9)
        self.n_steps = int(round(self.v["duration_s"] / self.h)) if self.v["duration_s"] > 0 else None
        self.extra = (0.0, 0.0)
        # Row k = TRAJECTORY_COLUMNS of state k, flat in one array of doubles: no Python object per
        # row for the garbage collector to scan (a full collection over lists of rows took ~6 ms, a
        # missed realtime deadline), and 80 bytes per period.
        self.rows = array("d")
        self.estimates = {}  # tau_hat that came before its row was written, by stamp
        self.rejects = M.Rejects(self.get_logger())
        self.fallen = False
        self.t_wall0 = None
        # lockstep bookkeeping
        self.started = False
        self.awaiting: Optional[int] = None   # stamp of the state waiting for its command
        self.sent_at = self.resent_at = 0.0
        self.wait_since = time.monotonic()
        self.last_wait_log = 0.0
        self.ready_at = None
        self.last_progress = time.monotonic()
        # realtime bookkeeping
        self.cmd: Optional[float] = None
        self.cmd_at = 0.0
        self.tick_times = array("d")
        self.stale = 0
        self.missed = 0

        self.state_pub = self.create_publisher(JointState, "joint_states", M.GRAPH_QOS)
        self.truth_pub = self.create_publisher(WrenchStamped, "lumped_disturbance", M.GRAPH_QOS)
        self.clock_pub = self.create_publisher(Clock, "/clock", M.GRAPH_QOS) if self.mode == "lockstep" else None
        self.cmd_sub = self.create_subscription(Float64, "wheel_torque_cmd", self._on_cmd, M.GRAPH_QOS, raw=True)
        self.create_subscription(Wrench, "external_wrench", self._on_wrench, M.GRAPH_QOS)
        self.create_subscription(WrenchStamped, "disturbance_estimate", self._on_estimate, M.GRAPH_QOS, raw=True)
        dur = f"{self.v['duration_s']:g} s" if self.n_steps is not None else "until stopped"
        self.get_logger().info(f"{self.mode} plant: h = {self.h * 1e3:.3f} ms, {self.cfg.substeps} RK4 sub-steps, "
                               f"{dur}, seed {self.cfg.seed}")

    # --- inputs ---------------------------------------------------------------------------
    def _on_wrench(self, msg: Wrench) -> None:
        e = (float(msg.torque.x), float(msg.torque.y))
        if not all(math.isfinite(x) for x in e):
            self.rejects("external_wrench", f"non-finite torque {e}")
            return
        self.extra = e
        self.get_logger().info(f"external wrench: tau_ext1 += {e[0]:g}, tau_ext2 += {e[1]:g} N m"
                               if any(e) else "external wrench cleared")

    def _on_estimate(self, data: bytes) -> None:
        try:
            stamp, t1, t2 = M.parse_wrench(data)
        except M.BadMessage:
            return  # only monitored for the CSV/metrics; the controller logs rejects
        k, off = divmod(stamp, self.period_ns)  # row k holds state k, stamped k * period_ns
        if off == 0 and 0 <= k < len(self.rows) // NCOL:  # row written before the estimate came (plain DSC)
            self.rows[k * NCOL + 6] = t1
            self.rows[k * NCOL + 7] = t2
        else:
            self.estimates[stamp] = (t1, t2)

    def _on_cmd(self, data: bytes) -> None:
        try:
            u = M.parse_command(data)
        except M.BadMessage as exc:
            self.rejects("wheel_torque_cmd", str(exc))
            return
        if self.mode == "realtime":
            self.cmd, self.cmd_at = u, time.monotonic()
            return
        if self.awaiting is None:
            self.rejects("wheel_torque_cmd", "command while no state is waiting for one")
            return
        self._advance(saturate(u, self.cfg.torque_limit))

    # --- the step shared by both modes -------------------------------------------------------
    def _stamp(self) -> int:
        return self.plant.k * self.period_ns

    def _publish_state(self) -> None:
        stamp = self._stamp()
        if self.clock_pub is not None:
            self.clock_pub.publish(M.encode_clock(stamp))
        x = self.plant.x
        self.state_pub.publish(M.encode_state(stamp, x[:2], x[2:], self.plant.u_prev))

    def _finish_period(self, u: float) -> bool:
        """Record row k with u_k, publish tau_d at t_k; integrate unless the run ends. True = ended."""
        p = self.plant
        stamp = self._stamp()
        tau_d = p.lumped_disturbance(u, self.extra)
        self.truth_pub.publish(M.encode_wrench(stamp, tau_d[0], tau_d[1]))
        th = self.estimates.pop(stamp, (math.nan, math.nan))
        self.rows.extend((p.t, *p.x, u, th[0], th[1], tau_d[0], tau_d[1]))
        if p.fallen:
            self.fallen = True
            self.get_logger().error(f"FALLEN at t = {p.t:.3f} s: |theta_b| = {abs(p.x[1]):.4f} > fall_angle "
                                    f"{self.cfg.fall_angle}")
            return self._end()
        if self.n_steps is not None and p.k >= self.n_steps:
            return self._end()
        p.step(u, self.extra)
        if not np.all(np.isfinite(p.x)):
            self.get_logger().error(f"state became non-finite at t = {p.t:.3f} s; stopping")
            self.exit_code = EXIT_ERROR
            return self._end()
        return False

    def _end(self) -> bool:
        self.done = True
        if self.fallen:
            self.exit_code = EXIT_FALLEN
        return True

    # --- lockstep ------------------------------------------------------------------------------
    def _advance(self, u: float) -> None:
        self.awaiting = None
        if self._finish_period(u):
            return
        self._send()

    def _send(self) -> None:
        self._publish_state()
        self.awaiting = self._stamp()
        self.sent_at = self.resent_at = time.monotonic()

    def _missing(self) -> str:
        what = M.lockstep_missing(self, self.state_pub, self.v["expected_subscribers"])
        return "; ".join(what) or "a wheel_torque_cmd (the controller is running but did not answer)"

    def _wait_for_graph(self) -> None:
        """Both modes start once the controller and ``expected_subscribers`` subscribers are matched (and
        SETTLE_S later).  After ``lockstep_timeout_s`` lockstep gives up; realtime starts without them."""
        now = time.monotonic()
        timeout = self.v["lockstep_timeout_s"]
        ready = (self.cmd_sub.get_publisher_count() >= 1
                 and self.state_pub.get_subscription_count() >= self.v["expected_subscribers"])
        if ready and self.ready_at is None:
            self.ready_at = now
        if not ready:
            self.ready_at = None
        if ready and now - self.ready_at >= SETTLE_S:
            self._start(now, "graph matched")
        elif now - self.wait_since > timeout:
            if self.mode == "lockstep":
                self._timeout(f"graph not ready after {timeout:g} s; waiting for: {self._missing()}")
            else:
                self.get_logger().warning(f"graph not ready after {timeout:g} s (missing: {self._missing()}); "
                                          f"starting the realtime run anyway")
                self._start(now, "realtime without the whole graph")
        elif now - self.last_wait_log > 2.0:
            self.last_wait_log = now
            self.get_logger().info(f"waiting for: {self._missing()}")

    def _start(self, now: float, why: str) -> None:
        self.started = True
        self.t_wall0 = now
        self.get_logger().info(f"{why}; starting {self.mode} run")
        if self.mode == "realtime":
            self.create_timer(self.h, self._tick)
        else:
            self._send()

    def spin_step(self, executor) -> None:
        if not self.started:
            self._wait_for_graph()
            executor.spin_once(timeout_sec=0.02)
            return
        if self.mode == "realtime":
            executor.spin_once(timeout_sec=0.05)
            self._progress()
            return
        executor.spin_once(timeout_sec=0.05)
        self._progress()
        timeout = self.v["lockstep_timeout_s"]
        if self.awaiting is not None and not self.done:
            waited = time.monotonic() - self.sent_at
            if waited > timeout:
                self._timeout(f"no wheel_torque_cmd answered state k = {self.plant.k} (t = {self.plant.t:.3f} s) "
                              f"within lockstep_timeout_s = {timeout:g} s; missing: {self._missing()}")
            elif time.monotonic() - self.resent_at > RESEND_S:
                # A state sent before every subscription matched is lost; resending is harmless
                # (the observer answers a repeated stamp again, the controller answers each stamp once).
                self.resent_at = time.monotonic()
                self._publish_state()

    def _progress(self) -> None:
        now = time.monotonic()
        if now - self.last_progress < 2.0 or self.t_wall0 is None:
            return
        self.last_progress = now
        total = f" / {self.n_steps * self.h:g}" if self.n_steps is not None else ""
        self.get_logger().info(f"t = {self.plant.t:.2f}{total} s simulated, "
                               f"{self.plant.k / max(now - self.t_wall0, 1e-9):.0f} steps/s, "
                               f"theta_b = {self.plant.x[1]:+.4f} rad")

    def _timeout(self, text: str) -> None:
        self.get_logger().error("lockstep timeout: " + text)
        self.exit_code = EXIT_ERROR
        self.done = True

    # --- realtime ------------------------------------------------------------------------------
    def _tick(self) -> None:
        now = time.monotonic()
        if self.tick_times:
            if now - self.tick_times[-1] > 1.5 * self.h:
                self.missed += 1
        else:
            self.t_wall0 = now
        self.tick_times.append(now)
        if self.done:
            return
        if len(self.tick_times) > 1:  # finish the period of the state published at the last tick
            u = self.cmd
            if u is None or now - self.cmd_at > self.v["stale_command_periods"] * self.h:
                self.stale += 1
                if self.stale <= 3 or self.stale % 200 == 0:
                    self.get_logger().warning(f"no fresh wheel_torque_cmd (#{self.stale}); applying zero torque")
                u = 0.0
            if self._finish_period(saturate(u, self.cfg.torque_limit)):
                return
        self._publish_state()

    # --- end of run --------------------------------------------------------------------------------
    def on_shutdown(self) -> None:
        log = self.get_logger()
        if self.stop_signal is not None and self.n_steps is not None and not self.done:
            self.exit_code = 128 + self.stop_signal  # interrupted: the run did not reach duration_s
            log.warning(f"interrupted at t = {self.plant.t:.3f} s of {self.n_steps * self.h:g} s")
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        n = len(self.rows) // NCOL
        for pub in (self.state_pub, self.truth_pub, self.clock_pub):
            if pub is not None:  # let a recorder receive the last states before this process exits
                pub.wait_for_all_acked(Duration(seconds=2.0))
        summary = {"mode": self.mode, "control_rate_hz": 1.0 / self.h, "periods": n, "wall_s": wall,
                   "steps_per_s": n / wall if wall > 0 else None, "fallen": self.fallen,
                   "exit_code": self.exit_code, "rejected": dict(self.rejects.counts)}
        if n:
            log.info(f"{self.mode} run: {n} periods, {self.rows[-NCOL]:.3f} s simulated in {wall:.2f} s wall "
                     f"({n / max(wall, 1e-9):.0f} steps/s); {'FALLEN' if self.fallen else 'upright'}")
        if self.mode == "realtime" and len(self.tick_times) > 2:
            per = np.diff(self.tick_times) * 1e3
            rt = {"period_ms_p50": float(np.percentile(per, 50)), "period_ms_p99": float(np.percentile(per, 99)),
                  "period_ms_max": float(per.max()), "ticks": len(self.tick_times),
                  "period_max_at_s": float(np.argmax(per) + 1) * self.h,  # sim time of the tick that ended it
                  "missed_deadlines": self.missed, "stale_command_substitutions": self.stale,
                  "missed_at_s": [round(float(i + 1) * self.h, 6)  # sim time of the ticks that came late (first 50)
                                  for i in np.flatnonzero(per > 1.5 * self.h * 1e3)[:50]]}
            summary["realtime"] = rt
            log.info(f"realtime: loop period p50 = {rt['period_ms_p50']:.3f} ms, p99 = {rt['period_ms_p99']:.3f} ms, "
                     f"max = {rt['period_ms_max']:.3f} ms (nominal {self.h * 1e3:g} ms); missed deadlines = "
                     f"{self.missed}; stale-command substitutions = {self.stale}")
        log.info(f"rejected messages: {self.rejects.summary()}")
        if n:
            table = np.array(self.rows).reshape(n, NCOL)
            cols = {c: table[:, i] for i, c in enumerate(TRAJECTORY_COLUMNS)}
            t_end = cols["t"][-1]
            win = metrics.WINDOW if t_end >= metrics.WINDOW[1] - 1e-9 else (t_end / 2, t_end)
            m = metrics.compute(cols, win, self.cfg.fall_angle)
            summary["metrics"] = {"window_s": list(win), **m.as_dict()}
            log.info(f"metrics t in [{win[0]:g}, {win[1]:g}] s: theta_b p2p = {m.theta_b_p2p:.5f} rad, RMS = "
                     f"{m.theta_b_rms:.5f} rad, max|theta_b| = {m.theta_b_max_abs:.5f} rad, u RMS = {m.u_rms:.3f} "
                     f"N m, tau_hat err RMS = ({m.tau_err1_rms:.3f}, {m.tau_err2_rms:.3f}) N m")
        if self.v["csv"] and n:
            SimResult(NAME, cols, self.fallen, self.h).write_csv(self.v["csv"])
            log.info(f"wrote {self.v['csv']}")
        if self.v["summary_json"]:
            with open(self.v["summary_json"], "w") as f:
                json.dump(_jsonable(summary), f, indent=1, allow_nan=False)
            log.info(f"wrote {self.v['summary_json']}")


def _jsonable(x):
    """Plain JSON values: numpy numbers -> float, NaN/inf -> None (JSON has neither)."""
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (bool, int, str)) or x is None:
        return x
    x = float(x)
    return x if math.isfinite(x) else None


def main(argv=None) -> int:
    return run_node(PlantSimNode, argv)


if __name__ == "__main__":
    sys.exit(main())
