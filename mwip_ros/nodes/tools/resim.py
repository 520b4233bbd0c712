"""``bag_replay`` mode ``resim``: drive a running observer and controller with a bag's states, compare.

It acts as the lockstep plant (:mod:`.lockstep`, the same driver ``plant_sim`` uses) with the
recorded states: for every recorded ``joint_states`` (in order; a resent duplicate stamp
once) it publishes ``/clock`` and the recorded bytes and waits for the one
``wheel_torque_cmd`` (or the yaw stage's ``wheel_torques_cmd``) that answers it, and collects
the new ``disturbance_estimate`` and ``controller_internals`` by stamp.  Then it compares them with
the recorded outputs (the k-th recorded command answers the k-th state; estimates and internals by
stamp) and prints
the largest absolute difference per topic and field, the compared and not reproduced
samples, and whether everything is within ``tolerance``.  Every message is decoded by the
message layer (:mod:`mwip_ros.msgs.layouts`).

A gain changed during the recorded run (``ros2 param set``) is in the bag's
``/parameter_events``, stamped with the last state its node had answered (the observer's
and the controller's clock follows their stream, :class:`~mwip_ros.nodes.runtime.state_input.StateInput`).
With ``parameter_events`` (default true) the same change is made on the running node, through
its ``set_parameters`` service, before the first state stamped after it: a run with a gain
change mid-way re-simulates exactly.  Changes of the nodes named ``disturbance_observer`` and
``dscndo_controller`` (in the recording's namespace) are applied.  A recorded value no node could
take (an unknown type code, no value, an array too long: :func:`.rclpy_compat.parameter_from_msg`)
is skipped with a warning naming it, and counted in the report; a value the running node refuses
is logged with its reason, counted, and the re-simulation goes on without it.

A controller that tracks ``cmd_vel`` (``motion.enabled`` without a ``motion.profile``, docs/theory.md 6.11) is
given the recorded ``cmd_vel`` where the recording has them: a Twist sets the target of the periods after the one
the controller last answered (``core.control.motion.Shaper.command``), so each recorded Twist (the newest of those
between two states, in the bag's order) is published before the first state recorded after it, and that state is sent
only once the controller has answered a ``get_parameters`` request sent after the Twist (its executor took the
Twist first).  The run starts once the controller's subscription has matched this publisher (its /diagnostics
``publishers_by_topic``): the subscription is best effort, so what comes before it matched is lost, even when
the publisher already counts it.  A profile is made inside each period from the state's stamp and re-simulates as it is.
"""
from __future__ import annotations

import time
from typing import Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from mwip_ros.bag import BagError
from mwip_ros.bag.segments import Segments, recorded_messages
from mwip_ros.msgs import BadMessage
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.qos import GRAPH_QOS, INPUT_QOS
from mwip_ros.msgs.topics import leaf
from mwip_ros.nodes.tools.comparison import Stat, compare_stamped, diff
from mwip_ros.nodes.runtime.diagnostics import topic_counts
from mwip_ros.nodes.runtime.guards import Rejects
from mwip_ros.nodes.runtime.lockstep import CHAIN, LockstepDriver
from mwip_ros.nodes.runtime.process import EXIT_ERROR, EXIT_OK
from mwip_ros.nodes.runtime.services import Answered
from mwip_ros.params import ParamError

__all__ = ["Resim", "EXIT_DIFFERENT"]

EXIT_DIFFERENT = 4          # outputs differ from the recording
COLLECT_IDLE_S = 1.0        # after the last command, wait this long without news for stragglers
COLLECT_MAX_S = 5.0
# the answer to a state: u, or the yaw stage's (u_L, u_R) when the controller tracks motion on a spatial plant's states
# (docs/theory.md 6.13); each compared in order (the k-th answer to the k-th state)
COMMANDS = {"wheel_torque_cmd": lambda data: (L.parse_command(data),),
            "wheel_torques_cmd": lambda data: L.parse_wheel_torques(data)[1:]}
OUTPUTS = (*COMMANDS, "disturbance_estimate", "controller_internals")
# the answering nodes (core.closed_loop.loop.STAGES): their recorded changes apply
LOOP_NODES = tuple(a.node for a in CHAIN)


def _estimate(data) -> Tuple[int, Dict[str, float]]:
    stamp, t1, t2 = L.parse_wrench(data)
    return stamp, {"tau_hat1": t1, "tau_hat2": t2}


class Resim:
    """The resim mode of the ``bag_replay`` node ``node`` (its parameters ``v``, ``bag``, ``types``)."""

    def __init__(self, node):
        self.node = node
        self.v = v = node.v
        self.log = node.get_logger()
        if v["loop"]:
            raise ParamError("loop", "loop is for mode replay; resim feeds every recorded state once")
        ignored = [k for k, d in (("rate", 1.0), ("publish_clock", False)) if v[k] != d]
        if v["topics"]:
            ignored.append("topics")
        if ignored:
            self.log.info(f"resim: ignoring {', '.join(ignored)} (lockstep, /clock from each state's stamp)")
        self.rejects = Rejects(self.log)
        self._read_bag()
        self.new_cmds: Dict[str, List[tuple]] = {name: [] for name in COMMANDS}
        self.new = {"disturbance_estimate": {}, "controller_internals": {}}
        self.extra_cmds = 0
        self.k = 0
        self.started = False
        self.t_wall0: Optional[float] = None
        self.collecting_since: Optional[float] = None
        self.last_news = 0.0
        self.finished = False
        self.failed = False
        self._param_clients: Dict[str, object] = {}
        self._param_wait: Optional[Tuple[float, list]] = None   # (since, futures) of changes being applied
        self._motion_asked = None   # the futures of the controller's motion.* (theory 6.11), then True once judged
        self.cmd_vel_pub = None     # set when the running controller tracks cmd_vel: the recorded ones are replayed
        self._cmd_vel_since = 0.0   # when cmd_vel_pub was made (the controller's match is awaited from then)
        self._ctl_cmd_vel_publishers = 0   # the controller's /diagnostics: publishers its cmd_vel subscription matched
        self._barrier = None        # (since, future): a replayed cmd_vel's get_parameters round trip under way
        self.replayed_cmd_vel = 0
        self.applied_changes = 0

        clock_pub = node.create_publisher(Clock, "/clock", GRAPH_QOS)
        state_pub = node.create_publisher(JointState, "joint_states", GRAPH_QOS)
        cmd_sub = node.create_subscription(Float64, "wheel_torque_cmd", lambda d: self._on_cmd("wheel_torque_cmd", d),
                                           INPUT_QOS, raw=True)
        node.create_subscription(JointState, "wheel_torques_cmd", lambda d: self._on_cmd("wheel_torques_cmd", d),
                                 INPUT_QOS, raw=True)
        est_sub = node.create_subscription(WrenchStamped, "disturbance_estimate", self._on_est, INPUT_QOS, raw=True)
        int_sub = node.create_subscription(JointState, "controller_internals", self._on_int, INPUT_QOS, raw=True)
        need = v["wait_for_subscribers"]
        needed = [int_sub] if self.has["controller_internals"] else []
        if self.has["disturbance_estimate"] and need == 0:
            needed.append(est_sub)
        self.lockstep = LockstepDriver(
            node, state_pub, clock_pub, cmd_sub, need_subs=need if need > 0 else
            (2 if self.has["disturbance_estimate"] else 1), timeout_s=v["timeout_s"], timeout_param="timeout_s",
            needed=needed, idle_hint="an answer from the running dscndo_controller: it and the "
                                     "disturbance_observer answer each stamp once, so restart both before every resim")
        t0, t1 = self.states[0][0] * 1e-9, self.states[-1][0] * 1e-9
        self.log.info(f"resim of {node.bag}: {len(self.states)} states (t = {t0:.3f} .. {t1:.3f} s), recorded "
                      f"{self._recorded_commands()} commands, {len(self.rec['disturbance_estimate'])} estimates, "
                      f"{len(self.rec['controller_internals'])} internals; tolerance {v['tolerance']:g}")

    # --- the recording
    def _bag_topic(self, name: str, required: bool) -> Optional[str]:
        types = self.node.types
        cands = [t for t in types if leaf(t) == name]
        if len(cands) > 1:
            exact = [t for t in cands if t == "/" + name]
            if len(exact) != 1:
                raise ParamError("bag", f"several {name} topics in the bag ({', '.join(sorted(cands))}); "
                                        f"resim needs one")
            cands = exact
        if not cands:
            if required:
                raise ParamError("bag", f"{self.node.bag} has no {name} topic (it has: {', '.join(sorted(types))}); "
                                        f"resim needs the recorded states")
            return None
        return cands[0]

    def _read_bag(self) -> None:
        bag = self.node.bag
        topics = {"joint_states": self._bag_topic("joint_states", True)}
        topics.update({name: self._bag_topic(name, False) for name in OUTPUTS + ("cmd_vel",)})
        by_topic = {t: name for name, t in topics.items() if t}
        self.cmd_vels: Dict[int, bytes] = {}   # the state index k -> the newest recorded cmd_vel before state k
        self.has = {name: topics[name] is not None for name in OUTPUTS}
        self.states: List[Tuple[int, bytes]] = []
        self.rec_cmds: Dict[str, List[tuple]] = {name: [] for name in COMMANDS}
        self.rec = {"disturbance_estimate": {}, "controller_internals": {}}
        seen = set()
        dropped = bad = 0
        # the runs of the bag (a reset, a new plant: the stamps go back), re-simulated one after the other;
        # every stamp is keyed (run, stamp), so two runs under the same stamps are never mixed
        self.state_keys: List[Tuple[int, int]] = []
        self._fed_run: Dict[int, int] = {}   # stamp -> the run of the state last fed with it
        try:
            self.segs = Segments.from_bag(bag, topics["joint_states"])
            for seg, _lt, topic, data in self.segs.tag(recorded_messages(bag)):
                name = by_topic.get(topic)
                if name is None:
                    continue
                try:
                    if name == "joint_states":
                        stamp = L.parse_joint_state(data)[0]
                        if seg is None:
                            dropped += 1   # a stray state, outside the recorded stream
                            continue
                        if (seg, stamp) in seen:
                            continue  # a state the plant resent: fed (and answered) once
                        seen.add((seg, stamp))
                        self.states.append((stamp, data))
                        self.state_keys.append((seg, stamp))
                    elif name in COMMANDS:
                        self.rec_cmds[name].append(COMMANDS[name](data))
                    elif name == "cmd_vel":
                        L.parse_twist(data)   # a Twist; its numbers the controller judges, as it did
                        self.cmd_vels[len(self.states)] = bytes(data)
                    else:
                        stamp, fields = _estimate(data) if name == "disturbance_estimate" else L.parse_internals(data)
                        self.rec[name].setdefault((seg or 0, stamp), fields)
                except BadMessage:
                    bad += 1
        except BagError as exc:
            raise ParamError("bag", f"cannot read the bag: {exc}") from None
        if self.segs.spliced:
            self.log.warning(f"resim: {self.segs.describe()}\nresim: each run is re-simulated from its start, one "
                             f"after the other (the observer and the controller restart where the stamps go back, "
                             f"as in the recording); outputs are compared run by run")
        if not self.states:
            raise ParamError("bag", f"{bag} has no joint_states messages to re-simulate")
        self.skipped_values: List[str] = []   # recorded parameter values that cannot be set (named, why)
        self.refused_values: List[str] = []   # recorded values the running node refused (its reasons)
        self.param_events = self._read_parameter_events() if self.v["parameter_events"] else []
        if dropped:
            self.log.warning(f"skipped {dropped} stray recorded state(s) (outside the recorded stream of stamps)")
        if bad:
            self.log.warning(f"skipped {bad} recorded message(s) that are not valid graph messages")
        if any(self.has[name] for name in COMMANDS) and self._recorded_commands() != len(self.states):
            self.log.warning(f"the bag has {self._recorded_commands()} commands for {len(self.states)} states; "
                             f"commands are compared in order (k-th command = answer to the k-th state)")
        self.stamp_set = seen

    def _read_parameter_events(self) -> List[Tuple[int, str, list]]:
        """[(stamp, node, [rcl_interfaces/Parameter])]: the recorded changes of the loop's nodes, in order."""
        from rcl_interfaces.msg import ParameterEvent
        from rclpy.serialization import deserialize_message

        from mwip_ros.nodes.runtime.rclpy_compat import parameter_from_msg

        if "/parameter_events" not in self.node.types:
            return []
        out, others = [], set()
        for seg, _lt, topic, data in self.segs.tag(recorded_messages(self.node.bag)):
            if topic != "/parameter_events":
                continue
            try:
                ev = deserialize_message(bytes(data), ParameterEvent)
            except Exception:  # noqa: BLE001 - a foreign or damaged message: not a change to apply
                continue
            changed = [prm for prm in ev.changed_parameters if prm.name != "use_sim_time"]
            if not changed:
                continue
            if leaf(ev.node) not in LOOP_NODES:
                others.add(ev.node)
                continue
            stamp = ev.stamp.sec * 1_000_000_000 + ev.stamp.nanosec
            readable = []
            for prm in changed:   # a value no node could take (type code 99, ...): skipped, never sent
                problem = parameter_from_msg(prm)[1]
                if problem is None:
                    readable.append(prm)
                    continue
                self.skipped_values.append(f"{ev.node} at t = {stamp * 1e-9:.3f} s: {problem}")
                self.log.warning(f"resim: skipped a recorded parameter value of {ev.node} at t = {stamp * 1e-9:.3f} "
                                 f"s that cannot be set: {problem}")
            if readable:
                out.append(((seg or 0, stamp), ev.node, readable))
        if others:
            self.log.info(f"resim: recorded parameter changes of {', '.join(sorted(others))} are not applied "
                          f"(only {', '.join(LOOP_NODES)})")
        out.sort(key=lambda e: e[0])
        for (seg, stamp), node, changed in out:
            run = f" of run {seg + 1}" if self.segs.spliced else ""
            self.log.info(f"resim: will set {', '.join(prm.name for prm in changed)} on {node} before the first "
                          f"state{run} after t = {stamp * 1e-9:.3f} s, as recorded")
        return out

    def _param_clients_ready(self) -> list:
        """Before the run: a set_parameters client for each node whose recorded changes resim applies, each shown to
        answer by an empty request (no parameter: nothing changes; :class:`Answered`), so that every recorded change
        is then sent once, when it is due (:meth:`_apply_due`)."""
        from rcl_interfaces.srv import SetParameters
        out = []
        for node in dict.fromkeys(node for _, node, _ in self.param_events):
            client = self._param_clients[node] = self.node.create_client(SetParameters, f"{node}/set_parameters")
            if client.wait_for_service(timeout_sec=self.v["timeout_s"]):   # else _apply_due names it, when due
                out.append(Answered(client, SetParameters.Request))
        return out

    def _apply_due(self, stamp) -> bool:
        """Start applying the recorded changes due before the state of ``stamp`` ((run, stamp)); True if some
        are under way."""
        from rcl_interfaces.srv import SetParameters

        futures = []
        while self.param_events and self.param_events[0][0] < stamp:
            _, node, changed = self.param_events.pop(0)
            client = self._param_clients.get(node)
            if client is None:
                client = self._param_clients[node] = self.node.create_client(SetParameters,
                                                                             f"{node}/set_parameters")
            if not client.wait_for_service(timeout_sec=self.v["timeout_s"]):
                self._fail(f"cannot apply the recorded parameter change of {node}: no {node}/set_parameters "
                           f"service after {self.v['timeout_s']:g} s")
                return True
            futures.append((node, changed, client.call_async(SetParameters.Request(parameters=changed))))
        if futures:
            self._param_wait = (time.monotonic(), futures)
        return bool(futures)

    def _params_applied(self) -> None:
        """Between callbacks: once every change under way is answered, send the state that waited for them."""
        since, futures = self._param_wait
        if not all(f.done() for _, _, f in futures):
            if time.monotonic() - since > self.v["timeout_s"]:
                self._fail(f"no answer to set_parameters within timeout_s = {self.v['timeout_s']:g} s")
            return
        self._param_wait = None
        t = self.states[self.k][0] * 1e-9
        for node, changed, f in futures:
            results = list(f.result().results)
            refused = [r.reason or f"parameter '{prm.name}' refused" for prm, r in zip(changed, results)
                       if not r.successful]
            done = [prm.name for prm, r in zip(changed, results) if r.successful]
            if refused:   # the node goes on with its old value; the comparison shows what that changes
                self.refused_values += [f"{node}: {reason}" for reason in refused]
                self.log.warning(f"{node} refused the recorded parameter change before the state at t = {t:.3f} s: "
                                 f"{'; '.join(refused)}; going on without it (outputs may differ from the recording)")
            else:
                self.applied_changes += 1
            if done:
                self.log.info(f"set {', '.join(done)} on {node} before the state at t = {t:.3f} s")
        self._send_now()

    def _recorded_commands(self) -> int:
        return sum(len(v) for v in self.rec_cmds.values())

    # --- inputs
    def _on_cmd(self, name: str, data) -> None:
        try:
            u = COMMANDS[name](data)
        except BadMessage as exc:
            self.rejects(name, str(exc))
            return
        if not self.lockstep.take_answer():
            self.extra_cmds += 1
            if self.extra_cmds <= 3:
                self.log.warning(f"a {name} while no state was waiting for one (ignored)")
            return
        self.new_cmds[name].append(u)
        self.k += 1
        self.last_news = time.monotonic()
        if self.k < len(self.states):
            self._send()
        else:
            self.collecting_since = time.monotonic()
            self.log.info(f"all {len(self.states)} states answered in {time.monotonic() - self.t_wall0:.2f} s; "
                          f"collecting the last estimates and internals")

    def _collect(self, name: str, parse, data) -> None:
        try:
            stamp, fields = parse(data)
        except BadMessage as exc:
            self.rejects(name, str(exc))
            return
        self.new[name].setdefault((self._fed_run.get(stamp, 0), stamp), fields)
        self.last_news = time.monotonic()

    def _on_est(self, data) -> None:
        self._collect("disturbance_estimate", _estimate, data)

    def _on_int(self, data) -> None:
        self._collect("controller_internals", L.parse_internals, data)

    # --- lockstep
    def _send(self) -> None:
        if not self._apply_due(self.state_keys[self.k]):
            self._send_now()

    def _send_now(self) -> None:
        if self._replay_cmd_vel():
            return   # the state goes once the controller has taken the Twist (step)
        stamp, data = self.states[self.k]
        self._fed_run[stamp] = self.state_keys[self.k][0]
        self.lockstep.send(self.k, stamp, data)

    def _fail(self, text: str) -> None:
        self.failed = True
        self.node.finish(EXIT_ERROR, text)

    def _replay_cmd_vel(self) -> bool:
        """Publish the recorded cmd_vel due before state k, if any, and ask the controller for a parameter: its answer
        comes after the Twist was taken (True: the state waits for it, :meth:`step`)."""
        from rcl_interfaces.srv import GetParameters
        data = self.cmd_vels.pop(self.k, None) if self.cmd_vel_pub is not None else None
        if data is None:
            return False
        self.cmd_vel_pub.publish(data)
        self.replayed_cmd_vel += 1
        self._barrier = (time.monotonic(), self._params_client.call_async(GetParameters.Request(
            names=["motion.enabled"])))
        return True

    def _motion_check(self) -> Optional[bool]:
        """Ask the running controller for motion.enabled and motion.profile once the graph is there: with cmd_vel
        (enabled, no profile) the recorded cmd_vel are replayed (a publisher that must first match the controller's
        subscription); meanwhile the set_parameters clients of the recorded changes show that they are answered
        (:meth:`_param_clients_ready`).  None while the answers (or the match) are awaited, else False (go)."""
        from rcl_interfaces.srv import GetParameters
        from geometry_msgs.msg import Twist
        if self._motion_asked is True:
            if self.cmd_vel_pub is not None and (self.cmd_vel_pub.get_subscription_count() < 1
                                                 or self._ctl_cmd_vel_publishers < 1):
                if time.monotonic() - self._cmd_vel_since > self.v["timeout_s"]:   # matched both ways, or fail
                    self._fail(f"resim timeout: the dscndo_controller's cmd_vel subscription did not match this "
                               f"node's publisher within timeout_s = {self.v['timeout_s']:g} s (its /diagnostics "
                               f"publishers_by_topic: {self.cmd_vel_pub.topic_name}: {self._ctl_cmd_vel_publishers})")
                return None   # the controller's cmd_vel subscription not matched yet (either way)
            return False
        if self._motion_asked is None:
            client = self._params_client = self.node.create_client(GetParameters, "dscndo_controller/get_parameters")
            if not client.wait_for_service(timeout_sec=self.v["timeout_s"]):
                self._motion_asked = True   # no such service to ask: the lockstep's own checks name what is missing
                return False
            # one name a request: rclpy answers nothing for a request whose parameter is an empty array; each asked
            # again until answered (a new client's first answer can be lost: runtime.services)
            self._motion_asked = [Answered(client, lambda n=n: GetParameters.Request(names=[n]))
                                  for n in ("motion.enabled", "motion.profile")]
            self._motion_asked += self._param_clients_ready()
            return None
        waiting = [a for a in self._motion_asked if a.poll() is None]   # each polled: each sent again when due
        if waiting:
            late = waiting[0]
            if late.waited() > self.v["timeout_s"]:
                self._fail(f"resim timeout: {late.client.srv_name} did not answer within timeout_s = "
                           f"{self.v['timeout_s']:g} s ({late.sent} requests sent)")
            return None
        enabled, profile = (list(a.answer.values) for a in self._motion_asked[:2])
        self._motion_asked = True
        if enabled and enabled[0].bool_value and not (profile and len(profile[0].double_array_value)):
            self.cmd_vel_pub = self.node.create_publisher(Twist, "cmd_vel", 10)   # reliable, volatile: as a user
            self._cmd_vel_since = time.monotonic()
            self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
            self.log.info(f"resim: the running dscndo_controller tracks cmd_vel: replaying the {len(self.cmd_vels)} "
                          f"recorded cmd_vel (each before the first state recorded after it)")
            return None
        if self.cmd_vels:
            self.log.info("resim: the bag has cmd_vel, which the running dscndo_controller does not read (motion "
                          "off, or a motion.profile): not replayed")
        return False

    def _on_diagnostics(self, msg) -> None:
        """The publishers the controller's cmd_vel subscription has matched, from its ``publishers_by_topic`` (a
        report each wall second)."""
        name = f"{self.node.get_namespace().rstrip('/')}/dscndo_controller"
        for st in msg.status:
            if st.name == name:
                for kv in st.values:
                    if kv.key == "publishers_by_topic":
                        self._ctl_cmd_vel_publishers = topic_counts(kv.value).get(self.cmd_vel_pub.topic_name, 0)

    def step(self, executor) -> None:
        if not self.started:
            ready = self.lockstep.wait_for_graph()
            if ready:
                if self._motion_check() is not False:   # asking (spin for the answer)
                    executor.spin_once(timeout_sec=0.02)
                    return
                self.started = True
                self.t_wall0 = time.monotonic()
                self.log.info("graph matched; starting the lockstep re-simulation")
                self._send()
            elif ready is False:
                self._fail("resim timeout: " + self.lockstep.graph_timeout_text())
                return
            executor.spin_once(timeout_sec=0.02)
            return
        executor.spin_once(timeout_sec=0.05 if self._param_wait is None and self._barrier is None else 0.005)
        if self._param_wait is not None and not self.failed:
            self._params_applied()
            return
        if self._barrier is not None and not self.failed:
            since, future = self._barrier
            if future.done():
                self._barrier = None
                self._send_now()
            elif time.monotonic() - since > self.v["timeout_s"]:
                self._fail(f"no answer to get_parameters after a replayed cmd_vel within timeout_s = "
                           f"{self.v['timeout_s']:g} s")
            return
        now = time.monotonic()
        if self.collecting_since is not None:
            if self._all_collected() or now - self.last_news > COLLECT_IDLE_S \
                    or now - self.collecting_since > COLLECT_MAX_S:
                self.finished = True
                self.node.finish(EXIT_OK)
            return
        failure = self.lockstep.check()
        if failure:
            self._fail(failure)

    def _all_collected(self) -> bool:
        return all(s in self.new[name] for name in self.rec for s in self.rec[name] if s in self.stamp_set)

    # --- comparison
    def compare(self):
        """{topic: Stat}, {topic: {field: Stat}}."""
        fed = set(self.state_keys[:self.k])
        topics: Dict[str, Stat] = {}
        fields: Dict[str, Dict[str, Stat]] = {}
        for name in COMMANDS:
            rec, new = self.rec_cmds[name], self.new_cmds[name]
            if not (self.has[name] and (rec or new)):
                continue
            st = topics[name] = Stat()
            n = min(len(rec), len(new))
            for a, b in zip(rec[:n], new[:n]):
                for x, y in zip(a, b):
                    st.add(diff(x, y))
            st.compared = n
            st.missing = max(0, min(len(rec), self.k) - n)
            st.extra = len(new) - n + (self.extra_cmds if name == "wheel_torque_cmd" else 0)
        for name, names in (("disturbance_estimate", ("tau_hat1", "tau_hat2")),
                            ("controller_internals", L.INTERNAL_NAMES)):
            if self.has[name]:
                st, fs = compare_stamped(self.rec[name], self.new[name], fed, names)
                topics[name] = st
                fields[name] = {n: f for n, f in fs.items() if f.compared}
        return topics, fields

    def report(self) -> None:
        tol = self.v["tolerance"]
        topics, fields = self.compare()
        wall = (time.monotonic() - self.t_wall0) if self.t_wall0 else 0.0
        lines = [f"bag_replay resim of {self.node.bag}",
                 f"  states fed: {self.k} of {len(self.states)} in {wall:.2f} s wall; tolerance {tol:g}",
                 *([f"  runs in the bag: {len(self.segs)} (a reset or a new plant), re-simulated one after the "
                    f"other: {', '.join(str(s.states) for s in self.segs)} states"] if self.segs.spliced else []),
                 f"  {'topic / field':<28}{'compared':>9}{'missing':>9}{'max |diff|':>14}  within",
                 "  " + "-" * 68]
        for topic, st in topics.items():
            lines.append(f"  {topic:<28}{st.compared:>9}{st.missing:>9}{st.max_diff:>14.3e}  "
                         f"{'yes' if st.ok(tol) else 'NO'}")
            for f, fst in fields.get(topic, {}).items():
                lines.append(f"    {f:<26}{fst.compared:>9}{'':>9}{fst.max_diff:>14.3e}  "
                             f"{'yes' if fst.max_diff <= tol else 'NO'}")
        extras = {t: st.extra for t, st in topics.items() if st.extra}
        if extras:
            lines.append("  not in the recording (not compared): " + ", ".join(f"{t} {n}" for t, n in extras.items()))
        absent = [t for t, h in self.has.items() if not h]
        if absent:
            lines.append("  not recorded (not compared): " + ", ".join(absent))
        bad = [t for t, st in topics.items() if not st.ok(tol)]
        if not self.finished:
            why = "failed" if self.failed else "interrupted"
            lines.append(f"  RESULT: INCOMPLETE - the re-simulation {why} after {self.k} of {len(self.states)} "
                         f"states; the table compares those (exit {EXIT_ERROR})")
            self.node.finish(EXIT_ERROR)
        elif bad:
            self.node.finish(EXIT_DIFFERENT)
            lines.append(f"  RESULT: DIFFERENT - {', '.join(bad)} not within tolerance {tol:g} "
                         f"(exit {EXIT_DIFFERENT})")
        else:
            self.node.finish(EXIT_OK)
            lines.append(f"  RESULT: REPRODUCED - every compared output within tolerance {tol:g} (exit {EXIT_OK})")
        if self.cmd_vel_pub is not None:
            lines.append(f"  recorded cmd_vel replayed: {self.replayed_cmd_vel}"
                         + (f" ({len(self.cmd_vels)} after the last state fed, not replayed)" if self.cmd_vels else ""))
        if self.applied_changes or self.param_events or self.refused_values:
            lines.append(f"  recorded parameter changes applied: {self.applied_changes}"
                         + (f" ({len(self.param_events)} after the last state, not applied)"
                            if self.param_events else ""))
        if self.refused_values:
            lines.append(f"  recorded parameter values refused by the running node: {len(self.refused_values)} ("
                         + "; ".join(self.refused_values[:3]) + (" ..." if len(self.refused_values) > 3 else "") + ")")
        if self.skipped_values:
            lines.append(f"  recorded parameter values skipped (they cannot be set): {len(self.skipped_values)} ("
                         + "; ".join(self.skipped_values[:3]) + (" ..." if len(self.skipped_values) > 3 else "") + ")")
        if self.rejects.counts:
            lines.append(f"  rejected messages: {self.rejects.summary()}")
        print("\n".join(lines), flush=True)
