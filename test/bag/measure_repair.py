"""Measure what ``repair`` saves from damaged copies of a recorded bag, against another repair.

    python test/bag/measure_repair.py [--old-root DIR] [--messages N] [--chunk-size BYTES]

Records a bag with BagWriter (N messages on each of three topics, small chunks), makes the
damaged copies of ``bagcheck.damage_cases`` (uncompressed and zstd), repairs each copy with

* ``expected``: the messages of the intact chunks the copy still holds (from the intact
  file's chunk and message indexes);
* ``library alone``: the mcap library's StreamReader with CRC checks, stopping at its first
  error (what reading without any repair logic gets);
* ``old``: the ``repair`` of the package found under ``--old-root`` (run in a subprocess
  with that directory first on PYTHONPATH), if given;
* ``new``: this checkout's ``repair``;

and prints a Markdown table of messages saved, plus the messages a reader can read back
from each repaired file (``readable``: the mcap reader with CRC checks, up to its first error).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/, for bagcheck

from mcap.reader import make_reader  # noqa: E402
from mcap.stream_reader import StreamReader  # noqa: E402
from mcap.records import Message  # noqa: E402

from bagcheck import damage_cases, write_bag  # noqa: E402

TOPICS = {"/joint_states": "sensor_msgs/msg/JointState", "/wheel_torque_cmd": "std_msgs/msg/Float64",
          "/disturbance_estimate": "geometry_msgs/msg/WrenchStamped"}

_DRIVER = """
import json, sys
from mwip_ros.bag.repair import repair
out = {}
for path in sys.argv[1:]:
    try:
        out[path] = repair(path).topic_counts
    except Exception as exc:
        out[path] = repr(exc)
import mwip_ros
print(json.dumps({"package": mwip_ros.__file__, "saved": out}))
"""


def library_alone(path: Path) -> int:
    n = 0
    try:
        for record in StreamReader(str(path), validate_crcs=True).records:
            n += isinstance(record, Message)
    except Exception:
        pass
    return n


def readable(mcap: Path) -> int:
    n = 0
    try:
        with open(mcap, "rb") as fh:
            for _ in make_reader(fh, validate_crcs=True).iter_messages(log_time_order=False):
                n += 1
    except Exception:
        pass
    return n


def repair_old(old_root: Path, paths):
    env = dict(os.environ, PYTHONPATH=f"{old_root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    # cwd too: ``python -c`` puts the working directory before PYTHONPATH on sys.path.
    r = subprocess.run([sys.executable, "-c", _DRIVER, *map(str, paths)], env=env, cwd=old_root,
                       capture_output=True, text=True, check=True)
    doc = json.loads(r.stdout)
    assert Path(doc["package"]).resolve().is_relative_to(old_root.resolve()), doc["package"]
    return doc["saved"]


def _total(counts):
    return sum(counts.values()) if isinstance(counts, dict) else counts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old-root", type=Path, default=None, help="a checkout whose mwip_ros to compare with")
    ap.add_argument("--messages", type=int, default=1500, help="messages per topic (default 1500)")
    ap.add_argument("--chunk-size", type=int, default=4096, help="chunk size in bytes (default 4096)")
    args = ap.parse_args()
    from mwip_ros.bag import repair

    work = Path(tempfile.mkdtemp(prefix="measure_repair_"))
    try:
        rows = []
        for compression in (None, "zstd"):
            src = work / f"src_{compression or 'none'}"
            write_bag(src, TOPICS, args.messages, compression=compression, chunk_size=args.chunk_size)
            cases = []
            for i, (case, data, expected) in enumerate(damage_cases(src / f"{src.name}_0.mcap")):
                copies = []
                for who in ("old", "new"):
                    bag = work / f"{src.name}_{i}_{who}"
                    bag.mkdir()
                    (bag / f"{bag.name}_0.mcap").write_bytes(data)
                    copies.append(bag)
                cases.append((case, expected, *copies))
            old = repair_old(args.old_root, [c[2] for c in cases]) if args.old_root else {}
            for case, expected, old_bag, new_bag in cases:
                mcap = new_bag / f"{new_bag.name}_0.mcap"
                alone = library_alone(mcap)
                try:
                    new = repair(new_bag).topic_counts
                except Exception as exc:
                    new = repr(exc)
                old_n = old.get(str(old_bag), "-")
                rows.append((f"{case} ({compression or 'uncompressed'})", expected, alone, old_n, new,
                             readable(old_bag / f"{old_bag.name}_0.mcap") if old else "-", readable(mcap)))
        total = 3 * args.messages
        print(f"{total} messages on {len(TOPICS)} topics, chunk_size {args.chunk_size}\n")
        print("| case | expected | library alone | old | new | new == expected | new >= old per topic "
              "| old readable | new readable |")
        print("|---|---:|---:|---:|---:|:-:|:-:|---:|---:|")
        bad = 0
        for case, expected, alone, old_n, new, old_read, new_read in rows:
            exact = new == expected
            at_least = "-" if not isinstance(old_n, dict) else \
                isinstance(new, dict) and all(new.get(t, 0) >= n for t, n in old_n.items())
            bad += (not exact) + (at_least is False)
            print(f"| {case} | {_total(expected)} | {alone} | {_total(old_n)} | {_total(new)} | "
                  f"{'yes' if exact else 'NO'} | {dict(((True, 'yes'), (False, 'NO'))).get(at_least, at_least)} "
                  f"| {old_read} | {new_read} |")
        return 1 if bad else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
