"""The documentation's headline numbers are what the code computes, to their printed digits.

Two tables of the docs pages (docs/*.md; README.md is searched too, so that no copy hides there): the paper
scenario's (the first table after "With the paper's values (`config/paper.yaml`), metrics over t in [5, 10] s:",
DSC and DSCNDO as run_experiment.sh reports them, docs/getting-started.md; the lockstep graph equals the offline
simulator sample by sample, test/nodes/test_graph.py) and the baseline's (DSC, DSCNDO, LQR, LQR+NDO,
docs/laws.md). Each table is found by its caption or header wherever it is, and must be on exactly one page, once.
Each law is simulated offline with config/paper.yaml, as ``mwip_sim --compare`` does, and every printed cell must
equal the computed metric formatted with the cell's own number of decimals (strings compared, so an edited digit
fails, and so does a change to the code that moves a printed digit; a metric on a rounding boundary may print either
way, test/printed.py).
"""
import re
from pathlib import Path

import pytest

from graphproc import PARAMS, REPO
from printed import prints_as
from mwip_ros import params as P
from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.closed_loop.sim import LAWS, simulate

pytestmark = pytest.mark.unit

README = REPO / "README.md"
DOCS = REPO / "docs"
PAPER_CAPTION = "With the paper's values (`config/paper.yaml`), metrics over t in [5, 10] s:"
BASELINE_HEADER = "| law | theta_b p2p [rad] | theta_b RMS [rad] | u RMS [N m] |"
RATIO = re.compile(r"DSCNDO's steady-state oscillation is ([0-9.]+)x smaller than DSC's")
LABELS = {"DSC": "dsc", "DSCNDO": "dscndo", "LQR": "lqr", "LQR+NDO": "lqr_ndo"}
FIELDS = {"theta_b p2p [rad]": "theta_b_p2p", "theta_b RMS [rad]": "theta_b_rms",
          "max abs theta_b [rad]": "theta_b_max_abs", "u RMS [N m]": "u_rms"}
TABLES = (("paper scenario", PAPER_CAPTION, {"DSC", "DSCNDO"}), ("baseline", BASELINE_HEADER, set(LABELS)))


def pages():
    """README.md and every page of the site."""
    return [README, *sorted(DOCS.glob("*.md"))]


def page_with(marker: str, candidates=None) -> Path:
    """The one page (of ``candidates``, default every page) with a line starting with ``marker`` (a table's caption
    or header), which it has once."""
    counts = [(p, sum(ln.strip().startswith(marker) for ln in p.read_text().splitlines()))
              for p in (candidates or pages())]
    found = [(p, n) for p, n in counts if n]
    assert found, f"no page of the docs has a line {marker!r}"
    assert len(found) == 1 and found[0][1] == 1, f"{marker!r} is on more than one page or more than once: {found}"
    return found[0][0]


def _cells(line: str):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def table_after(text: str, marker: str):
    """(header cells, rows of cells) of the first Markdown table at or after the line ``marker``."""
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip().startswith(marker)), None)
    assert start is not None, f"no line {marker!r}"
    i = next(i for i in range(start, len(lines)) if lines[i].lstrip().startswith("|"))
    block = []
    while i < len(lines) and lines[i].lstrip().startswith("|"):
        block.append(_cells(lines[i]))
        i += 1
    assert len(block) >= 3 and all(set(c) <= set("-: ") for c in block[1]), block[:2]
    return block[0], block[2:]


def window_of(caption: str):
    m = re.search(r"t in \[([0-9.]+), ([0-9.]+)\] s", caption)
    assert m, caption
    return float(m.group(1)), float(m.group(2))


_computed = {}


def computed(law: str):
    """Metrics of ``law`` (a key of LAWS) in the paper's scenario over the caption's window."""
    if law not in _computed:
        values = P.merged_values(P.load_param_files([PARAMS]))
        kind, use_obs = LAWS[law]
        run = simulate(P.closed_loop(values, use_observer=use_obs, law=kind), law)
        _computed[law] = metrics.compute(run.columns, window_of(PAPER_CAPTION), values["fall_angle"])
    return _computed[law]


def mismatches(name: str, text: str, marker: str, must):
    """Every printed cell of the table at ``marker`` in ``text`` that differs from the computed value: (table, row,
    column, printed, computed as printed). Also the rows the table must have, if missing."""
    bad = []
    head, rows = table_after(text, marker)
    labels = [r[0] for r in rows]
    if sorted(labels) != sorted(must):
        bad.append((name, "rows", "", ", ".join(labels), ", ".join(sorted(must))))
    for row in rows:
        m = computed(LABELS[row[0]])
        for col, printed in zip(head[1:], row[1:]):
            if col == "upright":
                want = "yes" if m.upright else "NO"
            else:
                decimals = len(printed.split(".")[1]) if "." in printed else 0
                want = f"{getattr(m, FIELDS[col]):.{decimals}f}"
                if prints_as(printed, getattr(m, FIELDS[col]), f".{decimals}f"):   # this CPU's rounding or another's
                    want = printed
            if printed != want:
                bad.append((name, row[0], col, printed, want))
    return bad


def test_the_tables_are_the_computed_metrics_to_their_printed_digits():
    head, _ = table_after(page_with(PAPER_CAPTION).read_text(), PAPER_CAPTION)
    assert set(head[1:]) <= set(FIELDS) | {"upright"} and "theta_b p2p [rad]" in head, head
    assert window_of(PAPER_CAPTION) == tuple(metrics.WINDOW)
    bad = []
    for name, marker, must in TABLES:
        page = page_with(marker)
        bad += [(page.name, *b) for b in mismatches(name, page.read_text(), marker, must)]
    assert not bad, "the docs differ from what the code computes:\n" + "\n".join(
        f"  {page}, {t}: {row} / {col}: printed {p!r}, computed {w!r}" for page, t, row, col, p, w in bad)


def test_the_headline_ratio_is_the_computed_one():
    """"DSCNDO's steady-state oscillation is 5.5x smaller than DSC's" (mwip_sim --compare prints the same ratio)."""
    page = page_with("DSCNDO's steady-state oscillation is")
    m = RATIO.search(page.read_text())
    assert m, f"{page.name} no longer states the DSC / DSCNDO peak-to-peak ratio"
    assert prints_as(m.group(1), computed('dsc').theta_b_p2p / computed('dscndo').theta_b_p2p, ".1f"), m.group(1)


def _bump_last_digit(cell: str) -> str:
    return cell[:-1] + str((int(cell[-1]) + 1) % 10)


def test_an_edited_number_is_caught():
    """The check above is not vacuous: one digit changed in either table, on the page it is on, is a mismatch
    naming that cell."""
    for name, marker, must in TABLES:
        text = page_with(marker).read_text()
        head, rows = table_after(text, marker)
        col = head.index("theta_b p2p [rad]")
        row = rows[-1]
        line = "| " + " | ".join(row) + " |"
        start = text.index(marker)
        at = text.index(line, start)
        edited_row = list(row)
        edited_row[col] = _bump_last_digit(row[col])
        edited = text[:at] + "| " + " | ".join(edited_row) + " |" + text[at + len(line):]
        assert mismatches(name, text, marker, must) == []
        assert [b[:4] for b in mismatches(name, edited, marker, must)] == [
            (name, row[0], "theta_b p2p [rad]", edited_row[col])]


def test_a_table_on_two_pages_is_refused(tmp_path):
    """A stale copy of a checked table (say, left in README.md) would not be checked: it is refused instead."""
    page = page_with(BASELINE_HEADER)
    copy = tmp_path / "copy.md"
    copy.write_text(page.read_text())
    assert page_with(BASELINE_HEADER, [README, page]) == page
    with pytest.raises(AssertionError, match="more than one page"):
        page_with(BASELINE_HEADER, [README, page, copy])
