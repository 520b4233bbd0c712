"""rosbag2 bag metadata: QoS profiles, ``metadata.yaml`` and the YAML they are written in.

rosbag2 (Jazzy) describes a bag in two places, both YAML written by yaml-cpp:

* each MCAP Channel's ``offered_qos_profiles`` metadata: the list of the publishers' QoS
  profiles (:func:`qos_profiles_yaml`, read back by :func:`parse_qos_yaml`);
* ``metadata.yaml`` (version 9): the ``rosbag2_bagfile_information`` mapping built by
  :func:`bag_metadata` from :class:`TopicInfo` and :class:`FileInfo`, also stored in the
  MCAP file as the ``rosbag2`` Metadata record.

:func:`dump_yaml` is ``yaml.safe_dump`` with yaml-cpp's block layout (a sequence is
indented under its key, null is ``~``, the empty string is ``""``, no line folding), so the
text reads back identically with any YAML loader and looks like what rosbag2 writes.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Union

import yaml

from mwip_ros.msgs.stamps import NS_PER_S
from mwip_ros.params.errors import bounded
from mwip_ros.yamlio import YamlRefused, load_yaml, shown

from .errors import BagError

__all__ = [
    "EMPTY_STARTING_TIME", "METADATA_VERSION", "ROS_DISTRO", "SERIALIZATION_FORMAT", "STORAGE_IDENTIFIER",
    "FileInfo", "TopicInfo", "bag_metadata", "dump_yaml", "metadata_yaml_text", "parse_qos_yaml",
    "qos_profile_dict", "qos_profiles_yaml", "write_metadata_yaml", "REPAIRED_KEY"]

# the custom_data entry mwip_bag_repair writes into a repaired bag's metadata.yaml: one line saying what was
# saved and what was lost (mwip_report shows it as a warning)
REPAIRED_KEY = "mwip_ros.repaired"

METADATA_VERSION = 9
STORAGE_IDENTIFIER = "mcap"
SERIALIZATION_FORMAT = "cdr"
ROS_DISTRO = "jazzy"
EMPTY_STARTING_TIME = 2 ** 63 - 1  # what rosbag2 writes for a bag without messages


# --- YAML --------------------------------------------------------------------------------------

class _Dumper(yaml.SafeDumper):
    """SafeDumper laid out like yaml-cpp: a block sequence is indented under its key."""

    def increase_indent(self, flow: bool = False, indentless: bool = False):
        return super().increase_indent(flow, False)


def _represent_none(dumper: yaml.SafeDumper, _value: None) -> yaml.Node:
    return dumper.represent_scalar("tag:yaml.org,2002:null", "~")


def _represent_str(dumper: yaml.SafeDumper, value: str) -> yaml.Node:
    if value == "":
        return dumper.represent_scalar("tag:yaml.org,2002:str", "", style='"')
    return dumper.represent_str(value)


_Dumper.add_representer(type(None), _represent_none)
_Dumper.add_representer(str, _represent_str)


def dump_yaml(value: Any) -> str:
    """``value`` as block YAML laid out like yaml-cpp's ``YAML::Dump`` (no trailing newline)."""
    text = yaml.dump(value, Dumper=_Dumper, sort_keys=False, default_flow_style=False, allow_unicode=True,
                     width=1 << 30)
    return text.rstrip("\n")


# --- QoS profiles, rendered the way rosbag2 (Jazzy, metadata version 9) renders them ---------

HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
LIVELINESS = {0: "system_default", 1: "automatic", 2: "manual_by_node", 3: "manual_by_topic", 4: "unknown",
              5: "best_available"}
_POLICIES = {"history": HISTORY, "reliability": RELIABILITY, "durability": DURABILITY, "liveliness": LIVELINESS}
_QOS_KEYS = ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
             "liveliness_lease_duration", "avoid_ros_namespace_conventions")
_TIME_KEYS = ("deadline", "lifespan", "liveliness_lease_duration")


def _duration_map(value: Any) -> Dict[str, int]:
    """rclpy Duration / nanoseconds / {'sec','nsec'} -> {'sec': s, 'nsec': ns} (rmw_time_t)."""
    if isinstance(value, Mapping):
        return {"sec": int(value.get("sec", 0)), "nsec": int(value.get("nsec", 0))}
    ns = int(getattr(value, "nanoseconds", value))
    return {"sec": ns // NS_PER_S, "nsec": ns % NS_PER_S}


def _policy_name(kind: str, value: Any) -> str:
    names = _POLICIES[kind]
    if isinstance(value, str):
        v = value.strip().lower()
        if v.isdigit():
            return names.get(int(v), "unknown")
        return v
    return names.get(int(value), "unknown")


def qos_profile_dict(profile: Any) -> Dict[str, Any]:
    """One QoS profile (rclpy ``QoSProfile``, or a dict as in metadata version 8 or 9) as the
    ordered dict rosbag2 version 9 writes: policy names as strings, durations as sec/nsec."""
    get = (lambda k, d=None: profile.get(k, d)) if isinstance(profile, Mapping) \
        else (lambda k, d=None: getattr(profile, k, d))
    out: Dict[str, Any] = {}
    for key in _QOS_KEYS:
        value = get(key)
        if key in _POLICIES:
            out[key] = _policy_name(key, 0 if value is None else value)
        elif key == "depth":
            out[key] = int(value or 0)
        elif key in _TIME_KEYS:
            out[key] = _duration_map(0 if value is None else value)
        else:
            out[key] = bool(value)
    return out


def qos_profiles_yaml(profiles: Iterable[Any]) -> str:
    """The ``offered_qos_profiles`` channel-metadata string rosbag2 (Jazzy) writes for a topic:
    ``YAML::Dump`` of the list of profiles, e.g. ``- history: unknown\\n  depth: 0\\n  reliability:
    reliable\\n ... \\n  avoid_ros_namespace_conventions: false``; ``[]`` for no profiles."""
    return dump_yaml([qos_profile_dict(p) for p in profiles])


def parse_qos_yaml(text: Any) -> List[Dict[str, Any]]:
    """A channel's ``offered_qos_profiles`` (v8 integers or v9 names) -> list of v9 profile dicts.

    ``text`` is the YAML string, or the already loaded list (as found in ``metadata.yaml``)."""
    if isinstance(text, (list, tuple)):
        doc: Any = list(text)
    elif text is None or not str(text).strip():
        return []
    else:
        try:
            doc = load_yaml(str(text), "offered_qos_profiles")   # bounded (mwip_ros.yamlio)
        except YamlRefused as exc:
            raise BagError(f"offered_qos_profiles refused: {exc.problem}") from None
        except yaml.YAMLError as exc:
            raise BagError(f"offered_qos_profiles is not valid YAML: {bounded(str(exc))}") from None
    if doc is None:
        return []
    if not isinstance(doc, list) or not all(isinstance(p, Mapping) for p in doc):
        raise BagError(f"offered_qos_profiles must be a YAML list of profiles, got {shown(text)}")
    return [qos_profile_dict(p) for p in doc]


# --- metadata.yaml -----------------------------------------------------------------------------

@dataclass
class TopicInfo:
    """One entry of ``topics_with_message_count``."""

    name: str
    type: str
    offered_qos_profiles: List[Dict[str, Any]] = field(default_factory=list)
    type_description_hash: str = ""
    message_count: int = 0
    serialization_format: str = SERIALIZATION_FORMAT


@dataclass
class FileInfo:
    """One entry of ``files``: a file's message count and log-time span."""

    path: str
    message_count: int = 0
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None

    def add(self, log_time_ns: int) -> None:
        self.message_count += 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)

    @property
    def starting_time(self) -> int:
        return EMPTY_STARTING_TIME if self.start_ns is None else self.start_ns

    @property
    def duration(self) -> int:
        return 0 if self.start_ns is None else self.end_ns - self.start_ns


def bag_metadata(topics: Sequence[TopicInfo], files: Sequence[FileInfo], *, compression_format: str = "",
                 compression_mode: str = "", custom_data: Optional[Mapping[str, str]] = None,
                 ros_distro: str = ROS_DISTRO) -> Dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (metadata version 9), keys in rosbag2's order."""
    starts = [f.start_ns for f in files if f.start_ns is not None]
    ends = [f.end_ns for f in files if f.end_ns is not None]
    start = min(starts) if starts else None
    return {
        "version": METADATA_VERSION,
        "storage_identifier": STORAGE_IDENTIFIER,
        "duration": {"nanoseconds": (max(ends) - start) if start is not None else 0},
        "starting_time": {"nanoseconds_since_epoch": start if start is not None else EMPTY_STARTING_TIME},
        "message_count": sum(f.message_count for f in files),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": [qos_profile_dict(p) for p in t.offered_qos_profiles],
                    "type_description_hash": t.type_description_hash,
                },
                "message_count": t.message_count,
            }
            for t in topics
        ],
        "compression_format": compression_format,
        "compression_mode": compression_mode,
        "relative_file_paths": [f.path for f in files],
        "files": [
            {
                "path": f.path,
                "starting_time": {"nanoseconds_since_epoch": f.starting_time},
                "duration": {"nanoseconds": f.duration},
                "message_count": f.message_count,
            }
            for f in files
        ],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": ros_distro,
    }


def metadata_yaml_text(info: Mapping[str, Any]) -> str:
    """The text of ``metadata.yaml`` for a ``bag_metadata()`` mapping."""
    return dump_yaml({"rosbag2_bagfile_information": dict(info)}) + "\n"


def write_metadata_yaml(bag_dir: Union[str, Path], info: Mapping[str, Any]) -> Path:
    """Write ``<bag_dir>/metadata.yaml`` atomically (temporary file, fsync, rename)."""
    bag_dir = Path(bag_dir)
    final = bag_dir / "metadata.yaml"
    tmp = bag_dir / f".metadata.yaml.{os.getpid()}.tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(metadata_yaml_text(info))
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, final)
    return final
