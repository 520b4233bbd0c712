"""The message layer's errors: bytes that are not a message, and messages that must not be used."""
from __future__ import annotations

__all__ = ["MessageError", "CdrError", "BadMessage"]


class MessageError(ValueError):
    """Base of every message-layer error; the text says what is wrong."""


class CdrError(MessageError):
    """Bytes that are not the expected CDR message (short, cut off, wrong encapsulation, ...)."""


class BadMessage(MessageError):
    """A well-formed message whose content must not be used (non-finite, wrong joints, ...)."""
