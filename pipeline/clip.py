"""``apf-mpc clip <experiment>/<member> [--outputs DIR] [--out FILE.gif] [--fps 10]
[--stride 1]`` (``make clip MEMBER=family/113``): one member of the outputs as an animated GIF
for slides, every method at once in its report colour (:mod:`pipeline.reporting.clip`). The
scenario explorer links to the file this command writes by default
(``reports/latest/clips/<experiment>_<member>.gif``)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from pipeline.commands import CommandError, run_command

__all__ = ["main"]

#: What --fps and --stride may be.
FPS_RANGE = (1, 60)
STRIDE_RANGE = (1, 100)


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.clip``: ``apf-mpc clip``."""
    from pipeline.cli import alias

    return alias("clip", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc clip``'s arguments."""
    parser.add_argument("member", help="the member, <experiment>/<index> as the explorer "
                                       "names it (e.g. family/113, paper/0)")
    parser.add_argument("--outputs", type=Path, default=Path("outputs"),
                        help="the outputs root (default outputs)")
    parser.add_argument("--out", type=Path, default=None,
                        help="the GIF to write (default reports/latest/clips/"
                             "<experiment>_<index>.gif, where the explorer links)")
    parser.add_argument("--fps", type=int, default=10,
                        help=f"frames per second ({FPS_RANGE[0]}-{FPS_RANGE[1]}, default 10: "
                             "real time at the paper's 0.1 s sample time)")
    parser.add_argument("--stride", type=int, default=1,
                        help=f"draw every n-th step ({STRIDE_RANGE[0]}-{STRIDE_RANGE[1]}, "
                             "default 1)")


def run(args: argparse.Namespace) -> int:
    """The clip ``args`` ask for, through the command layer."""
    return run_command(lambda: _clip(args))


def _clip(args) -> int:
    from pipeline.reporting.clip import CLIPS_FOLDER, clip_name, write_clip
    from pipeline.reporting.explorer import experiment_members, member_data

    for key, value, (low, high) in (("--fps", args.fps, FPS_RANGE),
                                    ("--stride", args.stride, STRIDE_RANGE)):
        if not low <= value <= high:
            raise CommandError(f"{key}: {value} is not allowed; allowed: an integer in "
                               f"[{low}, {high}]")
    match = re.fullmatch(r"([A-Za-z0-9_.-]+)/([0-9]+)", args.member)
    if match is None:
        raise CommandError(f"member: {args.member!r} is not allowed; allowed: "
                           "<experiment>/<index>, e.g. family/113")
    experiment, member = match[1], int(match[2])
    known = experiment_members(args.outputs)
    if experiment not in known:
        raise CommandError(f"member: no experiment {experiment!r} under {args.outputs}; "
                           f"allowed: {', '.join(known) or 'none (make reproduce writes them)'}")
    if member not in known[experiment]:
        first, last = known[experiment][0], known[experiment][-1]
        allowed = f"{first}-{last}" if last != first else str(first)
        raise CommandError(f"member: {experiment} has no member {member}; allowed: {allowed}")
    payload = member_data(args.outputs, experiment, member)
    if payload is None:
        raise CommandError(f"member: {args.member}: no run of it could be read under "
                           f"{args.outputs}")
    out = args.out or Path("reports/latest") / CLIPS_FOLDER / clip_name(experiment, member)
    if out.suffix.lower() != ".gif" or out.is_dir():
        raise CommandError(f"--out: {str(out)!r} is not allowed; allowed: a file name ending "
                           "in .gif")
    clip = write_clip(payload, out, fps=args.fps, stride=args.stride)
    print(f"clip: {clip.path} ({clip.frames} frames, {clip.duration_s:.1f} s at "
          f"{args.fps} fps; {', '.join(m['name'] for m in payload['methods'])})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
