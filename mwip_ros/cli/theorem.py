"""``mwip_theorem``: the Theorem 2 table (eq. 34-35) for a parameter file."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mwip_ros.cli.exits import plugin_refusal
from mwip_ros import params as P
from mwip_ros.core.control.theorem import theorem2
from mwip_ros.params.paths import default_params_file

MEANING = {"a1": "k1 - (m11+m12)/m22", "a2": "k2 - k1/2 - (m11+m12)/(2 m22)",
           "a3": "1/tau4 - 3 k1/2 - (m11+m12)/(2 m22)", "a4": "c1/m11 - (m11+m12) c2/A_bar - 1",
           "a5": "c4/m22 - m12 c3/A_bar - 1", "gamma": "min(a1..a5), must be > 0"}


def theorem_report(values) -> str:
    """The Theorem 2 table as text, from a merged parameter dict."""
    nom = P.physical(values, "nominal")
    th = theorem2(nom, P.gains(values), P.observer_gain(values))
    lines = [f"Theorem 2 (eq. 35), nominal model: m11={nom.m11:.4f} m12={nom.m12:.4f} m22={nom.m22:.4f} "
             f"A_bar={nom.A_bar:.4f}"]
    for k, v in th.as_dict().items():
        flag = "ok" if v > 0 else "VIOLATED"
        lines.append(f"  {k:<5} = {v:12.4f}   {flag:<8}  {MEANING[k]}")
    lines.append("  -> conditions " + ("hold (gamma > 0)" if th.satisfied else "do NOT hold: stability is not "
                                        "guaranteed by Theorem 2"))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="mwip_theorem",
                                 description="Print a1..a5 and gamma of Theorem 2 (eq. 34-35) for the gains and "
                                             "nominal model of a ROS 2 parameter file. Exit 0 if gamma > 0, else 1.")
    ap.add_argument("--params", type=Path, nargs="+", default=None, metavar="FILE",
                    help="parameter file(s), merged in order (default: config/paper.yaml)")
    args = ap.parse_args(argv)
    refused = plugin_refusal("mwip_theorem")
    if refused is not None:
        return refused
    try:
        values = P.merged_values(P.load_param_files(args.params or [default_params_file()], option="--params"))
    except P.ParamError as exc:
        print(f"mwip_theorem: error: {exc}", file=sys.stderr)
        return 2
    print(theorem_report(values))
    return 0 if theorem2(P.physical(values, "nominal"), P.gains(values), P.observer_gain(values)).satisfied else 1


if __name__ == "__main__":
    sys.exit(main())
