"""true_wheel_states (a spatial plant's wheels, docs/graph.md): what the plant encodes the readers parse back; anything
else is a BadMessage naming what is wrong."""
import math

import pytest

from mwip_ros.msgs import cdr
from mwip_ros.msgs import layouts as L
from mwip_ros.msgs.errors import BadMessage

pytestmark = pytest.mark.unit


def test_a_wheel_state_round_trips_with_and_without_rates():
    data = L.encode_wheel_states(5_000_000, (1.25, -0.5), (3.0, -2.0))
    stamp, frame, names, pos, vel, eff = cdr.decode_joint_state(data)
    assert (stamp, frame, list(names)) == (5_000_000, "", ["wheel_left_joint", "wheel_right_joint"])
    assert (list(pos), list(vel), list(eff)) == ([1.25, -0.5], [3.0, -2.0], [])
    assert L.parse_wheel_states(data) == (5_000_000, (1.25, -0.5), (3.0, -2.0))
    assert L.parse_wheel_states(L.encode_wheel_states(7, (0.0, 0.1))) == (7, (0.0, 0.1), None)


@pytest.mark.parametrize("data, words", [
    (L.encode_wheel_torques(1, 1.0, 2.0), "positions"),                      # the torque pair: no positions
    (L.encode_state(1, (0.0, 0.0, 0.0, 0.0), 0.0), "joint names"),           # joint_states
    (L.encode_wheel_states(1, (0.0, math.nan)), "non-finite"),
    (L.encode_wheel_states(1, (2e9, 0.0)), "implausible wheel angle"),
    (L.encode_wheel_states(1, (0.0, 0.0), (0.0, 1e4)), "implausible wheel rate"),
    (L.encode_wheel_states(1, (0.0, 0.0), (1.0,)), "velocities"),
])
def test_what_is_not_a_wheel_state_is_refused(data, words):
    with pytest.raises(BadMessage, match=words):
        L.parse_wheel_states(data)
