"""The time left of a sweep, from each law's own measured cost.

The laws of one sweep differ in cost per scenario by two orders of magnitude (a compiled law against MPC's QP
per period), so the time left is not the elapsed time scaled by the runs left: :class:`Eta` keeps, per law,
the scenarios left and the seconds per scenario its finished chunks took where they ran
(:attr:`~mwip_ros.sweep.engine.ChunkResult.seconds`), and the time left is the sum over the laws of scenarios
left x seconds per scenario, divided by the workers running in parallel.  A law's first chunk also pays the
process's one-off costs (numba compiling the loop: seconds), so once a second chunk of the law has finished the
first is left out.  A law with scenarios left and no chunk finished yet is *untimed*: the estimate then covers
the timed laws only, a lower bound, and says which laws it leaves out.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Dict, Iterable, List, Optional, Tuple

__all__ = ["Eta", "describe_left", "Heartbeat"]


class Eta:
    """Time left of the chunks given (each with ``controller`` and a length), updated as each one finishes."""

    def __init__(self, chunks: Iterable):
        self.left: Dict[str, int] = {}
        for c in chunks:
            self.left[c.controller] = self.left.get(c.controller, 0) + len(c)
        self._timed: Dict[str, List[Tuple[float, int]]] = {}   # law -> (seconds, scenarios) per finished chunk

    def done(self, controller: str, scenarios: int, seconds: float) -> None:
        """A chunk of ``scenarios`` runs of ``controller`` finished after ``seconds`` of its worker's time."""
        self.left[controller] = max(0, self.left.get(controller, 0) - scenarios)
        if scenarios > 0 and seconds >= 0:
            self._timed.setdefault(controller, []).append((float(seconds), int(scenarios)))

    def cost(self, controller: str):
        """Seconds per scenario of ``controller`` (its first chunk left out once there is a second), or None."""
        chunks = self._timed.get(controller)
        if not chunks:
            return None
        use = chunks[1:] if len(chunks) > 1 else chunks
        return sum(s for s, _ in use) / sum(n for _, n in use)

    def estimate(self, workers: int = 1) -> Tuple[float, List[str]]:
        """(seconds left for the timed laws on ``workers`` in parallel, the untimed laws with runs left)."""
        work, untimed = 0.0, []
        for law, n in self.left.items():
            if n <= 0:
                continue
            c = self.cost(law)
            if c is None:
                untimed.append(law)
            else:
                work += n * c
        return work / max(1, int(workers)), untimed


def describe_left(seconds: float, untimed: List[str]) -> str:
    """'85 s left', 'more than 12 s left (mpc_ndo not timed yet)', or 'time left not known yet (mpc not timed
    yet)' while only untimed laws have runs left."""
    if not untimed:
        return f"{seconds:.0f} s left"
    if seconds < 0.5:
        return f"time left not known yet ({', '.join(untimed)} not timed yet)"
    return f"more than {seconds:.0f} s left ({', '.join(untimed)} not timed yet)"


class Heartbeat:
    """A line at least every ``every_s`` seconds while work goes on, whatever runs it (this process, workers, Dask):
    a daemon thread calls ``line()`` (a text to print, or None) when nothing was said for ``every_s``; ``said()``
    marks a line said otherwise (a chunk that finished).  A context manager: the thread stops on leaving.

    Parameters
    ----------
    every_s : float
        The longest silence [s].
    line : callable
        ``line() -> str or None``: what to say (None: nothing, e.g. a progress bar redrawn instead).
    say : callable
        ``say(text)``: prints it.
    """

    def __init__(self, every_s: float, line: Callable[[], Optional[str]], say: Callable[[str], None]):
        self.every_s, self.line, self.say = float(every_s), line, say
        self.lock = threading.Lock()   # a line at a time, the thread's and the caller's
        self._last = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="heartbeat", daemon=True)

    def said(self) -> None:
        """A line was just said: the next heartbeat waits ``every_s`` from now."""
        self._last = time.monotonic()

    def _run(self) -> None:
        while not self._stop.wait(max(0.05, self.every_s - (time.monotonic() - self._last))):
            if time.monotonic() - self._last >= self.every_s:
                with self.lock:
                    text = self.line()
                    if text:
                        self.say(text)
                    self._last = time.monotonic()

    def __enter__(self):
        self._last = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(2.0)
