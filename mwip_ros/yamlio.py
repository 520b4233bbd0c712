"""The one YAML reader of mwip_ros: every YAML the project reads (parameter files, ``-p`` values, sweep and
tune specs, a bag's ``metadata.yaml`` and its channels' QoS strings) goes through :func:`load_yaml`; and the one way a
file is opened for reading (:func:`open_regular`, :func:`read_bytes`): YAML, a policy file, a CSV, a bag.

Every file is opened without blocking (``O_NONBLOCK``: a FIFO with no writer does not hold the caller) and read only
when it is a regular file: a FIFO, a device (``/dev/zero``, ``/dev/urandom``), a socket or a directory is refused
(:class:`NotRegularFile`, an ``OSError``: one line naming the file and what it is) before a byte is read.

It reads ROS 2's numbers (``1e-1`` is a double, as rcl reads it) and bounds what a document may cost:

* a file is at most :data:`MAX_BYTES` (4 MiB): its size is checked (``stat``) before it is read, and at
  most ``MAX_BYTES + 1`` bytes are ever read (a file that grows meanwhile is refused too);
* no aliases (``*name``, and so no ``<<:`` merge keys): rcl's own parameter parser refuses them ("Will not
  support aliasing"), no file of the project needs them, and they are what turns a few hundred bytes into
  gigabytes (a "billion laughs" document);
* at most :data:`MAX_NODES` nodes (scalars, sequences, mappings) and :data:`MAX_DEPTH` levels of nesting.

A document beyond a bound is refused with :class:`YamlRefused`, a ``yaml.YAMLError`` whose ``problem``
is one line; callers report it as they report any YAML error (``ParamError``, ``SpecError``,
``BagError``: one line, exit 2).  The checks run on libyaml's event stream first (fast: a refused
document costs well under a second), and again in the composer that builds the document, so they hold
even where libyaml is missing.  :func:`shown` bounds a value's ``repr`` for an error message.
"""
from __future__ import annotations

import os
import re
import reprlib
import stat
from pathlib import Path
from typing import Any, BinaryIO, Optional, Union

import yaml
from yaml.events import AliasEvent, CollectionEndEvent, CollectionStartEvent, NodeEvent

__all__ = ["MAX_BYTES", "MAX_NODES", "MAX_DEPTH", "MAX_SHOWN", "RosYamlLoader", "YamlRefused", "NotRegularFile",
           "FileTooLarge", "load_yaml", "read_text", "read_bytes", "open_regular", "regular_size", "shown"]

MAX_BYTES = 4 * 1024 * 1024   # a YAML file or text: 4 MiB (the project's own files are a few KB)
MAX_NODES = 200_000           # nodes of one document: PyYAML builds ~0.8 KB of objects per node while loading
MAX_DEPTH = 64                # nesting levels (a parameter file needs < 10; deeper would exhaust the stack)
MAX_SHOWN = 200               # characters of a value shown in an error message


class YamlRefused(yaml.YAMLError):
    """A YAML document (or file) beyond one of the bounds; ``problem`` says which, in one line."""

    def __init__(self, problem: str, mark=None):
        super().__init__(problem)
        self.problem = problem
        self.problem_mark = mark

    def __str__(self) -> str:
        return self.problem


class NotRegularFile(OSError):
    """A file that is not a regular file (a FIFO, a device, a socket, a directory): never read.  Its text says
    what the file is and not its name: the caller names it ("cannot read PATH: ...")."""


class FileTooLarge(OSError):
    """A regular file larger than what its reader takes: never read past the bound."""


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def regular_size(path: Union[str, Path], what: str = "file") -> int:
    """The size of the regular file ``path`` (``stat``: nothing is opened); :class:`NotRegularFile` for anything
    else, ``OSError`` as ``stat`` raises it (a missing file)."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise NotRegularFile(f"the {what} is {_kind(st.st_mode)}, not a regular file: not read")
    return st.st_size


def open_regular(path: Union[str, Path], what: str = "file") -> BinaryIO:
    """``path`` opened for reading in binary if it is a regular file (opened with ``O_NONBLOCK``, so that opening a
    FIFO does not wait for a writer, then checked with ``fstat``: the file that was opened is the one judged);
    :class:`NotRegularFile` for anything else, ``OSError`` as ``open`` raises it."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFile(f"the {what} is {_kind(mode)}, not a regular file: not read")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: Union[str, Path], limit: int, what: str = "file") -> bytes:
    """The bytes of the regular file ``path`` (:func:`open_regular`), at most ``limit``: :class:`FileTooLarge`
    (naming the file, its size and the bound) above it, checked before it is read and again by reading at most
    ``limit + 1`` bytes (a file that grows meanwhile)."""
    with open_regular(path, what) as f:
        size = os.fstat(f.fileno()).st_size
        if size > limit:
            raise FileTooLarge(f"the {what} is {_mib(size)}; at most {_mib(limit)} is read")
        data = f.read(limit + 1)
    if len(data) > limit:
        raise FileTooLarge(f"the {what} is more than {_mib(limit)}; at most {_mib(limit)} is read")
    return data


def _mib(n: int) -> str:
    return f"{n / 2 ** 20:.1f} MiB" if n >= 2 ** 20 else f"{n:,} bytes"


class _Guard:
    """Counts nodes and depth over one document's events; refuses an alias."""

    def __init__(self):
        self.nodes, self.depth = 0, 0

    def event(self, ev) -> None:
        if isinstance(ev, AliasEvent):
            raise YamlRefused(f"YAML aliases (*{ev.anchor[:40]}) are not supported (rcl refuses "
                              f"them too); write the value out", ev.start_mark)
        if isinstance(ev, NodeEvent):   # a scalar or the start of a sequence or a mapping
            self.nodes += 1
            if self.nodes > MAX_NODES:
                raise YamlRefused(f"more than {MAX_NODES:,} YAML nodes (values, lists, mappings)", ev.start_mark)
            if isinstance(ev, CollectionStartEvent):
                self.depth += 1
                if self.depth > MAX_DEPTH:
                    raise YamlRefused(f"nested deeper than {MAX_DEPTH} levels", ev.start_mark)
        elif isinstance(ev, CollectionEndEvent):
            self.depth -= 1


class RosYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader, reading numbers as ROS 2 does: ``1e-1``, ``1E3`` and ``2.5e3`` are doubles (YAML 1.1,
    and so PyYAML, wants a dot and a signed exponent); ``200`` stays an integer.  It refuses aliases and
    counts nodes and depth (:class:`_Guard`) as it composes."""

    def __init__(self, stream):
        super().__init__(stream)
        self._guard = _Guard()

    def compose_node(self, parent, index):
        ev = self.peek_event()
        self._guard.event(ev)
        return super().compose_node(parent, index)

    def compose_sequence_node(self, anchor):
        node = super().compose_sequence_node(anchor)
        self._guard.depth -= 1
        return node

    def compose_mapping_node(self, anchor):
        node = super().compose_mapping_node(anchor)
        self._guard.depth -= 1
        return node


yaml.add_implicit_resolver("tag:yaml.org,2002:float",
                           re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$"),
                           list("-+0123456789."), Loader=RosYamlLoader)


def read_text(path: Union[str, Path], what: str = "YAML file") -> str:
    """The text of ``path`` (a regular file: :func:`open_regular`), refused (:class:`YamlRefused`) above
    :data:`MAX_BYTES` before it is read; reads at most ``MAX_BYTES + 1`` bytes.  ``OSError``
    (:class:`NotRegularFile` among them) / ``UnicodeDecodeError`` as ``open`` and ``decode`` raise them."""
    with open_regular(path, what) as f:
        size = os.fstat(f.fileno()).st_size
        if size > MAX_BYTES:
            raise YamlRefused(f"the {what} is {_mib(size)}; at most {_mib(MAX_BYTES)} is read")
        data = f.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:   # it grew since the stat (or is a device that streams)
        raise YamlRefused(f"the {what} is more than {_mib(MAX_BYTES)}; at most {_mib(MAX_BYTES)} is read")
    return data.decode("utf-8")


def _prescan(text: str) -> None:
    """The bounds on libyaml's event stream (C, fast), before anything is built.  A document libyaml cannot
    parse is left to the composer (its error is the one reported; the composer checks the bounds again)."""
    loader_cls = getattr(yaml, "CSafeLoader", None)
    if loader_cls is None:
        return
    guard = _Guard()
    loader = loader_cls(text)
    try:
        while True:
            ev = loader.get_event()
            if ev is None:
                return
            if isinstance(ev, yaml.DocumentEndEvent):
                guard.nodes = guard.depth = 0
                continue
            guard.event(ev)
    except YamlRefused:
        raise
    except yaml.YAMLError:
        return
    finally:
        loader.dispose()


def load_yaml(source: Union[str, Path], what: Optional[str] = None) -> Any:
    """The YAML document of ``source``: a ``Path`` (a file, read with :func:`read_text`) or a ``str`` (its
    text: a ``-p name:=value`` value, a bag channel's QoS string), with ROS 2's numbers and the bounds of
    this module.  ``what`` names it in a size refusal ("parameter file", "sweep spec", ...); the caller adds
    the file's name.

    Raises ``yaml.YAMLError`` (:class:`YamlRefused` beyond a bound: one line), and for a file ``OSError`` /
    ``UnicodeDecodeError``."""
    if isinstance(source, Path):
        text = read_text(source, what or "YAML file")
    else:
        text = source
        if len(text) > MAX_BYTES:
            raise YamlRefused(f"the {what or 'YAML text'} is {_mib(len(text))}; at most {_mib(MAX_BYTES)} is read")
    _prescan(text)
    loader = RosYamlLoader(text)
    try:
        return _load(loader)
    finally:
        loader.dispose()


def _load(loader: RosYamlLoader) -> Any:
    try:
        return loader.get_single_data()
    except RecursionError:
        raise YamlRefused("nested too deeply") from None
    except ValueError as exc:   # e.g. an integer of more than 4,300 digits (Python's own limit)
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "integer string conversion" in text:
            text = "an integer of more than 4,300 digits"
        raise YamlRefused(text[:MAX_SHOWN]) from None


def shown(value: Any, limit: int = MAX_SHOWN) -> str:
    """``repr(value)`` when it is at most ``limit`` characters, else an abridged one (reprlib) cut to ``limit``."""
    text = repr(value)
    if len(text) <= limit:
        return text
    r = reprlib.Repr()
    r.maxstring, r.maxother, r.maxlist, r.maxtuple, r.maxdict, r.maxlevel = limit // 2, limit // 2, 8, 8, 8, 3
    text = r.repr(value)
    if len(text) > limit:
        text = text[:limit - 20] + " ... " + text[-15:]
    return text
