"""rosbag2-compatible MCAP bags, without rclpy.

==================  ================================================================
:mod:`.writer`      ``BagWriter``: record a bag (MCAP file + ``metadata.yaml``)
:mod:`.reader`      the one reader: files, metadata, raw messages in log-time order
:mod:`.metadata`    QoS profile YAML, ``metadata.yaml`` contents, the YAML dumper
:mod:`.schema`      message definitions and type hashes for MCAP schemas
:mod:`.scan`        the record walk of a damaged MCAP file (for repair)
:mod:`.repair`      ``repair``: make a bag cut short whole again
:mod:`.errors`      ``BagError``
==================  ================================================================
"""
from .errors import BagError
from .metadata import REPAIRED_KEY, qos_profiles_yaml
from .reader import (check, damaged_chunks, mcap_files, raw_messages, read_metadata, topic_counts, topic_qos,
                     topic_types)
from .repair import RepairResult, repair
from .schema import message_definition, type_hash
from .writer import BagWriter

__all__ = ["REPAIRED_KEY", "BagError", "BagWriter", "RepairResult", "check", "damaged_chunks", "mcap_files",
           "message_definition", "qos_profiles_yaml", "raw_messages", "read_metadata", "repair", "topic_counts",
           "topic_qos", "topic_types", "type_hash"]
