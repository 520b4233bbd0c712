"""The plan of ``scripts/run_experiment.sh``: which laws it runs, for how long, with which sensors.

The script's choices that need the law registry (:mod:`mwip_ros.core.laws`, its plug-ins from
``$MWIP_ROS_LAWS`` included) or the merged parameter files are made here, in one place, before any node
starts::

    python -m mwip_ros.cli.experiment --params FILE... [--laws a,b] [--duration S] [--sensors state|raw]

prints one line per item for the script to read (``duration S`` when a duration is given, ``model raw|state``,
then ``run NAME FAMILY USE_OBSERVER`` per run, in order), or one line naming the mistake on stderr and exit 2.

* ``--laws``: any registered law's name (``names()``).  Without it, the files' law
  (``dscndo_controller.law``, a family) runs without and with the observer term (``dsc`` gives the paper's
  ``dsc, dscndo``); a file naming ``smc`` runs ``smc, smc_ndo``.  With it, a law the files name other than
  the paper's ``dsc`` is noted as replaced (never silently).
* ``--duration``: what ``mwip_sim --duration`` takes (:func:`mwip_ros.cli.sim.duration_error`): finite,
  > 0 and within ``plant_sim.duration_s``'s range; a file's ``duration_s: 0`` (run until stopped) is refused,
  since the script's runs must end for the next law and the report.
* ``--sensors raw``: the overlay comes before the user's files (the script puts it first), so a key the user
  sets (``state_estimator.method: complementary``) wins; the files must leave ``sensors.model`` raw.
* ``--robot``: a robot's side (docs/hardware.md) instead of ``plant_sim``: the ``wheel_driver`` with a backend
  (:data:`ROBOTS`), its raw IMU and encoders through the ``state_estimator`` (``model raw``).  ``emulated-moteus`` is
  the moteus emulator's robot on the wall clock: ``--mode realtime`` only, and a torque limit (the files'
  ``torque_limit`` or ``wheel_driver.wheel_torque_limit``), which the controllers get as ``maximum_torque``.  The
  plan then says ``robot NAME BACKEND``.

``python -m mwip_ros.cli.experiment --timing SUMMARY.json [LABEL]...`` prints each run's period timing (the
driver's ``summary_json``) as the Markdown section the script adds to the report.
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional, Tuple

from mwip_ros import params as P
from mwip_ros.core import laws

PROG = "run_experiment"
PAPER_LAW = "dsc"   # the paper's family (config/paper.yaml, the schema's default): naming it replaces nothing
# --robot NAME: the wheel_driver's backend for it (docs/hardware.md)
ROBOTS = {"mock": "mock", "upkie-pybullet": "upkie", "emulated-moteus": "moteus"}


class PlanError(ValueError):
    """A mistake on the command line or in the files: the one line the user reads."""


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=f"python -m {__name__}", description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", nargs="+", required=True, metavar="FILE")
    ap.add_argument("--laws", default=None)
    ap.add_argument("--duration", default=None)
    ap.add_argument("--sensors", default="state", choices=("state", "raw"))
    ap.add_argument("--robot", default=None, choices=tuple(ROBOTS))
    ap.add_argument("--mode", default="lockstep", choices=("lockstep", "realtime"))
    return ap


def parse_duration(text: str) -> float:
    """``--duration``'s value as ``mwip_sim`` reads it (a float: 10, 2.5, 1e3); PlanError naming the option."""
    from mwip_ros.cli.sim import duration_error
    try:
        d = float(text)
    except ValueError:
        raise PlanError(f"--duration must be a number of seconds (e.g. 10, 2.5, 1e3), got '{text}'") from None
    err = duration_error(d)
    if err:
        raise PlanError(err)
    return d


def law_runs(spec: Optional[str], file_family: str) -> Tuple[List[type], Optional[str]]:
    """The laws to run, in order, and a note for the user (or None).

    ``spec`` is ``--laws`` (comma-separated registered names; None: not given); ``file_family`` is the
    merged files' ``dscndo_controller.law``."""
    known = laws.names()
    if spec is None:
        runs = [law for law in (laws.lookup(file_family, False), laws.lookup(file_family, True)) if law is not None]
        if not runs:
            raise PlanError(f"dscndo_controller.law: unknown law '{file_family}'; known: {', '.join(laws.families())}")
        note = None if file_family == PAPER_LAW else (
            f"laws {', '.join(r.name for r in runs)}: the parameter files' law '{file_family}' without and with "
            f"the observer term (--laws picks others)")
        return runs, note
    names = [n.strip() for n in spec.split(",")]
    if not names or any(not n for n in names):
        raise PlanError(f"--laws takes registered law names separated by commas ({', '.join(known)}); "
                        f"got '{spec}'")
    for n in names:
        if n not in known:
            raise PlanError(f"--laws takes {', '.join(known)}; got '{n}'")
    runs = [laws.get(n) for n in dict.fromkeys(names)]
    note = None
    if file_family != PAPER_LAW and file_family not in {r.family for r in runs}:
        note = (f"note: --laws {','.join(r.name for r in runs)} runs in place of the parameter files' "
                f"law '{file_family}'")
    return runs, note


def plan(argv=None) -> List[str]:
    """The lines the script reads; PlanError on a mistake."""
    args = _parser().parse_args(argv)
    duration = parse_duration(args.duration) if args.duration is not None else None
    try:
        values = P.merged_values(P.load_param_files(args.params, option="--params"))
    except P.ParamError as exc:
        raise PlanError(str(exc)) from None
    if duration is None and values["duration_s"] == 0:
        raise PlanError("plant_sim.duration_s is 0 (run until stopped) in the parameter files: every run of "
                        "run_experiment.sh must end (the next law, the report); give --duration S")
    model = values.get("sensors.model", "state")
    if args.sensors == "raw" and model != "raw":
        raise PlanError(f"--sensors raw, but the parameter files set plant_sim sensors.model: {model}")
    robot = robot_line(args.robot, args.mode, args.params, values) if args.robot else None
    if robot:
        model = "raw"   # the driver publishes what the robot's IMU and encoders read: the estimator is in the loop
    runs, note = law_runs(args.laws, values["law"])
    if note:
        print(f"{PROG}: {note}", file=sys.stderr)
    lines = [f"duration {duration!r}"] if duration is not None else []
    lines.append(f"model {model}")
    if robot:
        lines.append(robot)
    lines += [f"run {law.name} {law.family} {str(law.observer).lower()}" for law in runs]
    return lines


def robot_line(robot: str, mode: str, files, values) -> str:
    """The plan's ``robot NAME BACKEND`` line for ``--robot``; PlanError for what that robot cannot run (module doc)."""
    if robot == "emulated-moteus":
        if mode != "realtime":
            raise PlanError("--robot emulated-moteus runs on the wall clock (moteus controllers, emulated in real "
                            "time): give --mode realtime")
        own = P.load_param_files(files, option="--params").for_node("wheel_driver")
        if not (own["wheel_torque_limit"] > 0 or values["torque_limit"] > 0):
            raise PlanError("--robot emulated-moteus needs a torque limit (moteus maximum_torque): plant_sim "
                            "torque_limit or wheel_driver wheel_torque_limit in the parameter files (config/upkie.yaml "
                            "sets torque_limit 1.8)")
    return f"robot {robot} {ROBOTS[robot]}"


def timing_markdown(paths, labels) -> List[str]:
    """The report's section on each run's period timing, from the drivers' ``summary_json`` files (one line per
    item: :func:`mwip_ros.robot.driver.timing_lines`); a file that is missing or unreadable is said so."""
    import json

    from mwip_ros.robot.driver import timing_lines
    out = ["", "## The robot side's period", ""]
    for path, label in zip(paths, list(labels) + [None] * len(paths)):
        out.append(f"**{label or path}**")
        out.append("")
        try:
            with open(path) as f:
                s = json.load(f)
            rep = dict(s["timing"])
            if s.get("schedule"):
                rep["periods_due"] = s["schedule"]["periods_due"]
            lines = [f"{s['mode']}, backend {s['backend']}, driver {s['driver_state']}"
                     + (f" ({s['fault_reason']}: {s['fault_detail']})" if s.get("fault_reason") else "")]
            lines += timing_lines(rep, 1.0 / s["control_rate_hz"])
            if s.get("device_replies_missed"):
                lines.append(f"device replies missed (left, right): {s['device_replies_missed']}")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            lines = [f"no timing: {path}: {exc}"]
        out += [f"- {line}" for line in lines] + [""]
    return out


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["--timing"]:
        files = [a for a in args[1:] if a.endswith(".json")]
        labels = [a for a in args[1:] if not a.endswith(".json")]
        print("\n".join(timing_markdown(files, labels)))
        return 0
    try:
        lines = plan(argv)
    except PlanError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    print("\n".join(lines))
    return 0



if __name__ == "__main__":
    sys.exit(main())
