"""``bag_replay``: play a recorded MCAP bag back into the graph, or re-simulate it.

usage:
    bag_replay --ros-args -p bag:=BAG_DIR [-p rate:=2.0] [-p loop:=true] [-p publish_clock:=true]
               [-p "topics:=[joint_states, wheel_torque_cmd]"] [-p wait_for_subscribers:=1]
    bag_replay --ros-args -p bag:=BAG_DIR -p mode:=resim [-p tolerance:=1e-9] [-p timeout_s:=10.0]
               (with a freshly started disturbance_observer and dscndo_controller,
                both with use_sim_time:=true, on the same or a changed parameter file)

mode ``replay`` (default): republish the bag's topics (all, or ``topics``) with their recorded
timing (log times, scaled by 1/``rate``), as the exact recorded CDR bytes, reliable QoS.
``publish_clock``: publish ``/clock`` with the bag's time (the log time of each next message)
and do not republish a recorded ``/clock``.  ``loop``: start again at the end.  Progress is
logged every few seconds, a count per topic at the end.  ``wait_for_subscribers``: wait (up to
``timeout_s``) until every replayed topic has that many matched subscriptions (0 = start at once).

mode ``resim``: act as the lockstep plant with the bag's states: for every recorded
``joint_states`` (in order; a resent duplicate stamp once) publish ``/clock`` (its stamp) and
the recorded state, wait for the one ``wheel_torque_cmd`` that answers it, collect the new
``disturbance_estimate`` and ``controller_internals`` by stamp.  Then compare with the recorded
outputs (the k-th recorded command answers the k-th state; estimates and internals by stamp),
print a table of the largest absolute difference per topic and per field, the number of
compared samples and of recorded samples that were not reproduced, and whether everything is
within ``tolerance``.  Before the first state it waits (up to ``timeout_s``) until the
controller's publishers are matched and ``joint_states`` has ``wait_for_subscribers``
subscriptions (0 = automatic: the controller, plus the observer - and its publisher matched -
when the bag has estimates; set 1 to re-simulate plain DSC without an observer).  Recorded
outputs that are not reproduced count as differences; new ones the bag lacks (plain DSC may
not have recorded the last estimates) are listed but not compared.  The controller and the
observer answer each stamp once: restart them before every resim.  A controller that tracks
``cmd_vel`` gets the recorded Twists, each before the first state recorded after it (:mod:`.resim`).

exit codes:
    0  replay: finished;  resim: every output reproduced within tolerance
    1  runtime error: resim lockstep timeout (names the missing node), replay subscribers
       never matched, unreadable message data, or interrupted before the end of a resim
    2  bad parameters (a missing, unreadable or damaged bag names 'bag', the file and the chunk's byte offset)
    4  resim: outputs differ (a difference above tolerance, or a recorded output not reproduced)
"""
from __future__ import annotations

import sys
from pathlib import Path

from rclpy.node import Node

from mwip_ros.bag import BagError, check, topic_counts, topic_qos, topic_types
from mwip_ros.nodes.runtime.params import declare
from mwip_ros.nodes.tools.replay import Replay
from mwip_ros.nodes.tools.resim import Resim
from mwip_ros.nodes.runtime.process import GracefulNodeMixin, run_node
from mwip_ros.params import ParamError

NAME = "bag_replay"


class BagReplay(Node, GracefulNodeMixin):
    """Parameters and the bag; the work is done by :class:`~.replay.Replay` or :class:`~.resim.Resim`."""

    def __init__(self, context=None, argv=()):
        super().__init__(NAME, context=context)
        self.v = declare(self, NAME, argv)
        bag = str(self.v["bag"]).strip()
        if not bag:
            raise ParamError("bag", "required: the bag directory to replay (e.g. -p bag:=bags/run1)")
        self.bag = str(Path(bag).expanduser())
        try:
            self.types = topic_types(self.bag)
            self.counts = topic_counts(self.bag)
            self.qos = topic_qos(self.bag)
            check(self.bag)  # a damaged chunk is never replayed as data
        except BagError as exc:
            raise ParamError("bag", f"cannot read the bag: {exc}") from None
        except (OSError, ValueError) as exc:
            raise ParamError("bag", f"cannot read the bag {self.bag}: {exc}") from None
        self.mode = Replay(self) if self.v["mode"] == "replay" else Resim(self)

    def spin_step(self, executor) -> None:
        self.mode.step(executor)

    def on_shutdown(self) -> None:
        self.mode.report()


def main(argv=None) -> int:
    return run_node(BagReplay, argv)   # --help included (run_node)


if __name__ == "__main__":
    sys.exit(main())
