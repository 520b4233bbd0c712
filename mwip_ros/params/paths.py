"""Where the package's installed files are (source checkout or ament install): the default parameter file."""
from __future__ import annotations

from pathlib import Path


def share_dir() -> Path:
    """The package's share directory: the source tree in a checkout, else the ament index."""
    src = Path(__file__).resolve().parents[2]
    if (src / "package.xml").is_file() and (src / "config").is_dir():
        return src
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory("mwip_ros"))


def default_params_file() -> Path:
    return share_dir() / "config" / "paper.yaml"
