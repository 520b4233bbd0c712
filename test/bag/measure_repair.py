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

    python test/bag/measure_repair.py --cut-loss [--old-root DIR]

measures instead the seconds of a run lost (:mod:`bag.cutloss`): a 10 s run at 200 Hz of
the loop topics written with the recorder's writer (1 MiB chunks; uncompressed and zstd), cut
at many points and killed at several times, repaired by

* ``before``: the repair under ``--old-root`` on bags of 1 MiB chunks without a time bound
  (this checkout's BagWriter with ``max_chunk_duration=None``: the old writer's layout);
* ``decode only``: this checkout's repair on those same bags;
* ``after``: this checkout's repair on bags of this checkout's default BagWriter (chunks also
  closed every ``DEFAULT_MAX_CHUNK_DURATION`` of log time);

then prints the cost of the time bound: file size and CPU time to write the run.
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


KILLS = (0.3, 1.0, 2.0, 3.0, 4.2, 6.9, 9.7)  # [s]: kill -9 after the messages up to these log times


def _old_last(old_counts, bag: Path):
    from bag.cutloss import saved_last
    return saved_last(bag) if isinstance(old_counts, dict) and sum(old_counts.values()) else None


def cut_loss(old_root) -> int:
    """The loss table of ``--cut-loss`` (see the module docstring); 1 if ``after`` ever loses 1 s or more."""
    import time as _time

    from bag.cutloss import copy_bag, cut_points, loss, lost_seconds, record_run, time_at_cut
    work = Path(tempfile.mkdtemp(prefix="measure_cut_loss_"))
    bad = 0
    try:
        for compression in (None, "zstd"):
            name = compression or "uncompressed"
            runs = {who: record_run(work / f"{name}_{who}", compression=compression, kills=KILLS,
                                    **({"max_chunk_duration": None} if who == "old" else {}))
                    for who in ("old", "new")}
            cases = {who: [(label, run.mcap.read_bytes()[:cut], time_at_cut(run, cut))
                           for label, cut in cut_points(run)]
                     + [(f"kill -9 at {k:g} s", data, max(t for _topic, t in run.written if t - run.t0 <= k * 1e9))
                        for k, data in run.kills.items()] for who, run in runs.items()}
            old = {}
            if old_root:
                bags = [copy_bag(data, work / f"{name}_oldcopy{i}") for i, (_l, data, _t) in enumerate(cases["old"])]
                counts = repair_old(old_root, bags)
                old = {i: lost_seconds(runs["old"], t, _old_last(counts[str(b)], b))
                       for i, (b, (_l, _d, t)) in enumerate(zip(bags, cases["old"]))}
            print(f"\n{name}: {len(runs['new'].written)} messages, {len(runs['new'].chunks)} chunks "
                  f"(1 MiB only: {len(runs['old'].chunks)})\n")
            print("| cut | before [s] | decode only [s] | after [s] |")
            print("|---|---:|---:|---:|")
            for i, ((label, data, t), (_l2, data2, t2)) in enumerate(zip(cases["old"], cases["new"])):
                decode = loss(runs["old"], data, t, work / "decode")
                after = loss(runs["new"], data2, t2, work / "after")
                bad += after >= 1.0
                before = f"{old[i]:.3f}" if i in old else "-"
                print(f"| {label} | {before} | {decode:.3f} | {after:.3f} |")
        print("\ncost of the time bound (10 s run, 7 topics at 200 Hz; best of 5):\n")
        print("| compression | max_chunk_duration | chunks | file bytes | write CPU [ms] |")
        print("|---|---|---:|---:|---:|")
        for compression in (None, "zstd"):
            for dur in (None, 0.5):
                best = None
                for k in range(5):
                    start = _time.process_time()
                    run = record_run(work / f"cost_{compression}_{dur}_{k}", compression=compression,
                                     max_chunk_duration=dur)
                    best = min(best or 1e9, _time.process_time() - start)
                print(f"| {compression or 'none'} | {dur} | {len(run.chunks)} | {run.mcap.stat().st_size} | "
                      f"{1000 * best:.0f} |")
        return 1 if bad else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--old-root", type=Path, default=None, help="a checkout whose mwip_ros to compare with")
    ap.add_argument("--messages", type=int, default=1500, help="messages per topic (default 1500)")
    ap.add_argument("--chunk-size", type=int, default=4096, help="chunk size in bytes (default 4096)")
    ap.add_argument("--cut-loss", action="store_true", help="measure the seconds of a run lost at many cut points")
    args = ap.parse_args()
    if args.cut_loss:
        return cut_loss(args.old_root)
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
