"""Robustness sweeps: many scenarios through the batch simulator, here or on a Dask cluster.

===================  ===============================================================
:mod:`.spec`         the sweep spec (YAML): base file, laws, window, varied parameters
:mod:`.scenarios`    every scenario's values and D_w seed; a scenario's parameter file
:mod:`.engine`       chunks, and the runners: this process, worker processes, Dask
:mod:`.results`      results.csv (streamed), summary.json / summary.md, region of attraction
:mod:`.tune`         gain tuning: differential evolution over a spec's scenarios
:mod:`.progress`     the time left, each law at its own cost; a line at least every few seconds
:mod:`.warm`         the batch loop compiled before a sweep needs it (and at set-up), said
===================  ===============================================================

The command lines are :mod:`mwip_ros.cli.sweep` (``mwip_sweep``) and :mod:`mwip_ros.cli.tune`
(``mwip_tune``); the figures are in
:mod:`mwip_ros.cli.plotting`.
"""
from .spec import Axis, SpecError, SweepSpec, load_spec, parse_spec
from .scenarios import Scenarios, expand, noise_seed, parameter_file

__all__ = ["Axis", "SpecError", "SweepSpec", "load_spec", "parse_spec", "Scenarios", "expand", "noise_seed",
           "parameter_file"]
