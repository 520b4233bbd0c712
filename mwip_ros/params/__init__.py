"""The ROS 2 parameter file: schema (the one place of every default), loading, typed configs.

==================  ================================================================
:mod:`.schema`      every parameter: type, default (the paper's values), range, text
:mod:`.file`        read and validate a parameter file; one node's values from it
:mod:`.typed`       PhysicalParams, DscGains, PlantConfig, ClosedLoop from values
:mod:`.errors`      ``ParamError`` (names the key)
==================  ================================================================
"""
from .errors import ParamError
from .file import ParamFile, load_param_file, load_param_files, load_yaml, merged_values, node_key, parse_param_dict
from .schema import (NODE_SPECS, PAPER_ACTUAL, PAPER_NOMINAL, ROS_OWN, ROS_OWN_PREFIXES, SHARED, SHARED_SPECS,
                     ParamSpec, check_derived, check_geometry, defaults_for, specs_for, spelling_hint)
from .typed import closed_loop, gains, motor, observer_gain, period, physical, plant_config, sinusoid

__all__ = ["ParamError", "ParamFile", "load_param_file", "load_param_files", "load_yaml", "check_derived",
           "check_geometry",
           "merged_values", "node_key", "parse_param_dict", "NODE_SPECS", "PAPER_ACTUAL", "PAPER_NOMINAL", "ROS_OWN",
           "ROS_OWN_PREFIXES", "SHARED", "SHARED_SPECS", "ParamSpec", "defaults_for", "specs_for", "spelling_hint",
           "closed_loop", "gains", "motor", "observer_gain", "period", "physical", "plant_config", "sinusoid"]
