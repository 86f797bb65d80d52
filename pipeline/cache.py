"""``apf-mpc cache size|clean [--root DIR]`` (``make cache-size``,
``make clean-cache``): what the member cache holds, or empty it
(:mod:`pipeline.store.member_cache`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import CommandError, run_command
from pipeline.store.member_cache import ENV, MemberCache

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.cache``: ``apf-mpc cache``."""
    from pipeline.cli import alias

    return alias("cache", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc cache``'s arguments."""
    parser.add_argument("action", choices=("size", "clean"),
                        help="size: entries, files and bytes; clean: remove every entry")
    parser.add_argument("--root", type=Path, default=None,
                        help=f"the cache's folder (default: ${ENV}, else outputs/member_cache)")


def run(args: argparse.Namespace) -> int:
    """The action ``args`` ask for, through the command layer."""
    return run_command(lambda: _act(args), kept="the cache as it was")


def _act(args) -> int:
    if args.root is not None:
        cache: MemberCache | None = MemberCache(args.root.resolve())
    else:
        cache = MemberCache.from_env(default=Path("outputs/member_cache"))
    if cache is None:
        raise CommandError(f"{ENV} turns the member cache off; name its folder with --root")
    if cache.root.exists() and not cache.root.is_dir():
        raise CommandError(f"--root: {cache.root} is not a folder")
    if args.action == "size":
        print(cache.size().sentence(cache.root))
    else:
        removed = cache.clean()
        print(f"removed {removed.entries} members ({removed.bytes / 1e6:.1f} MB) from "
              f"{cache.root}; run folders keep their own copies")
    return 0


if __name__ == "__main__":
    sys.exit(main())
