"""Local worker processes and signals: a worker leaves Ctrl-C to its parent; the parent's cleanup of its
workers is not cut short by a second signal (:class:`signals_held`)."""
from __future__ import annotations

import signal
import threading

__all__ = ["worker_init", "signals_held", "stop_resource_tracker"]


def worker_init() -> None:
    """A local worker ignores SIGINT: a Ctrl-C at a terminal reaches the whole process group, and the parent,
    which knows what finished, stops the workers itself (SIGTERM, then SIGKILL)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class signals_held:
    """SIGINT and SIGTERM held back in the main thread while inside (a cleanup that must finish: stopping the
    workers), then handed to the handler that was in place: a second Ctrl-C or SIGTERM cannot leave a worker
    behind."""

    def __enter__(self):
        self._old, self._got = {}, []
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, lambda signum, frame: self._got.append(signum))
        return self

    def __exit__(self, *exc):
        for sig, handler in self._old.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        for signum in self._got[:1]:
            handler = self._old.get(signum)
            if callable(handler):
                handler(signum, None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


def stop_resource_tracker() -> None:
    """Stop multiprocessing's resource tracker (it is started with the first spawned pool and otherwise outlives
    this process, an orphan until its init reaps it) and wait for it: call it once every worker has exited.  The
    next pool starts a new one."""
    try:
        import multiprocessing
        from multiprocessing import resource_tracker
        if multiprocessing.active_children():   # a process still holds the tracker: waiting could hang
            return
        tracker = resource_tracker._resource_tracker
        stop = getattr(tracker, "_stop", None)
        if stop is not None and getattr(tracker, "_fd", None) is not None:
            stop()
    except Exception:  # noqa: BLE001 - a private API that changed: the tracker exits after this process
        pass
