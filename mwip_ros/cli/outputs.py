"""The command-line tools' outputs: checked before any work, never overwritten without ``--force``.

One mechanism for every tool (``mwip_sim``, ``mwip_sweep``, ``mwip_tune``, ``mwip_report``):

* :func:`refuse_existing`: a file output (``--csv``, ``--plot``, ``--out FILE.yaml``, ``--write-params``);
* :func:`refuse_directory`: a directory output holding a known set of files (``mwip_sweep --out``,
  ``mwip_report --out``), with :func:`remove_stale` to remove, under ``--force``, the files of an earlier
  output so none of it is left beside the new one.

Each returns the reason, one line for the user, or None.  What they refuse whatever ``--force``: a
place that is not a directory (``FILE/sub``), a missing parent (a file output; a directory output is
created with its parents), an existing path that is not a regular file (``/dev/null``, a FIFO: never
removed, never written through), and a place where nothing can be created (``/proc``, a read-only or
unwritable directory): that is tried, by creating and removing a probe file, not guessed from the mode
bits (root passes every mode check, and ``/proc`` says it is writable).
"""
from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterable, List, Optional, Sequence

__all__ = ["refuse_existing", "refuse_directory", "existing_outputs", "remove_stale", "make_directory"]


def _probe(directory: Path) -> Optional[str]:
    """Why nothing can be created in the existing directory ``directory``, or None when a file can."""
    try:
        fd, name = tempfile.mkstemp(prefix=".mwip-probe-", dir=directory)
    except OSError as exc:
        return os.strerror(exc.errno) if exc.errno else str(exc)
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:
        pass
    return None


def _kind(p: Path) -> str:
    """What the existing, non-regular ``p`` is, for a message."""
    try:
        mode = p.stat().st_mode
    except OSError:
        return "a dangling link"
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISREG(mode):
        return "a file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _is_regular(p: Path) -> bool:
    try:
        return stat.S_ISREG(p.stat().st_mode)
    except OSError:
        return False


def refuse_existing(path, force: bool, option: str) -> Optional[str]:
    """Why the file ``path`` (given as ``option``, e.g. ``--out``) cannot be written, in one line for the
    user, or None when it can: a directory, something else that is not a regular file (``/dev/null``),
    a parent directory that is missing, is a file or where no file can be created (whatever ``force``),
    or a file that exists (without ``force``).

    Call it before any work, so a mistake costs nothing and a finished run is not lost at the end."""
    p = Path(path)
    parent = p.parent
    if p.is_dir():
        return f"{option} {p} is a directory; give a file name"
    try:
        exists = p.exists() or p.is_symlink()
    except OSError as exc:   # ENAMETOOLONG, ELOOP, a component that is a file (ENOTDIR)
        if exc.errno == errno.ENOTDIR:
            return f"{option} {p}: {_first_file(p)} is not a directory"
        return f"{option} {p}: {os.strerror(exc.errno) if exc.errno else exc}"
    if exists and not _is_regular(p):
        return f"{option} {p} is {_kind(p)}, not a regular file; give a file name"
    if not parent.exists():
        bad = _first_file(p)
        if bad is not None:
            return f"{option} {p}: {bad} is not a directory"
        return f"{option} {p}: the directory {parent} does not exist"
    if not parent.is_dir():
        return f"{option} {p}: {parent} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{option} {p}: the directory {parent} is not writable"
    why = _probe(parent)
    if why:
        return f"{option} {p}: cannot create a file in {parent} ({why})"
    if exists and not force:
        return f"{option} {p} exists; choose another name or add --force to overwrite it"
    return None


def _first_file(p: Path) -> Optional[Path]:
    """The first ancestor of ``p`` that exists and is not a directory (``FILE`` of ``FILE/sub/x``), or None."""
    for a in reversed(p.parents):
        if a.exists() and not a.is_dir():
            return a
    return None


def existing_outputs(directory, names: Iterable[str]) -> List[str]:
    """The ``names`` that exist in ``directory`` (as anything: a file, a directory, a link)."""
    d = Path(directory)
    out = []
    for n in names:
        q = d / n
        try:
            if q.exists() or q.is_symlink():
                out.append(n)
        except OSError:
            continue
    return out


def refuse_directory(path, names: Sequence[str], force: bool, option: str, what: str = "outputs") -> Optional[str]:
    """Why the directory output ``path`` (``option``, e.g. ``--out``) that a tool fills with ``names``
    cannot be used, in one line, or None when it can (it may not exist yet: it is created with its parents).

    Refused whatever ``force``: ``path`` is not a directory (a file, ``/dev/null``); an ancestor is a file
    (``FILE/sub``); nothing can be created in it or in its nearest existing ancestor (``/proc/x``, a
    read-only place); one of ``names`` there is not a regular file (``--force`` removes only files).
    Without ``force``: any of ``names`` exists there (``what`` names them in the message, e.g. "a report")."""
    p = Path(path)
    try:
        exists = p.exists() or p.is_symlink()
    except OSError as exc:
        return f"{option} {p}: {os.strerror(exc.errno) if exc.errno else exc}"
    if exists:
        if not p.is_dir():
            return f"{option} {p} is {_kind(p)}, not a directory"
        why = _probe(p)
        if why:
            return f"{option} {p}: cannot write into it ({why})"
        there = existing_outputs(p, names)
        if there and not force:
            return (f"{option} {p} already holds {what} ({', '.join(there)}); choose another {option} "
                    f"or add --force")
        for n in there:
            q = p / n
            if not q.is_symlink() and not _is_regular(q):
                return f"{option} {p}: {q} is {_kind(q)}; --force removes only regular files"
        return None
    bad = _first_file(p)
    if bad is not None:
        return f"{option} {p}: {bad} is not a directory"
    ancestor = next(a for a in p.parents if a.exists())
    why = _probe(ancestor)
    if why:
        return f"{option} {p}: cannot create it in {ancestor} ({why})"
    return None


def remove_stale(path, names: Sequence[str]) -> Optional[str]:
    """Remove the ``names`` in the directory ``path`` (after :func:`refuse_directory` passed them under
    ``--force``): no file of an earlier output is left beside the new one.  The reason, one line, when
    one cannot be removed; None when done."""
    p = Path(path)
    for n in existing_outputs(p, names):
        q = p / n
        if not q.is_symlink() and not _is_regular(q):
            return f"{q} is {_kind(q)}; --force removes only regular files"
        try:
            q.unlink()
        except OSError as exc:
            return f"cannot remove {q} ({os.strerror(exc.errno) if exc.errno else exc})"
    return None


def make_directory(path, option: str) -> Optional[str]:
    """Create the output directory ``path`` (and its parents); a one-line reason naming ``option`` if it cannot
    be created, else None."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"{option} {path}: cannot create it ({exc.strerror or exc})"
    return None
