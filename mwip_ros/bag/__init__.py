"""rosbag2-compatible MCAP bags: writing (:mod:`.writer`), reading (:mod:`.reader`),
repairing a recording cut short (:mod:`.repair`) and message definitions (:mod:`.schema`)."""
from .schema import BagError, message_definition, type_hash

__all__ = ["BagError", "message_definition", "type_hash"]
