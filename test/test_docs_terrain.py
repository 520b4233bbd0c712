"""docs/laws.md "Terrain": the MuJoCo terrain tables are what mwip_ros.sweep.terrain measures.  A subset, to keep CI
cheap (about 20 s): for DSCNDO and LQR (ideal sensing; the slope table LQR+NDO too), each printed limit passes and
the next grid value fails (slope balanced and held, step driven over, lateral push survived); the flat-ground hold's
drift and band to their printed digits."""
from __future__ import annotations

import pytest

from graphproc import REPO
from test_docs_numbers import table_after

pytest.importorskip("mujoco")

from mwip_ros.sweep import terrain as T  # noqa: E402

pytestmark = pytest.mark.slow   # the documentation's tables recomputed (MuJoCo runs): heavy, not a unit of code

PAGE = REPO / "docs" / "laws.md"
SUBSET = ("dscndo", "lqr")


@pytest.fixture(scope="module")
def base():
    return T.base_values()


def _rows(caption):
    head, rows = table_after(PAGE.read_text(), caption)
    assert [r[0] for r in rows] == list(T.LAWS), rows
    return {r[0]: r for r in rows}


def _limit(cell):
    return None if cell == "-" else float(cell)


def _edge(run, grid, best):
    """``best`` passes (unless none did) and the grid value after it fails (unless it is the last)."""
    i = grid.index(best) + 1 if best is not None else 0
    if best is not None:
        assert run(best).ok, best
    if i < len(grid):
        assert not run(grid[i]).ok, grid[i]


@pytest.mark.parametrize("law", SUBSET + ("lqr_ndo",))   # the two (47 item 3): DSCNDO and LQR+NDO hold 5 deg
def test_the_slope_table(base, law):
    row = _rows("Slope, MuJoCo, ideal sensing:")[law]
    _edge(lambda d: T.slope_run(base, law, d, False), list(T.SLOPES_DEG), _limit(row[1]))
    _edge(lambda d: T.slope_run(base, law, d, True), list(T.SLOPES_DEG), _limit(row[2]))
    flat = T.slope_run(base, law, 0, True)
    assert row[3:] == [f"{flat.value:.4f}", f"{flat.extra:.3f}"]


@pytest.mark.parametrize("law", SUBSET)
def test_the_step_table(base, law):
    row = _rows("Step, MuJoCo, ideal sensing:")[law]
    _edge(lambda h: T.step_run(base, law, h), list(T.STEPS), _limit(row[1]))


@pytest.mark.parametrize("law", SUBSET)
def test_the_push_table(base, law):
    row = _rows("Lateral push, MuJoCo, ideal sensing:")[law]
    _edge(lambda f: T.push_run(base, law, f), list(T.PUSHES), _limit(row[1]))
