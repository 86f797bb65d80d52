"""Is slower ever less safe? (``make speed-check``)

A vehicle that slows down should not collide more. The study runs the treatment and the
control on the scenario family under variants of speed (each a family of its own, resumable
like every family):

* ``nominal``: the paper's 3 m/s;
* ``slow``: 1.5 m/s, the same obstacles (the run twice as long, so it reaches the goal);
* ``slow_time_scaled``: 1.5 m/s with every obstacle's speed halved and its appearance delayed
  in proportion: the same encounters in space, met at half the speed;
* ``slow_time_horizon``: 1.5 m/s with the horizon in time (``controller.horizon_reach_m=null``:
  10 steps of 0.1 s preview 1.5 m, less than an obstacle's keep-out reach);
* ``velocity_planning``: the paper's V_r block on (``planner.velocity_rule=predicted_clearance``);
* ``velocity_planning_stopping_distance``: the same with the earlier stopping-distance rule.

``speed.csv`` has one row per variant and method (collisions, avoidable or not, goal reached;
a collision is unavoidable only when the run's own check says so and the other method of the
variant collided on that scenario too, :mod:`pipeline.analysis.unavoidable`);
``summary.json`` the comparisons the report draws and what explains them.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd

from pipeline.analysis.tally import Tally
from pipeline.analysis.unavoidable import label_across_methods
from pipeline.store.member_cache import MemberCounts
from pipeline.studies.results.speed import SpeedCheckResult

logger = logging.getLogger(__name__)

SLOW = ["scenario.speed_mps=1.5", "scenario.n_steps=260"]
#: The variants: overrides and what each one is.
VARIANTS: dict[str, tuple[list[str], str]] = {
    "nominal": ([], "3 m/s (the paper's speed)"),
    "slow": (SLOW, "1.5 m/s, the same obstacles"),
    "slow_time_scaled": (SLOW + ["scenario.family.appear_time_s=[4.0,8.0]",
                                 "scenario.family.crossing_speed_mps=[0.1,0.4]",
                                 "scenario.family.oncoming_speed_mps=[0.15,0.5]",
                                 "scenario.family.extra_appear_time_s=[0.0,12.0]"],
                         "1.5 m/s, every obstacle at half its speed and appearing twice as "
                         "late: the same encounters in space"),
    "slow_time_horizon": (SLOW + ["controller.horizon_reach_m=null"],
                          "1.5 m/s, the horizon in time only (10 x 0.1 s = 1.5 m ahead)"),
    "velocity_planning": (["planner.velocity_planning=true"],
                          "velocity planning on (predicted clearance, the default rule)"),
    "velocity_planning_stopping_distance": (
        ["planner.velocity_planning=true", "planner.velocity_rule=stopping_distance"],
        "velocity planning on, the earlier stopping-distance rule"),
}
METHODS = ("improved", "baseline")


def speed_check(compose, out_dir: Path, n_members: int = 200, log=logger.info,
                variants: tuple[str, ...] = tuple(VARIANTS)) -> SpeedCheckResult:
    """Run every variant's families; the result written into ``out_dir`` and returned."""
    from pipeline.store.manifest import refuse_other_record
    from pipeline.studies.experiment import run_family

    out_dir = Path(out_dir)
    refuse_other_record(out_dir, ("speed",))
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    counts = MemberCounts()
    for variant in variants:
        overrides, words = VARIANTS[variant]
        tables, speeds = {}, {}
        for method in METHODS:
            cfg = compose([f"method={method}", "scenario=family",
                           f"scenario.family.size={n_members}", *overrides])
            tables[method] = run_family(cfg, out_dir / variant / method, progress=False,
                                        counts=counts)
            speeds[method] = cfg.scenario.speed_mps
        # both methods of a variant run the same scenarios: a collision the other method
        # avoided there is not unavoidable
        for method, table in label_across_methods(tables).items():
            tally = Tally.of(table)
            rows.append({"variant": variant, "method": method, "what": words,
                         "speed_mps": speeds[method], "scenarios": tally.scenarios,
                         "collisions": tally.collisions,
                         "collisions_avoidable": tally.collisions_avoidable,
                         "collisions_unavoidable": tally.collisions_unavoidable,
                         "collisions_unavoidable_run": tally.collisions_unavoidable_run,
                         "goal_not_reached": tally.goal_not_reached,
                         "collision_rate": tally.collisions / max(tally.scenarios, 1)})
            log(f"speed-check: {variant} {method}: {tally.collisions} collisions of "
                f"{tally.scenarios}")
    log(f"speed-check: {counts.sentence()}")
    checks = _checks(pd.DataFrame(rows))
    return SpeedCheckResult(n_members, tuple(rows), tuple(checks)).write(out_dir)


def _checks(table: pd.DataFrame) -> list[dict]:
    """Per method: is velocity planning (on) no less safe than off, and 1.5 m/s than 3 m/s;
    and the controls that say why where it is not."""
    def collisions(variant: str, method: str):
        part = table[(table["variant"] == variant) & (table["method"] == method)]
        return int(part["collisions"].iloc[0]) if len(part) else None

    out = []
    for method in METHODS:
        nominal = collisions("nominal", method)
        for variant, goal in (("velocity_planning", "velocity planning on <= off"),
                              ("slow", "1.5 m/s <= 3 m/s"),
                              ("slow_time_scaled", "1.5 m/s (same encounters) <= 3 m/s")):
            value = collisions(variant, method)
            if value is None or nominal is None:
                continue
            out.append({"method": method, "check": goal, "variant": variant,
                        "collisions": value, "nominal": nominal, "holds": value <= nominal})
    return out
