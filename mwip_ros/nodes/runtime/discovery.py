"""How every mwip_ros process finds the others: Fast DDS with the package's discovery profile, unless the user has
a middleware set-up of their own (docs/graph.md, "Discovery").

Fast DDS 2.14 (Jazzy's) sends a new participant's first announcement before it starts to receive, so the one
answer that a running participant sends straight back can be lost. The newcomer then learns of that participant
only at its next periodic announcement, 3 s later by default: a recorder that missed a short run, ``mwip_ctl``
answering after 3 s, a test that lost its first message. The profile :data:`PROFILE` makes every participant of
the package announce itself every 0.25 s, so that gap is at most a quarter of a second
(``scripts/bench_discovery.py`` measures it; BENCHMARKS.md, "Discovery").

:func:`apply` sets the profile in an environment (the process's own, before ``rclpy.init``: :func:`.process.run_node`
and ``mwip_ctl`` call it) and keeps the user's own set-up where there is one. This module imports no ROS.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import MutableMapping, Optional

__all__ = ["PROFILE", "OFF_VARIABLE", "USER_SETTINGS", "FASTDDS_RMWS", "apply", "kept_because"]

PROFILE = Path(__file__).with_name("fastdds_discovery.xml")
OFF_VARIABLE = "MWIP_DISCOVERY"   # "off": leave the middleware exactly as the environment has it
FASTDDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")   # the middlewares the profile is written for
# a user's own Fast DDS set-up: any of these set, and the package's profile is not applied
USER_SETTINGS = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE", "ROS_DISCOVERY_SERVER",
                 "ROS_SUPER_CLIENT", "RMW_FASTRTPS_USE_QOS_FROM_XML")
CWD_PROFILE = "DEFAULT_FASTRTPS_PROFILES.xml"   # Fast DDS loads this file from the working directory by itself


def kept_because(environ: MutableMapping[str, str], cwd: Optional[str] = None) -> Optional[str]:
    """Why the package's profile is not applied to ``environ`` (the user's own set-up, named), or None when it is.

    Parameters
    ----------
    environ : mapping
        The environment the process will run with.
    cwd : str, optional
        Its working directory (default: this process's); Fast DDS reads a profile file from there by itself.

    Returns
    -------
    str or None
        One phrase naming the user's setting, or None when nothing of the user's is in the way.
    """
    if environ.get(OFF_VARIABLE, "").strip().lower() in ("off", "0", "false", "no"):
        return f"{OFF_VARIABLE}={environ[OFF_VARIABLE]}"
    rmw = environ.get("RMW_IMPLEMENTATION", "").strip()
    if rmw and rmw not in FASTDDS_RMWS:
        return f"RMW_IMPLEMENTATION={rmw}"
    for key in USER_SETTINGS:
        value = environ.get(key, "").strip()
        if value and not (key == "FASTRTPS_DEFAULT_PROFILES_FILE" and value == str(PROFILE)):   # not ours
            return f"{key} is set"
    if (Path(cwd or os.getcwd()) / CWD_PROFILE).is_file():
        return f"{CWD_PROFILE} in the working directory"
    return None


def apply(environ: Optional[MutableMapping[str, str]] = None, cwd: Optional[str] = None) -> Optional[str]:
    """Point Fast DDS at :data:`PROFILE` in ``environ`` (default: ``os.environ``) unless the user has a set-up.

    Call it before the process creates its first participant (``rclpy.init``); a child process started with
    ``environ`` inherits the choice. Changes nothing when :func:`kept_because` names a setting of the user's.

    Parameters
    ----------
    environ : mutable mapping, optional
        The environment to change (default: this process's, which Fast DDS reads).
    cwd : str, optional
        The working directory the participant will be created in (default: this process's).

    Returns
    -------
    str or None
        What was kept (:func:`kept_because`), or None when the profile was applied.
    """
    env = os.environ if environ is None else environ
    reason = kept_because(env, cwd)
    if reason is None:
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
    return reason
