"""The optional third-party packages: each is imported where its feature needs it, and a missing one stops only
that feature, in one line naming the package and how to install it.

==========  ===================  ===========================  ===============================================
module      pip package          rosdep key (package.xml)     what needs it (without it)
==========  ===================  ===========================  ===============================================
daqp        daqp                 python3-daqp-pip             the law mpc / mpc_ndo, its QP solver (exit 2
                                                              for a tool or node asked for it; the other
                                                              laws run)
foxglove    foxglove-sdk         python3-foxglove-sdk-pip     foxglove_server, the live view (exit 2)
numba       numba                python3-numba                the batch simulator's compiled loop (mwip_sweep,
                                                              mwip_tune): without it the scalar loop runs
                                                              each scenario, slower, the same numbers
dask        dask[distributed]    python3-dask-pip             mwip_sweep --dask (exit 2)
lz4         lz4                  python3-lz4-pip              reading a bag whose chunks are lz4-compressed
mujoco      mujoco               python3-mujoco-pip           the plant backend mujoco (exit 2 for a tool
                                                              asked for it; the rk4 backend runs)
gymnasium   gymnasium            python3-gymnasium-pip        mwip_ros.envs, the Gymnasium environments (an
                                                              import of mwip_ros.envs raises the one line)
moteus      moteus               python3-moteus-pip           the moteus backend and mwip_moteus_emulator (exit
                                                              2; the other backends run)
==========  ===================  ===========================  ===============================================

Every one is declared in package.xml (a ROS user's ``rosdep install`` installs them); the keys ending in ``-pip``
are PyPI packages that rosdistro does not name, defined for rosdep in ``rosdep/mwip_ros.yaml``.
"""
from __future__ import annotations

import contextlib
import importlib
import os
import sys
from typing import Dict, Iterator, NamedTuple, Optional

__all__ = ["OptionalPackage", "OPTIONAL", "MissingPackage", "headless_gl", "missing", "required"]


class OptionalPackage(NamedTuple):
    pip: str        # what `pip install` takes
    rosdep: str     # the key package.xml declares
    feature: str    # what needs it, for the one line


OPTIONAL: Dict[str, OptionalPackage] = {
    "daqp": OptionalPackage("daqp", "python3-daqp-pip", "the law mpc (its QP solver)"),
    "foxglove": OptionalPackage("foxglove-sdk", "python3-foxglove-sdk-pip", "foxglove_server (the live view)"),
    "numba": OptionalPackage("numba", "python3-numba", "the batch simulator's compiled loop"),
    "dask": OptionalPackage("dask[distributed]", "python3-dask-pip", "mwip_sweep --dask"),
    "lz4": OptionalPackage("lz4", "python3-lz4-pip", "reading lz4-compressed bag chunks"),
    "mujoco": OptionalPackage("mujoco", "python3-mujoco-pip", "the plant backend mujoco"),
    "gymnasium": OptionalPackage("gymnasium", "python3-gymnasium-pip", "mwip_ros.envs (the Gymnasium environments)"),
    "moteus": OptionalPackage("moteus", "python3-moteus-pip", "the moteus backend and its emulator"),
    "upkie": OptionalPackage("upkie", "python3-upkie-pip", "the Upkie backend"),
    "upkie_description": OptionalPackage("upkie-description", "python3-upkie-description-pip",
                                         "the Upkie backend (Upkie's URDF)"),
    "urdf_parser_py": OptionalPackage("urdf_parser_py", "urdfdom_py", "a robot's planar model from its URDF "
                                      "(robot.planar_model: the Upkie backend)"),
    "pybullet": OptionalPackage("pybullet", "python3-pybullet-pip", "the Upkie backend's simulation (PyBullet)"),
}


class MissingPackage(ImportError):
    """An optional package a feature needs cannot be imported; ``str()`` is the one line to show."""


def _text(module: str, reason: str, feature: Optional[str]) -> str:
    top = module.split(".")[0]
    pkg = OPTIONAL.get(top, OptionalPackage(top, f"python3-{top}", top))
    return (f"{feature or pkg.feature} needs the Python package {pkg.pip}, which cannot be imported ({reason}): "
            f"pip install '{pkg.pip}' (rosdep key {pkg.rosdep})")


@contextlib.contextmanager
def required(module: str, feature: Optional[str] = None) -> Iterator[None]:
    """Around the import statements of an optional package: an ImportError inside becomes :class:`MissingPackage`,
    whose text names the package (``module``'s top level), the feature (``feature``, else the table's) and how to
    install it.  The imports stay plain statements, where a reader (and package.xml's check) sees them::

        with required("daqp", "the law mpc"):
            import daqp
    """
    if module.split(".")[0] == "mujoco":
        headless_gl()
    try:
        yield
    except ImportError as exc:
        raise MissingPackage(_text(module, str(exc) or type(exc).__name__, feature)) from None


def headless_gl() -> None:
    """Before ``import mujoco``: with no display and no ``MUJOCO_GL`` of the user's, MuJoCo's renderer (``mwip_sim
    --render``) uses EGL; MuJoCo reads the variable once, when it is imported; a missing EGL only disables drawing."""
    if sys.platform.startswith("linux") and not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"


def missing(module: str, feature: Optional[str] = None) -> Optional[str]:
    """None when ``module`` can be imported (it is imported then), else the one line :func:`required` raises: for a
    check before any work (the law chosen, ``--dask``)."""
    try:
        with required(module, feature):
            importlib.import_module(module)
    except MissingPackage as exc:
        return str(exc)
    return None
