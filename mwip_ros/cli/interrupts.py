"""SIGTERM handled like SIGINT by the long-running commands (``mwip_sweep``, ``mwip_tune``, ``mwip_sim``,
``mwip_report``).

``timeout``, ``kill`` and batch schedulers stop a job with SIGTERM, whose default action ends the
process at once: no ``finally``, no worker shut down, no "interrupted: N rows kept" line.  With
:func:`handled`, SIGTERM raises :class:`Interrupted` (a :class:`KeyboardInterrupt`) in the main
thread exactly as Ctrl-C does, so the one interrupt path of each command runs for both: finished work
kept, workers stopped, one line.  The exit status is 128 + the signal: 130 for SIGINT, 143 for SIGTERM
(:func:`exit_code`).

Local worker processes (:mod:`mwip_ros.sweep.engine`) ignore SIGINT: a Ctrl-C at a terminal reaches the
whole process group, and only the parent, which knows what finished, decides; it stops its workers
itself (SIGTERM, then SIGKILL), whichever signal it got.
"""
from __future__ import annotations

import contextlib
import signal
import sys
import threading
from typing import Callable, Iterator, Optional

from .exits import EXIT_SIGINT, EXIT_SIGTERM, plugin_refusal   # 130, 143

__all__ = ["Interrupted", "handled", "received", "exit_code", "run_main", "EXIT_SIGINT", "EXIT_SIGTERM"]


_received: Optional[int] = None


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (``signum``)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _handler(signum, _frame):
    global _received
    _received = signum
    raise Interrupted(signum)


def received() -> Optional[int]:
    """The last signal :func:`handled` turned into :class:`Interrupted` (None: none)."""
    return _received


def exit_code(default: int = EXIT_SIGINT) -> int:
    """128 + the signal that interrupted (130 SIGINT, 143 SIGTERM); ``default`` when none was received
    (a KeyboardInterrupt raised otherwise)."""
    return 128 + _received if _received else default


@contextlib.contextmanager
def handled() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` in the main thread while inside; the previous handlers
    after."""
    global _received
    _received = None
    if threading.current_thread() is not threading.main_thread():   # only the main thread may set handlers
        yield
        return
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in old:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


def run_main(main: Callable[..., int], argv=None, prog: str = "") -> int:
    """``main(argv)`` with SIGTERM handled like SIGINT; an interrupt it does not handle itself ends in one
    line and 128 + the signal; a handled one that returns 130 (SIGINT's code) returns 143 after SIGTERM.  A law
    plug-in that failed to import (:func:`mwip_ros.core.laws.check_plugins`, before ``main``) and a law's step that
    raised (:class:`~mwip_ros.core.laws.LawError`) end in one line, exit 2 (:mod:`.exits`)."""
    from mwip_ros.core import laws
    refused = plugin_refusal(prog)   # a law plug-in ($MWIP_ROS_LAWS) that failed to import: one line, exit 2
    if refused is not None:
        return refused
    with handled():
        try:
            code = main(argv)
        except laws.LawError as exc:   # a law's step raised (a plug-in's bug): the law, when, where, its error
            print(f"{prog}: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            sig = signal.Signals(_received).name if _received else "SIGINT"
            print(f"{prog}: interrupted ({sig})", file=sys.stderr)
            return exit_code()
    if code == EXIT_SIGINT and _received:
        return exit_code()
    return code
