"""Issue 49's realtime fall: states several periods apart (a realtime driver that missed periods, a loaded machine).

A realtime graph gets its states n periods apart whenever the driver wakes late (the bench run of
docs/hardware.md, "The goals, measured": gaps of up to 14 periods in bursts).  Each stage must then step over the
time that passed, and stay what it is in lockstep: the observer (eq. 12's explicit Euler in steps of at most one
period: one step of n h multiplies its error by -(lambda n h - 1), lambda = 180 1/s for Upkie, so a burst of late
samples blew tau_hat up to 1e3 N m within 0.3 s and the robot fell) and DSC's filter (eq. 25 over the whole gap,
not one period).  The nodes here are built in this process (no DDS) and fed the states directly.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from graphproc import PARAMS
from nodeharness import NodeHarness, node_class
from mwip_ros.core.control.controller import filter_step
from mwip_ros.core.plants.model import State
from mwip_ros.msgs import layouts as L

pytestmark = pytest.mark.node

REPO_CONFIG = PARAMS.parent
UPKIE = [PARAMS, REPO_CONFIG / "upkie.yaml"]   # X M_hat^-1's eigenvalues 180 and 2.4 1/s: a stiff observer
H_NS = 5_000_000
GAP = 10   # periods between two states: 50 ms, as the bench's bursts (4 to 14 periods)


def _estimates(obs: NodeHarness) -> dict:
    return {s: (t1, t2) for s, t1, t2 in (L.parse_wrench(d) for d in obs.sent("disturbance_estimate"))}


def test_observer_over_gaps_of_ten_periods_equals_the_observer_every_period_with_the_state_held():
    """States 10 periods apart: the observer integrates each gap in ten steps of one period, the state and the torque
    of the gap's start held; so its estimates equal those of an observer fed every period with that state repeated
    (today's one step of 10 h multiplied the error by -8 a sample: 1e10 N m after a dozen)."""
    rng = np.random.default_rng(49)
    samples = [State(0.0, *rng.uniform(-0.05, 0.05, 3)) for _ in range(15)]
    u = [float(v) for v in rng.uniform(-0.5, 0.5, len(samples))]
    with NodeHarness(node_class("disturbance_observer"), "-p", "mode:=realtime", params=UPKIE) as gapped, \
            NodeHarness(node_class("disturbance_observer"), "-p", "mode:=realtime", params=UPKIE) as every:
        for j, (x, u_prev) in enumerate(zip(samples, u)):
            gapped.feed("joint_states", L.encode_state(j * GAP * H_NS, x, u_prev))
            for i in range(GAP if j + 1 < len(samples) else 1):   # the held state in between, the same torque
                every.feed("joint_states", L.encode_state((j * GAP + i) * H_NS, x, u[j + 1] if i else u_prev))
        got, want = _estimates(gapped), _estimates(every)
        assert gapped.node.rejects.counts == {} and every.node.rejects.counts == {}
    assert sorted(got) == [j * GAP * H_NS for j in range(len(samples))]
    for stamp, tau in got.items():
        assert all(math.isfinite(v) and abs(v) < 10.0 for v in tau), (stamp, tau)
        np.testing.assert_allclose(tau, want[stamp], rtol=1e-6, atol=1e-9)


def test_observer_converges_to_a_constant_disturbance_over_gaps():
    """A robot held still against a constant torque: whatever the gaps (1 to 14 periods, as measured), tau_hat goes to
    the disturbance that holds it, N(q, q') - u (eq. 8 with q'' = 0), and stays there."""
    x = State(0.0, 0.03, 0.0, 0.0)
    u = 0.2
    gaps = [1, 2, 4, 7, 10, 12, 9, 6, 11, 14, 1, 1, 3] * 6
    with NodeHarness(node_class("disturbance_observer"), "-p", "mode:=realtime", params=UPKIE) as obs:
        k = 0
        for n in [0] + gaps:
            k += n
            obs.feed("joint_states", L.encode_state(k * H_NS, x, u))
        est = [e for _s, e in sorted(_estimates(obs).items())]
        nominal = obs.node.obs.nominal
    # at rest M q'' = 0: tau_d = N - u with N = (0, -G_b sin theta_b) (eq. 1: the gravity term on the body row)
    want = (-u, -nominal.G_b * math.sin(x[1]))
    assert len(est) == len(gaps) + 1
    assert all(abs(t1) < 1.0 and abs(t2) < 10.0 for t1, t2 in est), est   # bounded all along
    np.testing.assert_allclose(est[-1], want, rtol=0.02, atol=1e-3)


def test_dsc_filter_advances_over_the_whole_gap():
    """DSC in the controller node: a state 10 periods after the last advances the filter x4d over the 10 periods
    (eq. 25 exact with x4_bar of the last state held), not over one."""
    states = [State(0.0, 0.04, 0.2, -0.1), State(0.0, 0.035, 0.1, -0.3), State(0.01, 0.02, -0.1, -0.2)]
    stamps = [0, H_NS, (1 + GAP) * H_NS]
    with NodeHarness(node_class("dscndo_controller"), "-p", "mode:=realtime", "-p", "law:=dsc",
                     "-p", "use_observer:=false", params=UPKIE) as ctl:
        for s, x in zip(stamps, states):
            ctl.feed("joint_states", L.encode_state(s, x, 0.0))
        internals = [L.parse_internals(d)[1] for d in ctl.sent("controller_internals")]
        tau4 = ctl.node.v["tau4"]
    assert len(internals) == 3
    h = H_NS * 1e-9
    second, third = internals[1], internals[2]
    after = filter_step(second["x4d"], second["x4_bar"], h, tau4)   # what step 2 advanced x4d to (one period) ...
    want = filter_step(after, second["x4_bar"], (GAP - 1) * h, tau4)   # ... and the rest of the gap, x4_bar held
    assert third["x4d"] == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert abs(third["x4d"] - after) > 1e-3 * max(1.0, abs(after))   # (one period's advance would be far off)
