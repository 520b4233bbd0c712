#!/usr/bin/env python3
"""Long soak: a million hostile messages into a running observer; prints its resident memory as it goes.

    source scripts/env.sh && python scripts/soak.py [--messages 1000000] [--bound-mib 60]

The test suite runs the same flood with 20,000 messages (test/nodes/test_hostile.py).
Exit 0 when the observer survived, answered a good state afterwards and its memory grew by
less than ``--bound-mib``; 1 otherwise.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from graphproc import Graph  # noqa: E402
from injector import Injector, flood, rss_mib  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--messages", type=int, default=1_000_000)
    ap.add_argument("--bound-mib", type=float, default=60.0)
    args = ap.parse_args(argv)
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    from mwip_ros.core.plants.model import State
    from mwip_ros.msgs import layouts as L

    with tempfile.TemporaryDirectory() as work, Graph(Path(work)) as g:
        obs = g.start("disturbance_observer")
        with Injector(g.domain_id, "soak") as inj:
            js = inj.publisher("joint_states", JointState)
            est = inj.record("disturbance_estimate", WrenchStamped)
            if not (inj.wait(lambda: js.get_subscription_count() >= 1, 30) and obs.wait_for_output("ready", 30)):
                print("soak: the observer did not come up", file=sys.stderr)
                return 1
            inj.spin(0.5)
            before = peak = rss_mib(obs.pid)
            print(f"observer RSS before: {before:.1f} MiB", flush=True)
            t0, done, step = time.monotonic(), 0, 100_000
            while done < args.messages:
                done += flood(inj, js, min(step, args.messages - done), big=0 if done else 60)
                peak = max(peak, rss_mib(obs.pid))
                print(f"  {done:>9,} hostile messages, {time.monotonic() - t0:6.1f} s: RSS {rss_mib(obs.pid):.1f} MiB "
                      f"(peak {peak:.1f})", flush=True)
            js.publish(L.encode_state(0, State(0.0, -0.1, 0.0, 0.0), 0.0))
            answered = inj.wait(lambda: bool(est), 60)
            after = rss_mib(obs.pid)
        obs.stop()
        last_line = (obs.output().splitlines() or [""])[-1]
    grew = after - before
    print(f"observer RSS: before {before:.1f} MiB, peak {peak:.1f} MiB, after {after:.1f} MiB (+{grew:.1f}); "
          f"answered a good state afterwards: {'yes' if answered else 'NO'}\n{last_line}")
    return 0 if answered and grew < args.bound_mib and obs.popen.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
