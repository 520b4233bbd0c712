"""The cross-entropy example (mwip_ros/envs/examples/cem.py) learns a linear policy that balances the paper's robot,
in under a minute, and docs/learning.md's comparison table is what it computes, to the printed digits (the search is
run again here, as the page's command runs it; DSCNDO's and LQR's rows by the batch simulator)."""
import time

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from mwip_ros.envs import MwipEnv  # noqa: E402
from mwip_ros.envs.examples import cem  # noqa: E402
from test_docs_numbers import page_with, table_after  # noqa: E402

pytestmark = pytest.mark.slow

HEADER = "| controller | theta_b RMS, mean [mrad] |"


@pytest.fixture(scope="module")
def learned():
    t0 = time.perf_counter()
    policy = cem.train()   # the page's command: its defaults
    rms = cem.judge(policy)
    return policy, rms, time.perf_counter() - t0


def test_the_search_and_its_judgement_take_under_a_minute(learned):
    assert learned[2] < 60.0, learned[2]


def test_the_learned_policy_balances_the_papers_robot_for_10_s(learned):
    """On the paper's robot itself (config/paper.yaml, its seed), through the scalar env: upright to the end."""
    policy = learned[0]
    env = MwipEnv(duration=10.0)
    obs, _ = env.reset(seed=0)
    steps, worst = 0, 0.0
    while True:
        obs, r, terminated, truncated, _ = env.step(policy(obs[None, :])[0])
        steps += 1
        worst = max(worst, abs(env._period.side.plant.x[1]))
        if terminated or truncated:
            break
    assert truncated and not terminated and steps == 2000
    assert worst < 0.1745 + 1e-9   # never beyond its initial tilt


def test_the_docs_table_is_what_the_example_computes(learned):
    header, rows = table_after(page_with(HEADER).read_text(), HEADER)
    rms = learned[1]
    want = {"linear policy (cross-entropy)": rms["policy"], "DSCNDO": rms["dscndo"], "LQR": rms["lqr"]}
    assert [r[0] for r in rows] == list(want)
    for row in rows:
        v = want[row[0]]
        ok = v[np.isfinite(v)]
        assert row[1:] == [f"{1e3 * ok.mean():.2f}", f"{1e3 * ok.max():.2f}", str(int((~np.isfinite(v)).sum()))], row
    assert len(rms["policy"]) == cem.HELD_OUT == 16


def test_the_policy_file_holds_the_weights(learned, tmp_path):
    import json
    learned[0].save(tmp_path / "p.json")
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["policy"] == "linear" and tuple(doc["w"]) == learned[0].w and doc["scale"] == 256.0
