"""Methods on a CommonRoad scenario file: ``apf-mpc commonroad FILE.xml [--methods
improved,baseline] [--out outputs/commonroad]`` (``make commonroad``; docs/commonroad.md).

Each method is one ``apf-mpc run scenario=commonroad`` on the file, written into
``<out>/<file's stem>/<method>`` and judged by our check and by CommonRoad's drivability
checker (:mod:`pipeline.studies.commonroad`); the report shows them, never judges them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.commands import output_folder

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m pipeline.commonroad``: ``apf-mpc commonroad``."""
    from pipeline.cli import alias

    return alias("commonroad", argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``apf-mpc commonroad``'s arguments."""
    parser.add_argument("scenario", type=Path, help="a CommonRoad scenario file (.xml)")
    parser.add_argument("--methods", default="improved,baseline",
                        help="comma-separated methods, one run each (default improved,baseline)")
    parser.add_argument("--out", type=output_folder, default=Path("outputs/commonroad"),
                        help="the runs go to OUT/<file's stem>/<method> (default "
                             "outputs/commonroad)")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides for every run")


def run(args: argparse.Namespace) -> int:
    """One run per method, stopping at the first that fails (its exit code)."""
    from pipeline import run as run_module

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if not methods:
        print(f"error: --methods {args.methods!r} is invalid; allowed: comma-separated method "
              "names, e.g. improved,baseline", file=sys.stderr)
        return 2
    for method in methods:
        code = run_module.command(
            ["experiment=commonroad", f"scenario.commonroad.path={args.scenario}",
             f"method={method}", f"hydra.run.dir={args.out / args.scenario.stem / method}",
             *road_overrides(method, args.scenario, args.overrides), *args.overrides], "apf-mpc commonroad")
        if code:
            return code
    return 0


#: The key by which a user turns the road's braking off as a whole
#: (``planner.velocity_planning=false`` is the paper's constant speed); any other braking key
#: the user sets replaces the road's value of that key alone.
BRAKING_SWITCH = "planner.velocity_planning"
#: A braking key left to the user where they set the key it rests on: the floor of 0 needs the
#: kinematic hand-over below ``vehicle.kinematic_below_mps`` (the lateral model's 1/v terms
#: forbid a stop without it).
RESTS_ON = {"planner.speed_floor_mps": "vehicle.kinematic_below_mps"}


def _given(key: str, overrides: list[str]) -> bool:
    return any(o.startswith(f"{key}=") for o in overrides)


def road_overrides(method: str, scenario: Path, overrides: list[str]) -> list[str]:
    """The road's settings for ``method``, each unless the user set it, where its controller
    can take them (the lateral MPC: not another kind, the nonlinear MPC or a plug-in):
    ``controller.road_edge_weight`` (in the path frame) and
    ``controller.steering_friction_share`` (:data:`~pipeline.studies.euro_ncap.ROAD`), and
    braking from every obstacle's prediction (:data:`~pipeline.studies.euro_ncap.BRAKING`,
    the Euro NCAP braking track's) for the project's own planner: none when the user sets
    :data:`BRAKING_SWITCH`, and none of :data:`RESTS_ON`'s keys whose base the user set."""
    # the road's settings as the Euro NCAP tests take them (one statement of their values)
    from pipeline.studies.euro_ncap import BRAKING, ROAD

    keys = dict(item.split("=", 1) for item in ROAD)
    braking = {} if _given(BRAKING_SWITCH, overrides) else \
        dict(item.split("=", 1) for item in BRAKING)
    wanted = {key: value for key, value in {**keys, **braking}.items()
              if not _given(key, overrides)
              and not (key in RESTS_ON and _given(RESTS_ON[key], overrides))}
    if not wanted:
        return []
    from pipeline import api

    try:
        cfg = api.compose(["experiment=commonroad", f"method={method}",
                           f"scenario.commonroad.path={scenario}",
                           *[o for o in overrides if not o.startswith("hydra")]])
    except Exception:
        return []      # wrong, in its one line)
    ctrl = cfg.controller
    lateral_mpc = getattr(ctrl, "kind", "") == "mpc" and not ctrl._target_ \
        and getattr(ctrl, "backend", "") != "nmpc"
    takes = {"controller.road_edge_weight": lateral_mpc and getattr(ctrl, "frame", "") == "path",
             "controller.steering_friction_share": lateral_mpc}
    brakes = lateral_mpc and not getattr(cfg.planner, "_target_", None)
    return [f"{key}={value}" for key, value in wanted.items() if takes.get(key, brakes)]


if __name__ == "__main__":
    sys.exit(main())
