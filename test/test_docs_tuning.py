"""The tuning table of the docs (docs/sweeps.md, "The shipped tuned gains") is what its printed command makes.

The cheap check, not the search itself (33 s here, and it writes the same gains to the last digit): the
``mwip_tune`` command printed above the table is parsed with mwip_tune's own option parser and compared, option by
option, with the settings line the tool wrote into the overlay the table names (``# settings:`` and ``# search:``
of config/tuned_dscndo.yaml) and with the command in the tuning spec's header; the caption's generations and
candidates must be what those settings give (scipy's differential evolution judges ``popsize * numbers``
candidates in its first population and in every generation); the table's gains are the base file's and the
overlay's to their printed digits; and its judged rows (J, upright, medians, Theorem 2) are both gains judged
again on the held-out set, as mwip_tune judges them (two batch runs of 100 scenarios, about a second each).
"""
from __future__ import annotations

import dataclasses
import re
import shlex

import numpy as np
import pytest
import yaml

from graphproc import REPO
from mwip_ros.cli import tune as cli
from mwip_ros.sweep.spec import load_spec
from mwip_ros.sweep.tune import Objective, knobs_for
from test_docs_numbers import page_with, table_after

pytestmark = pytest.mark.unit

CAPTION = "DSCNDO tuned on `tune_dscndo.yaml`"
HEADER = "| | paper's gains | tuned |"
GAIN_ROWS = {"k1, k2, tau4": ("k1", "k2", "tau4"), "X (diagonal)": ("X.c1", "X.c4")}
JUDGED = {"J (held out)": "J", "upright": "upright_share", "theta_b RMS, median [rad]": "theta_b_rms_median",
          "u RMS, median [N m]": "u_rms_median", "Theorem 2": "theorem2_holds"}


def _options(words):
    """mwip_tune's namespace for ``words`` (a command without ``mwip_tune``; ``--out`` added if missing)."""
    if "--out" not in words:
        words = [*words, "--out", "unused.yaml"]
    return cli._parser().parse_args(words)


def _paragraph(lines, i):
    """The paragraph of ``lines`` that starts at line ``i``, as one string."""
    out = []
    while i < len(lines) and lines[i].strip():
        out.append(lines[i].strip())
        i += 1
    return " ".join(out)


def documented(text):
    """(the printed command's options, the caption, the table) of the docs page's tuning table."""
    lines = text.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith(CAPTION))
    command = next(ln for ln in reversed(lines[:at]) if ln.startswith("mwip_tune "))
    return _options(shlex.split(command)[1:]), _paragraph(lines, at), table_after(text, HEADER)


def recorded(overlay):
    """(options, generations, candidates, spec path) from the overlay's header, as mwip_tune wrote it."""
    head = overlay.read_text().splitlines()
    spec = re.match(r"# mwip_tune: \w+ tuned on (\S+) ", head[0]).group(1)
    settings = next(ln for ln in head if ln.startswith("# settings: "))[len("# settings: "):]
    gens, cands = re.match(r"# search: (\d+) generations, (\d+) candidates$",
                           next(ln for ln in head if ln.startswith("# search: "))).groups()
    return _options([spec, *shlex.split(settings)]), int(gens), int(cands), spec


def disagreements(text):
    """Every way the printed command, the caption and the overlay's recorded settings disagree (empty: none)."""
    doc, caption, _ = documented(text)
    overlay = REPO / re.search(r"\(`(config/[^`]+\.yaml)`\):", caption).group(1)
    rec, gens, cands, spec_path = recorded(overlay)
    spec = load_spec(REPO / doc.spec)
    bad = []
    holdout = spec.seed + 1 if doc.holdout_seed is None else doc.holdout_seed
    for name in ("controller", "tune", "maxiter", "popsize", "seed", "weight", "bounds"):
        if getattr(doc, name) != getattr(rec, name):
            bad.append(f"--{name}: printed {getattr(doc, name)!r}, the overlay was made with {getattr(rec, name)!r}")
    if holdout != rec.holdout_seed:
        bad.append(f"--holdout-seed: printed {holdout}, the overlay was made with {rec.holdout_seed}")
    if str(doc.spec) != spec_path or doc.spec.name not in caption:
        bad.append(f"spec: printed {doc.spec}, the overlay was tuned on {spec_path}, the caption says {caption!r}")
    m = re.search(r"\((\d+) mass-mismatch scenarios [^)]*?, (\d+) generations, ([\d,]+) candidates", caption)
    n, g, c = int(m.group(1)), int(m.group(2)), int(m.group(3).replace(",", ""))
    numbers = len(knobs_for(doc.tune, doc.controller))
    if (g, c) != (gens, cands):
        bad.append(f"caption: {g} generations, {c} candidates; the overlay's search: {gens}, {cands}")
    if c != doc.popsize * numbers * (g + 1) or g > doc.maxiter:
        bad.append(f"caption: {g} generations, {c} candidates; the printed command gives at most {doc.maxiter} "
                   f"generations of {doc.popsize * numbers} candidates after a first population of as many")
    if n != spec.samples:
        bad.append(f"caption: {n} scenarios; the spec has {spec.samples}")
    return bad


def test_the_printed_command_made_the_tables_overlay():
    text = page_with(CAPTION).read_text()
    assert disagreements(text) == []


def test_a_command_that_disagrees_with_the_table_is_caught():
    """Not vacuous: the defaults (no --maxiter, --popsize), as the docs once printed, or one changed option."""
    text = page_with(CAPTION).read_text()
    doc_line = next(ln for ln in text.splitlines() if ln.startswith("mwip_tune ") and "--maxiter" in ln)
    old = "mwip_tune config/sweeps/tune_dscndo.yaml --controller dscndo --tune k1 k2 tau4 X --out tuned.yaml"
    bad = disagreements(text.replace(doc_line, old))
    assert any(b.startswith("--maxiter: printed 30") for b in bad) and any(b.startswith("--popsize: printed 8")
                                                                           for b in bad), bad
    for edit in (("--seed 0", "--seed 1"), ("--tune k1 k2 tau4 X", "--tune k1 k2 X"), ("--popsize 6", "--popsize 7")):
        assert disagreements(text.replace(doc_line, doc_line.replace(*edit))), edit


def test_the_specs_header_prints_the_same_command():
    doc, _, _ = documented(page_with(CAPTION).read_text())
    header = [ln for ln in (REPO / doc.spec).read_text().splitlines() if ln.startswith("#")]
    spec_cmd = next(ln.lstrip("# ") for ln in header if ln.lstrip("# ").startswith("mwip_tune "))
    assert vars(_options(shlex.split(spec_cmd)[1:])) == vars(doc)


def _printed(cell: str, value) -> bool:
    if isinstance(value, bool):
        return cell == ("holds" if value else "fails")
    if cell.endswith(" %"):
        return cell == f"{100 * value:.0f} %"
    decimals = len(cell.split(".")[1]) if "." in cell else 0
    return cell == f"{value:.{decimals}f}"


def test_the_tables_gains_and_judged_rows_are_the_overlays_judged_on_the_held_out_set():
    text = page_with(CAPTION).read_text()
    doc, caption, (head, rows) = documented(text)
    assert head[1:] == ["paper's gains", "tuned"], head
    overlay = REPO / re.search(r"\(`(config/[^`]+\.yaml)`\):", caption).group(1)
    spec = load_spec(REPO / doc.spec)
    knobs = knobs_for(doc.tune, doc.controller)
    tuned_values = dict(spec.base_values)
    for section in yaml.safe_load(overlay.read_text()).values():
        tuned_values.update(section["ros__parameters"])
    x = {}
    for label, values in (("paper's gains", spec.base_values), ("tuned", tuned_values)):
        x[label] = np.array([values["X"][0] if k.name == "X.c1" else values["X"][3] if k.name == "X.c4"
                             else values[k.name] for k in knobs], dtype=float)
    names = [k.name for k in knobs]
    table = {r[0]: r[1:] for r in rows}
    assert sorted(n for row in GAIN_ROWS if row in table for n in GAIN_ROWS[row]) == sorted(names), table
    assert set(table) == set(GAIN_ROWS) | set(JUDGED), table
    holdout = dataclasses.replace(spec, seed=spec.seed + 1 if doc.holdout_seed is None else doc.holdout_seed)
    held = Objective(holdout, doc.controller, knobs, doc.weight)
    assert f"judged on {len(held.scenarios)} held-out scenarios" in caption
    bad = []
    for col, label in enumerate(("paper's gains", "tuned")):
        judged = held.judge(x[label])
        for row, gains in GAIN_ROWS.items():
            cells = [c.strip() for c in table[row][col].split(",")]
            want = [x[label][names.index(g)] for g in gains]
            bad += [(row, label, c, w) for c, w in zip(cells, want) if not _printed(c, w)]
        bad += [(row, label, table[row][col], judged[key]) for row, key in JUDGED.items()
                if not _printed(table[row][col], judged[key])]
        x[label] = judged
    assert not bad, "the tuning table differs from the overlay judged on the held-out set: " + "; ".join(
        f"{row} / {label}: printed {p!r}, computed {w!r}" for row, label, p, w in bad)
    m = re.search(r"calm the body ([0-9.]+) times more with (\d+) % less torque", text)
    assert m, "the sentence under the tuning table changed"
    p, t = x["paper's gains"], x["tuned"]
    assert m.groups() == (f"{p['theta_b_rms_median'] / t['theta_b_rms_median']:.1f}",
                          f"{100 * (1 - t['u_rms_median'] / p['u_rms_median']):.0f}")
