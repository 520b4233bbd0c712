"""The exit codes of the command-line tools, one list for all of them (the nodes' are
:mod:`mwip_ros.nodes.runtime.process`'s, the same numbers; ``scripts/run_experiment.sh`` follows them too).

====  =========================================================================================
0     done (a simulation: every run stayed upright)
1     an unexpected error (a traceback; a sweep's worker that failed)
2     a mistake in the input, said in one line: a bad option, parameter, spec or law plug-in;
      nothing ran (or, ``mwip_sweep``, a law that raised, named with its scenario)
3     a simulated robot fell, or its run failed (the law's command not a number or implausible,
      the state diverged): the verdict line says when and why
130   interrupted (Ctrl-C, SIGINT); 143 terminated (SIGTERM): finished work is kept
====  =========================================================================================
"""
from __future__ import annotations

import signal
import sys
import textwrap
from typing import Dict, Optional

__all__ = ["EXIT_OK", "EXIT_ERROR", "EXIT_USAGE", "EXIT_FELL", "EXIT_SIGINT", "EXIT_SIGTERM", "epilog",
           "plugin_refusal"]

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_FELL = 0, 1, 2, 3
EXIT_SIGINT, EXIT_SIGTERM = 128 + signal.SIGINT, 128 + signal.SIGTERM   # 130, 143

_MEANING: Dict[int, str] = {
    EXIT_OK: "done",
    EXIT_ERROR: "an unexpected error",
    EXIT_USAGE: "a mistake in an option, parameter file, spec or law plug-in, said in one line (nothing ran)",
    EXIT_FELL: "a robot fell or its run failed (the line says when and why)",
    EXIT_SIGINT: "interrupted (Ctrl-C)",
    EXIT_SIGTERM: "terminated (SIGTERM)",
}


def epilog(**said: str) -> str:
    """'exit codes:' and a line per code a tool uses ('  3    a robot fell ...'), each with the common meaning or the
    tool's own words (``said`` keyed ``e0``, ``e2``, ...; an empty string leaves the code out), wrapped for a
    RawDescriptionHelpFormatter."""
    lines = ["exit codes:"]
    for code, meaning in _MEANING.items():
        text = said.get(f"e{code}", meaning)
        if text:
            lines += textwrap.wrap(text, 100, initial_indent=f"  {code:<5}", subsequent_indent=" " * 7)
    return "\n".join(lines)


def plugin_refusal(prog: str) -> Optional[int]:
    """A law plug-in of ``$MWIP_ROS_LAWS`` that failed to import (:func:`mwip_ros.core.laws.check_plugins`): its one
    line on stderr and :data:`EXIT_USAGE`; None when every plug-in loaded.  Every tool calls it before its work."""
    from mwip_ros.core import laws
    try:
        laws.check_plugins()
    except laws.PluginError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return None
