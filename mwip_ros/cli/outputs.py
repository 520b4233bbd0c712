"""The command-line tools' outputs: checked before any work, never overwritten without ``--force``."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

__all__ = ["refuse_existing"]


def refuse_existing(path, force: bool, option: str) -> Optional[str]:
    """Why the file ``path`` (given as ``option``, e.g. ``--out``) cannot be written, in one line for the
    user, or None when it can: a directory, a parent directory that is missing, is a file or is not
    writable (whatever ``force``), or a file that exists (without ``force``).

    Call it before any work, so a mistake costs nothing and a finished run is not lost at the end."""
    p = Path(path)
    parent = p.parent
    if p.is_dir():
        return f"{option} {p} is a directory; give a file name"
    if not parent.exists():
        return f"{option} {p}: the directory {parent} does not exist"
    if not parent.is_dir():
        return f"{option} {p}: {parent} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{option} {p}: the directory {parent} is not writable"
    if (p.exists() or p.is_symlink()) and not force:
        return f"{option} {p} exists; choose another name or add --force to overwrite it"
    return None
