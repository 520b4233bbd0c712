"""plant_sim's ~/reset service: the robot and its time go back to the start, and the observer and the controller
follow the stamps back (re-initialised, logged) so the loop goes on (the stamp guard's rules, and the loop in this
process; the service through the middleware: test_plant_resets.py's realtime calls, test/cli/test_ctl.py)."""
import json

import pytest

from mwip_ros.msgs import layouts as L
from mwip_ros.nodes.runtime.guards import NEW, REPEAT, RESTART, RESYNC, StampGuard
from nodeharness import Loop

INITIAL_THETA_B = -0.1745   # config/paper.yaml


@pytest.mark.unit
def test_a_stream_that_goes_back_is_followed_after_resync_agreeing_stamps_resends_included():
    g = StampGuard(window_ns=100)
    assert [g.check(s) for s in (0, 10, 20, 20)] == [NEW, NEW, NEW, REPEAT]
    back = [g.check(0) for _ in range(RESYNC)]          # a lockstep reset: state 0, resent until answered
    assert all(v not in (NEW, REPEAT, RESTART) for v in back[:-1]) and back[-1] == RESTART, back
    assert g.check(10) == NEW
    stray = StampGuard(window_ns=100)
    assert [stray.check(s) for s in (0, 10)] == [NEW, NEW]
    assert stray.check(-500) not in (NEW, RESTART) and stray.check(5000) not in (NEW, RESTART)
    assert stray.check(20) == NEW          # two stamps that do not agree restart nothing


@pytest.mark.unit
def test_a_restart_is_asked_of_may_restart_and_a_crowded_start_needs_a_moving_stream():
    """Issue 30 item 5: stamps that agree restart the stream only when ``may_restart`` says they can be the stream's
    own publisher's (told whether the run is a reset back to the stream's start); a lone stamp judged without
    commit does not move the stream's time; before any stream, a crowded topic starts only on stamps that move."""
    asked, answer = [], [False]

    def may_restart(own):
        asked.append(own)
        return answer[0]

    w = 10 ** 9   # the window: 1 s (a stream that stands still that long in wall time has paused)
    g = StampGuard(window_ns=w, may_restart=may_restart)
    answer[0] = True
    assert [g.check(s * w // 10) for s in (0, 1, 2)] == [NEW, NEW, NEW] and asked == [True]   # the start: asked
    answer[0], asked[:] = False, []
    ahead = [g.check(1000 * w + s) for s in (0, 10, 20)]          # a second publisher's stamps, far ahead
    assert all(v not in (NEW, REPEAT, RESTART) for v in ahead) and "no restart" in ahead[-1] and asked == [False]
    assert g.check(3 * w // 10) == NEW and g.last == 3 * w // 10   # the stream goes on
    asked[:] = []
    answer[0] = True
    assert [g.check(s) for s in (0, 0, 0)][-1] == RESTART and asked == [True]   # back to the start: a reset
    assert g.check(4, commit=False) == NEW and g.last == 0       # judged, not committed: a lone sample ahead
    assert g.check(1) == NEW and g.last == 1
    crowded = StampGuard(window_ns=100, may_restart=lambda own: False)
    assert all(crowded.check(5) not in (NEW, RESTART) for _ in range(5))   # a stray repeated starts nothing
    assert [crowded.check(s) for s in (7, 8, 9)][-1] == NEW and crowded.last == 9   # three that move do


@pytest.mark.unit
def test_a_realtime_stream_reset_again_and_again_is_followed_each_time_and_only_back_to_its_start():
    """A realtime plant's resets restart its stamps at the run's start and move on at once (no resend of state 0,
    which may even be lost): the stream must come back to its start each time, not only the first (it once took
    the run's third stamp for the start, so a second reset was refused as an intruder's stamps)."""
    asked = []

    def may_restart(own):
        asked.append(own)
        return own

    h = 5_000_000   # 5 ms [ns]: the window (20 periods, 0.1 s) is wall time too (a pause), longer than this test
    g = StampGuard(window_ns=20 * h, may_restart=may_restart)
    assert [g.check(k * h) for k in range(40)] == [NEW] * 40
    for reset in range(4):
        first = h if reset == 2 else 0   # the third reset's first state lost
        verdicts = [g.check(k * h) for k in range(first // h, 30)]
        assert RESTART in verdicts and verdicts[-1] == NEW and g.last == 29 * h, (reset, verdicts)
        assert asked[-1] is True and g.start == first, (reset, asked, g.start)
    asked.clear()
    late = [g.check(k * h) for k in range(60, 63)]   # a run that neither goes back to the start nor follows a pause
    assert RESTART not in late and asked == [False] and "no restart" in late[-1]


@pytest.mark.node
def test_reset_in_lockstep_goes_back_to_the_initial_state_and_the_loop_goes_on(tmp_path):
    """The loop in this process (plant, observer and controller wired, test/nodeharness.py): a reset before the
    run is a no-op; one during it sends the plant back to its initial state at t = 0, and the observer and the
    controller follow the stamps back (once the plant's resends agree) so the loop goes on."""
    summary = tmp_path / "summary.json"
    with Loop("-p", "duration_s:=0.0", "-p", f"summary_json:={summary}") as loop:
        plant = loop.plant
        first = plant.call("~/reset")
        assert first.success and first.message.startswith("already at the initial state"), first.message
        loop.start()
        assert loop.run(lambda: len(plant.sent("joint_states")) > 400)
        n_before = len(plant.sent("joint_states"))
        answer = plant.call("~/reset")
        assert answer.success and answer.message.startswith("reset #1"), answer.message

        def went_back_and_on():
            later = [L.parse_joint_state(d)[0] for d in plant.sent("joint_states")[n_before:]]
            return 0 in later and max(later[later.index(0):]) >= 500_000_000   # 0.5 s after the reset
        assert loop.run(went_back_and_on), plant.logs()[-2000:]
        after = [L.parse_joint_state(d) for d in plant.sent("joint_states")[n_before:]]
        first = next(x for stamp, x, _ in after if stamp == 0)
        assert first.theta_b == INITIAL_THETA_B and first.theta_w == 0.0 and first.dtheta_b == 0.0
        for name in ("disturbance_observer", "dscndo_controller"):
            assert "restarted at t = 0.000 s" in loop[name].logs(), loop[name].logs()[-2000:]
    summary = json.loads(summary.read_text())
    assert (summary["resets"], summary["reset_calls"]) == (1, 2), summary   # one reset done of two calls
