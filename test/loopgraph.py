"""One loop graph for many lockstep runs: the answering nodes started once, plants run against them one after another.

    with LoopGraph(tmp_path, params=PARAMS) as loop:
        loop.start()                                        # the observer and the controller (run_lockstep's args)
        loop.set("dscndo_controller", law="lqr", use_observer=False)   # through its parameter service
        run = loop.run("lqr", "-p", "duration_s:=2.0")      # a plant process: its exit code, csv, output
        est = loop.estimates()                              # after the observer stopped: its csv, one part a run

What :func:`graphproc.run_lockstep` does per run (a graph of processes on a private domain, the plant writing its
csv, the observer its estimates), with the observer and the controller kept up between the runs: a fresh graph is
three process starts, this is one. Each new plant starts a new stream at stamp 0; the observer and the controller
follow it after :data:`~mwip_ros.nodes.runtime.guards.RESYNC` copies of its first state (the plant resends an
unanswered state: the first ones are counted as rejected) and re-initialise, as for a plant restarted by hand. A
law or a gain changes through the parameter service between runs, as ``ros2 param set`` changes it.
"""
from __future__ import annotations

import signal
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

from graphproc import PARAMS, Graph, Proc, loop_chain

__all__ = ["LoopGraph", "Run", "concurrently"]


class Run:
    """One plant run of a :class:`LoopGraph`: ``code`` (its exit), ``csv`` (its trajectory), ``plant`` (its Proc)."""

    def __init__(self, label: str, code: Optional[int], csv: Path, plant: Proc, estimated: bool):
        self.label, self.code, self.csv, self.plant, self.estimated = label, code, csv, plant, estimated

    def output(self) -> str:
        return self.plant.output()


class LoopGraph:
    """A :class:`graphproc.Graph` with the loop's answering nodes for ``params`` (:func:`graphproc.loop_chain`),
    each started once with ``-p use_sim_time:=true`` and the arguments :func:`graphproc.run_lockstep` gives it
    (the observer's estimates to ``estimates.csv``, the estimator's to ``estimator.csv``), and ``args`` of a node's
    own; ``env`` is added to every process's environment."""

    def __init__(self, workdir: Path, params=PARAMS, args: Optional[Dict[str, tuple]] = None,
                 env: Optional[Dict[str, str]] = None):
        from mwip_ros import params as P
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.params = params
        self.graph = Graph(self.workdir)
        self.graph.env.update(env or {})
        self.nodes: Dict[str, Proc] = {}
        self.runs: List[Run] = []
        self.estimates_csv = self.workdir / "estimates.csv"
        own = {"disturbance_observer": ("-p", f"csv:={self.estimates_csv}")}
        if "csv" in P.specs_for("state_estimator"):
            own["state_estimator"] = ("-p", f"csv:={self.workdir / 'estimator.csv'}")
        for node, extra in (args or {}).items():
            own[node] = own.get(node, ()) + tuple(extra)
        self._args = own
        self._inj = None
        self._setter = None

    @property
    def domain_id(self) -> int:
        return self.graph.domain_id

    def start(self, *nodes: str, params=None) -> None:
        """Start the answering nodes ``nodes`` (default: every one of the chain of ``params`` not started yet) with
        ``params`` (default: the graph's)."""
        params = self.params if params is None else params
        names = nodes or tuple(a.node for a in loop_chain(params) if a.node not in self.nodes)
        for node in names:
            self.nodes[node] = self.graph.start(node, "-p", "use_sim_time:=true", *self._args.get(node, ()),
                                                params=params)

    def set(self, node: str, **values) -> None:
        """Set parameters of ``node`` (dotted names with ``__`` for ``.``) through its parameter service, each
        change asserted accepted."""
        from injector import Injector, ParamSetter
        if self._inj is None:
            self._inj = Injector(self.domain_id, name="loop_graph_params")
            self._setter = ParamSetter(self._inj)
        for key, value in values.items():
            result = self._setter.set(node, key.replace("__", "."), value)
            assert result.successful, (node, key, value, result.reason)

    def run(self, label: str, *plant_args: str, params=None, timeout: float = 180.0, wait=None,
            estimated: Optional[bool] = None) -> Run:
        """A plant (``plant_sim``, lockstep) run to its end with ``plant_args`` and ``params`` (default: the
        graph's): it writes ``LABEL.csv``. ``wait(plant, timeout)``, if given, waits for the plant instead of
        ``plant.wait`` and returns its exit code (:func:`graphproc.run_lockstep`'s); ``estimated``: whether the
        observer estimates the run's states (default: whether it is running; False for a run that sends it none)."""
        csv = self.workdir / f"{label}.csv"
        plant = self.graph.start("plant_sim", "-p", f"csv:={csv}", *plant_args,
                                 params=self.params if params is None else params, label=label)
        code = plant.wait(timeout) if wait is None else wait(plant, timeout)
        observer = self.nodes.get("disturbance_observer")
        if estimated is None:
            estimated = observer is not None and observer.poll() is None
        run = Run(label, code, csv, plant, estimated)
        self.runs.append(run)
        return run

    def stop(self, node: str, sig=signal.SIGINT, timeout: float = 20.0) -> Optional[int]:
        """Stop the answering node ``node`` (by PID); its exit code."""
        return self.nodes[node].stop(sig, timeout=timeout)

    def estimates(self) -> Dict[str, Path]:
        """{run label: a csv of the observer's estimates of that run} (once the observer stopped: its csv is
        whole): its csv cut where ``t`` goes back (a new stream), one part per run it estimated, in order."""
        lines = self.estimates_csv.read_text().splitlines()
        header, parts, last = lines[0], [], None
        for line in lines[1:]:
            t = float(line.split(",", 1)[0])
            if last is None or t < last:
                parts.append([])
            parts[-1].append(line)
            last = t
        estimated = [r for r in self.runs if r.estimated]
        assert len(parts) == len(estimated), (len(parts), [r.label for r in estimated])
        out = {}
        for run, part in zip(estimated, parts):
            out[run.label] = self.workdir / f"{run.label}.estimates.csv"
            out[run.label].write_text("\n".join([header, *part]) + "\n")
        return out

    def close(self) -> None:
        if self._inj is not None:
            self._inj.close()
            self._inj = None
        self.graph.close()

    def __enter__(self) -> "LoopGraph":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def concurrently(*jobs: Callable[[], Any]) -> list:
    """Each job (a sequence of runs on a :class:`LoopGraph` of its own: its own domain) in a thread of its own; their
    results, in order (a job's exception raised again once every job has ended). A lockstep loop waits on its
    processes' answers most of the time, so two loops take the two cores' turns between them."""
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(len(jobs)) as pool:
        futures = [pool.submit(job) for job in jobs]
        return [f.result() for f in futures]
