"""``mwip_bag_repair``: recover the messages of a bag whose recording was cut short.

Command line::

    mwip_bag_repair BAG_DIR_OR_MCAP [--dry-run]

Prints :meth:`mwip_ros.bag.RepairResult.report`.  Exit codes: 0 repaired (or nothing to
repair), 1 nothing could be recovered, 2 usage error.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Sequence

from mwip_ros.bag import BagError, repair
from mwip_ros.cli.exits import EXIT_OK, EXIT_USAGE
from mwip_ros.yamlio import NotRegularFile

__all__ = ["EXIT_NOTHING", "EXIT_OK", "EXIT_USAGE", "main"]

EXIT_NOTHING = 1   # nothing could be recovered


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mwip_bag_repair",
        description="Recover the messages of a rosbag2 MCAP bag whose recording was cut short "
                    "(e.g. by kill -9): keeps every complete message, writes a complete MCAP file "
                    "(the original is kept as <name>.mcap.broken) and rebuilds metadata.yaml.",
        epilog="Exit codes: 0 repaired or nothing to repair, 1 nothing could be recovered, 2 usage error.")
    parser.add_argument("path", metavar="BAG_DIR_OR_MCAP", help="bag directory or .mcap file")
    parser.add_argument("--dry-run", action="store_true", help="report what would be saved; change nothing")
    return parser


def _usage_error(message: str) -> int:
    print(f"mwip_bag_repair: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = _parser().parse_args(argv)
    target = Path(args.path)
    if not target.exists():
        return _usage_error(f"no such bag directory or MCAP file: {target}")
    if target.is_file() and target.suffix != ".mcap":
        return _usage_error(f"{target} is not an .mcap file (give a bag directory or an .mcap file)")
    try:
        result = repair(target, dry_run=args.dry_run)
    except NotRegularFile as exc:   # a FIFO or a device among the files: never read (mwip_ros.yamlio)
        return _usage_error(f"{target}: {exc}")
    except (BagError, OSError) as exc:
        print(f"mwip_bag_repair: error: {exc}", file=sys.stderr)
        return EXIT_NOTHING
    print(result.report(), flush=True)
    return EXIT_OK if result.ok else EXIT_NOTHING


if __name__ == "__main__":
    sys.exit(main())
