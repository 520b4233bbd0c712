"""A sweep's outputs: ``results.csv`` (streamed), ``summary.json`` and ``summary.md``.

``results.csv`` has one row per scenario and law: ``scenario, seed, controller``, each varied
parameter by its spec key holding the value used, then ``upright, t_fall, failure`` (why a run failed: ``fall``,
``bad_command`` (the law's command not a finite number or beyond 1e6 N m), ``diverged``; empty when upright) and the
metrics over the window (:data:`METRICS`; NaN where a run has no sample in the window).  Values are written
with ``repr`` so a row reads back to the very floats that ran.  Rows are written and flushed as
chunks finish, so an interrupted sweep leaves every finished row readable.

The summary takes, per law, the share of scenarios that stayed upright and the median, 90th
percentile and maximum of each metric over the upright ones; where the spec varies
``plant_sim.initial.theta_b``, the region of attraction: the largest |theta_b(0)| such that every
scenario starting at most that far from upright recovered.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

__all__ = ["METRICS", "EXTRA_METRICS", "ALL_METRICS", "UNITS", "RATIO_METRICS", "run_labels",
            "median_ratios", "ResultsWriter", "laws", "sort_file", "read_results",
           "summarize", "summary_markdown", "region_of_attraction", "write_summary", "THETA0_KEY"]

# results.csv name -> the batch simulator's metric name
METRICS = {"theta_b_p2p": "theta_b_p2p", "theta_b_rms": "theta_b_rms", "max_abs_theta_b": "theta_b_max_abs",
           "u_rms": "u_rms", "tau_hat1_err_rms": "tau_err1_rms", "tau_hat2_err_rms": "tau_err2_rms"}
THETA0_KEY = "plant_sim.initial.theta_b"
UNITS = {"theta_b_p2p": "rad", "theta_b_rms": "rad", "max_abs_theta_b": "rad", "u_rms": "N m",
         "tau_hat1_err_rms": "N m", "tau_hat2_err_rms": "N m"}
REFERENCE = "dscndo"          # the law each law's medians are compared to (else the last law)
RATIO_METRICS = ("theta_b_p2p", "theta_b_rms", "u_rms")
# what a run has beside them when its loop has the stage (raw sensors' estimator, the motor, motion references:
# core.closed_loop.metrics.motion_metrics): written always (NaN without the stage), summarized where some run has a
# value; a results.csv of before them still reads
EXTRA_METRICS = {"theta_b_est_err_rms": "theta_b_est_err_rms", "dtheta_b_est_err_rms": "dtheta_b_est_err_rms",
                 "u_applied_rms": "u_applied_rms", "saturated_s": "saturated_s", "speed_rms": "speed_rms",
                 "hold_drift": "hold_drift", "hold_rate": "hold_rate", "max_lean": "max_lean"}
UNITS.update({"theta_b_est_err_rms": "rad", "dtheta_b_est_err_rms": "rad/s", "u_applied_rms": "N m",
              "saturated_s": "s", "speed_rms": "m/s", "hold_drift": "m", "hold_rate": "m/s", "max_lean": "rad"})
ALL_METRICS = {**METRICS, **EXTRA_METRICS}


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, list):
        return json.dumps(v)
    return str(v)


class ResultsWriter:
    """Append rows to ``results.csv`` chunk by chunk (header first), flushing after each chunk."""

    def __init__(self, path: Path, varied: List[str], extra: bool = False):
        """``extra``: the loop has a stage whose metrics are :data:`EXTRA_METRICS` (raw sensors, the motor), and
        the table gets their columns."""
        self.path = path
        self.varied = list(varied)
        self.metrics = ALL_METRICS if extra else METRICS
        self.header = ["scenario", "seed", "controller", *self.varied, "upright", "t_fall", "failure", *self.metrics]
        self._f = open(path, "w", newline="")
        self._w = csv.writer(self._f)
        self._w.writerow(self.header)
        self._f.flush()
        self.rows = 0

    def add(self, chunk, result, scenarios) -> None:
        """The chunk's rows in one write: a Ctrl-C or SIGTERM (raised between Python statements) lands before
        or after it, so the file holds whole chunks only."""
        text = io.StringIO()
        w = csv.writer(text)
        for j in range(len(chunk)):
            i = chunk.first + j
            row = [i, scenarios.seeds[i], chunk.controller, *(scenarios.values[k][i] for k in self.varied),
                   bool(result.upright[j]), float(result.t_fall[j]), _failure(result, j),
                   *(float(result.metrics[m][j]) if m in result.metrics else math.nan
                     for m in self.metrics.values())]
            w.writerow([_fmt(v) for v in row])
        self._f.write(text.getvalue())
        self._f.flush()
        self.rows += len(chunk)

    def close(self) -> None:
        self._f.close()


def _failure(result, j: int) -> str:
    """Why run ``j`` failed ('fall', 'bad_command', 'diverged': core.closed_loop.trajectory.FAILURES), '' when it did
    not."""
    from mwip_ros.core.closed_loop.trajectory import FAILURES
    f = getattr(result, "failure", None)
    return FAILURES[int(f[j])] if f is not None else ("" if result.upright[j] or math.isnan(result.t_fall[j])
                                                      else "fall")


def laws(cols: Dict[str, list]) -> List[str]:
    """The laws of a results table, in the registry's order dsc, dscndo, ... (whatever order their chunks
    finished in)."""
    from mwip_ros.core import laws as registry
    known = registry.names()
    labels = list(dict.fromkeys(cols["controller"]))   # a law, or a law and its choices ('dscndo (raw, kalman)')

    def order(c):
        law = c.split(" (")[0]
        return (known.index(law) if law in known else len(known) + len(law), labels.index(c))
    return sorted(labels, key=order)


def sort_file(path: Path, order: List[str]) -> None:
    """Rewrite a finished results.csv by scenario, then law (rows arrive as chunks finish, in any order), so
    the file is the same however the sweep ran.  Atomic: the sorted copy replaces the file."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    i_s, i_c = head.index("scenario"), head.index("controller")
    body.sort(key=lambda r: (int(r[i_s]), order.index(r[i_c])))
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        csv.writer(f).writerows([head, *body])
    tmp.replace(path)


REQUIRED = ("scenario", "seed", "controller", "upright", "t_fall", *METRICS)   # what every results.csv has


def read_results(path: Path) -> Dict[str, list]:
    """results.csv as columns: numbers as floats (``scenario``, ``seed`` as ints, ``upright`` as bools),
    list-valued parameters as lists, ``controller`` as strings.

    ValueError, one line naming the file and the line, for anything a sweep does not write: no header or one
    without :data:`REQUIRED`'s columns, a value that does not parse, a field over the csv module's limit
    (128 KiB).  A row cut by a crash mid-write (fewer fields) is not a result and is skipped."""
    path = Path(path)
    cols: Dict[str, list] = {}
    from mwip_ros.core.kernels.budget import RESULT_COLUMN, fmt_bytes, memory_budget
    from mwip_ros.yamlio import NotRegularFile, open_regular
    try:
        raw = open_regular(path, "results file")
    except NotRegularFile as exc:
        raise ValueError(f"{path}: {exc}") from None
    # a cell read back costs RESULT_COLUMN bytes and takes at least 2 characters of the file: within the budget
    most = 2 * memory_budget() // RESULT_COLUMN
    size = os.fstat(raw.fileno()).st_size
    if size > most:
        raw.close()
        raise ValueError(f"{path} is {fmt_bytes(size)}: reading it back may take more than the memory budget "
                         f"({fmt_bytes(memory_budget())}, MWIP_MEMORY_BUDGET); at most {fmt_bytes(most)} is read")
    try:
        with io.TextIOWrapper(raw, encoding="utf-8", newline="") as f:
            reader = csv.reader(f)
            head = next(reader, None)
            if not head:
                raise ValueError(f"{path} is empty")
            missing = [h for h in REQUIRED if h not in head]
            if missing:
                raise ValueError(f"{path}: the header has no {', '.join(repr(m) for m in missing[:3])} column"
                                 f"{'s' if len(missing) > 1 else ''} (a cut header, or not a sweep's results.csv)")
            if len(set(head)) != len(head):
                raise ValueError(f"{path}: the header repeats a column")
            cols = {h: [] for h in head}
            for r in reader:
                if len(r) != len(head):   # a row cut by a crash mid-write: not a result
                    continue
                try:
                    for h, v in zip(head, r):
                        cols[h].append(_value(h, v))
                except (ValueError, RecursionError) as exc:
                    raise ValueError(f"{path} line {reader.line_num}: column {h!r}: {_brief(exc)}") from None
    except csv.Error as exc:
        raise ValueError(f"{path}: not a results.csv ({exc})") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not text ({exc.reason})") from None
    n = min(len(v) for v in cols.values())
    return {h: v[:n] for h, v in cols.items()}   # a row cut mid-parse above raised; every column has n values


def _brief(exc) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 120 else text[:120] + "..."


def _value(h: str, v: str):
    if h in ("controller", "failure"):
        return v
    if h in ("scenario", "seed"):
        return int(v)
    if h == "upright":
        if v not in ("0", "1"):
            raise ValueError(f"{v[:20]!r} is not 0 or 1")
        return v == "1"
    if v.startswith("["):
        x = json.loads(v)
        if not isinstance(x, list) or not all(isinstance(e, (int, float)) and not isinstance(e, bool) for e in x):
            raise ValueError("not a list of numbers")
        return x
    if h not in ALL_METRICS and h != "t_fall" and _CHOICE.match(v) and v.lower() not in ("nan", "inf", "infinity"):
        return v   # a varied choice (sensors.model, state_estimator.method, ...)
    return float(v)


_CHOICE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def region_of_attraction(theta0: np.ndarray, upright: np.ndarray) -> Optional[float]:
    """The largest a = |theta_b(0)| among the runs such that every run with |theta_b(0)| <= a stayed upright;
    None when the smallest one already fell."""
    a = np.abs(np.asarray(theta0, dtype=float))
    ok = np.asarray(upright, dtype=bool)
    best = None
    for level in np.unique(a):
        if not ok[a <= level].all():
            break
        best = float(level)
    return best


def _stats(x: np.ndarray) -> Dict[str, Optional[float]]:
    x = x[np.isfinite(x)]
    if not len(x):
        return {"median": None, "p90": None, "max": None}
    return {"median": float(np.median(x)), "p90": float(np.percentile(x, 90)), "max": float(np.max(x))}


def _present(cols: Dict[str, list]) -> List[str]:
    """:data:`METRICS`, and the :data:`EXTRA_METRICS` some run of the table has a value of."""
    return list(METRICS) + [m for m in EXTRA_METRICS if m in cols and np.isfinite(np.array(cols[m], dtype=float)).any()]


def run_labels(cols: Dict[str, list], spec_info: dict) -> List[str]:
    """Each row's group in the summary: its law, and the values of the varied choices (string and bool axes:
    ``sensors.model``, ``state_estimator.method``, ``motor.enabled``, ...), e.g. ``dscndo (raw, kalman)``."""
    axes = [a for a in spec_info.get("axes", []) if a.get("type") in ("string", "bool") and a["key"] in cols]
    if not axes:
        return list(cols["controller"])

    def shown(a, v) -> str:   # a bool reads back as 1.0 / 0.0: say it as the parameter file does
        return f"{a['name']} {'true' if float(v) else 'false'}" if a["type"] == "bool" else str(v)
    return [f"{c} ({', '.join(shown(a, cols[a['key']][i]) for a in axes)})" for i, c in enumerate(cols["controller"])]


def summarize(cols: Dict[str, list], spec_info: dict) -> dict:
    """The summary document of a results table (``read_results``): a row per law, or per law and choice
    (:func:`run_labels`)."""
    labels = run_labels(cols, spec_info)
    ctrl = np.array(labels)
    upright = np.array(cols["upright"], dtype=bool)
    out = {"spec": spec_info, "scenarios": len(set(cols["scenario"])), "controllers": {}}
    order = {c: i for i, c in enumerate(laws(cols))}
    groups = sorted(set(labels), key=lambda g: (order.get(g.split(" (")[0], len(order)), labels.index(g)))
    for c in groups:
        sel = ctrl == c
        entry = {"runs": int(sel.sum()), "upright": int(upright[sel].sum()),
                 "upright_share": float(upright[sel].mean()) if sel.any() else math.nan,
                 "failures": _failures(cols, sel),
                 "metrics_over": "upright runs",
                 "metrics": {m: _stats(np.array(cols[m], dtype=float)[sel & upright]) for m in _present(cols)}}
        if THETA0_KEY in cols:
            entry["region_of_attraction_theta_b0"] = region_of_attraction(np.array(cols[THETA0_KEY])[sel],
                                                                          upright[sel])
        out["controllers"][c] = entry
    out["units"] = {m: UNITS[m] for m in _present(cols)}
    out["ratios"] = median_ratios(out["controllers"])
    return out


def _failures(cols: Dict[str, list], sel: np.ndarray) -> Dict[str, int]:
    """How many runs of ``sel`` failed, by cause ('fall', 'bad_command', 'diverged'; a results.csv without the
    ``failure`` column: the runs that fell, as 'fall')."""
    if "failure" not in cols:
        return {"fall": int(np.sum(sel & ~np.isnan(np.array(cols["t_fall"], dtype=float))))} if sel.any() else {}
    out: Dict[str, int] = {}
    for f in np.array(cols["failure"], dtype=object)[sel]:
        if f:
            out[f] = out.get(f, 0) + 1
    return out


def median_ratios(controllers: Dict[str, dict]) -> dict:
    """Each law's median of :data:`RATIO_METRICS` over the reference law's (DSCNDO when the sweep ran it, else the
    last law): ``{"reference", "why", "laws": {law: {metric: ratio or None}}}``."""
    names = list(controllers)
    if not names:
        return {"reference": None, "why": "", "laws": {}}
    firsts = [c for c in names if c.split(" (")[0] == REFERENCE]
    ref = REFERENCE if REFERENCE in controllers else (firsts[0] if firsts else names[-1])
    why = ("the DSCNDO law" if ref == REFERENCE else "DSCNDO's first group" if firsts
           else f"the last law, as the sweep did not run {REFERENCE}")
    out = {}
    for c in names:
        if c == ref:
            continue
        out[c] = {}
        for m in RATIO_METRICS:
            a, b = controllers[c]["metrics"][m]["median"], controllers[ref]["metrics"][m]["median"]
            out[c][m] = a / b if a is not None and b is not None and b > 0 else None
    return {"reference": ref, "why": why, "of": "medians over the upright runs", "laws": out}


def _num(v, fmt="{:.4g}") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def summary_markdown(doc: dict) -> str:
    spec = doc["spec"]
    lines = [f"# Sweep summary: {spec.get('name', '')}", "",
             f"{doc['scenarios']:,} scenarios x {len(doc['controllers'])} law(s), {spec['duration_s']:g} s each, "
             f"metrics over t in [{spec['window'][0]:g}, {spec['window'][1]:g}] s (median / p90 / max over the "
             f"runs that stayed upright).", ""]
    if spec.get("varied"):
        lines += ["Varied: " + ", ".join(f"`{k}` ({d})" for k, d in spec["varied"].items()), ""]
    shown = [m for m in ALL_METRICS if all(m in e["metrics"] for e in doc["controllers"].values())]
    head = ["law", "upright", *(f"{m} [{UNITS[m]}]" for m in shown)]
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for c, e in doc["controllers"].items():
        other = ", ".join(f"{n} {why}" for why, n in e.get("failures", {}).items() if why != "fall")
        cells = [c, f"{e['upright']}/{e['runs']} ({100 * e['upright_share']:.1f} %{'; ' + other if other else ''})"]
        for m in shown:
            s = e["metrics"][m]
            cells.append(" / ".join(_num(s[k]) for k in ("median", "p90", "max")))
        lines.append("| " + " | ".join(cells) + " |")
    ratios = doc.get("ratios") or median_ratios(doc["controllers"])
    if ratios["laws"]:
        ref = ratios["reference"]
        rhead = ["law", *(f"{m} median / {ref}'s [x]" for m in RATIO_METRICS)]
        lines += ["", f"Each law's medians over {ref}'s ({ratios['why']}); above 1: {ref}'s is that many times "
                      f"smaller:", "",
                  "| " + " | ".join(rhead) + " |", "|" + "|".join("---" for _ in rhead) + "|"]
        for c, r in ratios["laws"].items():
            lines.append("| " + " | ".join([c, *(_num(r[m], "{:.2f}") for m in RATIO_METRICS)]) + " |")
    roa = {c: e.get("region_of_attraction_theta_b0") for c, e in doc["controllers"].items()
           if "region_of_attraction_theta_b0" in e}
    if roa:
        lines += ["", "Region of attraction (largest |theta_b(0)| from which every scenario recovered): "
                  + ", ".join(f"{c} {_num(v, '{:.3f}')} rad" for c, v in roa.items())]
    return "\n".join(lines) + "\n"


def write_summary(doc: dict, out: Path) -> None:
    from mwip_ros.core.closed_loop.metrics import json_safe
    (out / "summary.json").write_text(json.dumps(json_safe(doc), indent=2, allow_nan=False, default=str))
    (out / "summary.md").write_text(summary_markdown(doc))
