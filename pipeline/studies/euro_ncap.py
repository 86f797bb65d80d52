"""The Euro NCAP crossings (``make euro-ncap``, ``apf-mpc euro-ncap``): the methods on the
seeded family of Euro NCAP's AEB/LSS VRU tests (:mod:`pipeline.loop.euro_ncap`), on both
tracks, judged by the protocol's own outcome and by the claims.

Each method runs the same family (resumable, like every family) into
``<out>/<track>/<method>``: on the lateral track the paper's two methods and the peers that
need no speed setting of their own (``mpc_dcbf``, ``cbf_filter``); on the lateral track with
braking (``lateral_braking``, a reading: velocity planning to a stop, :data:`BRAKING`) the
paper's two methods; on the Appendix-A
kinematic track the same with the kinematic MPC (references spaced at the test speed,
``controller.reference_alignment=path_speed``). Velocity obstacles and the dynamic window
are left out: their candidate speed and their speed limit are set for the paper's 3 m/s,
and the tests drive 10-60 km/h (a reading, registered). The ego is the protocol's car: a
rectangle covered by discs (:func:`~pipeline.loop.euro_ncap.ego_vehicle`), with obstacle
slots for every disc of a test (``controller.max_obstacles``).

``euro_ncap.csv`` has one row per test and method: the case, the test speed, the impact
position, the protocol's outcome (:func:`~pipeline.loop.euro_ncap.protocol_outcome`: the road
user hit or not and the ego's speed at the impact), contact with a parked car and the steps
off the road; ``summary.json`` per track, method and case the tests avoided and the impact
speeds, and per track the claims ledger of improved against the baseline and each peer (C0-C5,
on each run's own window, as among recorded pedestrians).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.store.member_cache import MemberCounts
from pipeline.studies.results.euro_ncap import EuroNcapResult

logger = logging.getLogger(__name__)

#: The road's edges in the lateral MPC on a road (controller.road_edge_weight): the collision
#: rows' weight, for every method whose MPC can take them (the lateral MPC in the path frame,
#: no controller of one's own); the peers' controllers and the kinematic MPC see no road.
ROAD_EDGE_WEIGHT = 1.0
#: The lateral MPC's steering bound by the tyres' friction at road speeds
#: (controller.steering_friction_share), for the same methods: without it the MPC plans
#: steering of up to 0.4 rad at 12-20 m/s, beyond what the tyres hold, and an evasive swerve
#: ends in a skid (docs/commonroad.md, "Steering within the tyres' friction").
STEERING_FRICTION_SHARE = 1.0
#: Both, as these tests and a CommonRoad road (pipeline.commonroad.road_overrides) take them.
ROAD = (f"controller.road_edge_weight={ROAD_EDGE_WEIGHT}",
        f"controller.steering_friction_share={STEERING_FRICTION_SHARE}")
#: Braking (a reading, the protocol's tests are built for it; the paper's MPC steers at a
#: constant speed): Section 3.1's velocity planning as the register reads it
#: (predicted_clearance: the fastest speed whose constant-velocity prediction of every
#: obstacle keeps the clearance along the APF's path) down to a stop, planned at 6 m/s^2 by a
#: car that brakes at up to 8 (a passenger car's full braking on dry asphalt, below the tyres'
#: mu g = 8.8; its acceleration stays at Appendix A's 3), the plant and the MPC's model
#: handing over to the kinematic single-track below 2 m/s (the road's default under
#: ``apf-mpc commonroad``: pipeline.commonroad.road_overrides).
BRAKING = ("planner.velocity_planning=true", "planner.velocity_rule=predicted_clearance",
           "planner.speed_floor_mps=0", "planner.braking_decel_mps2=6.0",
           "planner.stop_margin_m=1.0", "vehicle.kinematic_below_mps=2.0",
           "vehicle.brake_max_mps2=8.0")
#: The methods per track: (folder name, overrides). The kinematic track's improved and
#: baseline are Appendix A's kinematic MPC with each APF.
TRACKS: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "lateral": (("improved", ("method=improved", *ROAD)), ("baseline", ("method=baseline", *ROAD)),
                ("mpc_dcbf", ("method=mpc_dcbf",)), ("cbf_filter", ("method=cbf_filter",))),
    "lateral_braking": (("improved", ("method=improved", *ROAD, *BRAKING)),
                        ("baseline", ("method=baseline", *ROAD, *BRAKING))),
    "kinematic": (("improved", ("method=improved", "controller=kinematic")),
                  ("baseline", ("method=baseline", "controller=kinematic")),
                  ("mpc_dcbf", ("method=mpc_dcbf_kinematic",)),
                  ("cbf_filter", ("method=cbf_filter_kinematic",))),
}
#: What the tests need of a track beyond every method's obstacle slot per disc of a test (a
#: cyclist's cover_discs and two parked cars' twice as many, :func:`slots`): on the kinematic
#: track, references at the test speed.
TRACK_OVERRIDES: dict[str, tuple[str, ...]] = {
    "lateral": (), "lateral_braking": (),
    "kinematic": ("controller.reference_alignment=path_speed",)}


def slots(cover_discs: int) -> int:
    """Obstacle slots for every disc a test can hold: the road user's cover (a cyclist's) and
    two parked cars' (``3 cover_discs``)."""
    return 3 * int(cover_discs)


def euro_ncap(compose: Callable[[list[str]], Any], out_dir: Path, n_members: int = 110,
              tracks: tuple[str, ...] = tuple(TRACKS), log: Callable[[str], None] = logger.info,
              extra: tuple[str, ...] = ()) -> EuroNcapResult:
    """Run every method of ``tracks`` on the family; the result written into ``out_dir`` and
    returned. ``extra``: overrides for every run (e.g. ``scenario.source.params.cases=[...]``)."""
    from pipeline.loop.euro_ncap import EuroNcapSettings, ego_vehicle
    from pipeline.store.manifest import refuse_other_record
    from pipeline.studies.experiment import run_family

    out_dir = Path(out_dir)
    refuse_other_record(out_dir, ("euro_ncap",))
    # every run's configuration first: a bad value is refused before anything is written
    runs: dict[str, list[tuple[str, Any]]] = {}
    settings = EuroNcapSettings.of(dict(compose(["scenario=euro_ncap", *extra])
                                        .scenario.source.params))
    slot_count = f"controller.max_obstacles={slots(settings.cover_discs)}"
    for track in tracks:
        runs[track] = []
        for name, overrides in TRACKS[track]:
            cfg = compose([*overrides, "scenario=euro_ncap", f"scenario.family.size={n_members}",
                           slot_count, *TRACK_OVERRIDES[track], *extra])
            settings = EuroNcapSettings.of(dict(cfg.scenario.source.params))
            runs[track].append((name, dataclasses.replace(
                cfg, vehicle=ego_vehicle(cfg.vehicle, settings))))
    out_dir.mkdir(parents=True, exist_ok=True)
    counts = MemberCounts()
    rows: list[dict] = []
    ledgers: list[dict] = []
    for track, configs in runs.items():
        tables: dict[str, pd.DataFrame] = {}
        for name, cfg in configs:
            folder = out_dir / track / name
            tables[name] = run_family(cfg, folder, progress=False, counts=counts)
            rows += _outcomes(cfg, folder, track, name, settings)
            hits = sum(r["hit"] for r in rows if r["track"] == track and r["method"] == name)
            log(f"euro-ncap: {track} {name}: {hits} of {n_members} tests hit the road user")
        ledgers += _ledger(tables, configs[0][1].claims, track)
    log(f"euro-ncap: {counts.sentence()}")
    table = pd.DataFrame(rows)
    return EuroNcapResult(n_members, tuple(rows), tuple(_by_case(table)), tuple(ledgers),
                          settings.to_params() if settings is not None else {}).write(out_dir)


def _outcomes(cfg: Any, folder: Path, track: str, method: str, settings: Any) -> list[dict]:
    """The protocol's outcome of every member of the family in ``folder``."""
    from pipeline.loop.euro_ncap import CASES, encounter, protocol_outcome
    from pipeline.loop.scenario import family_members
    from pipeline.store.runs import read_member

    out = []
    for index, member in enumerate(family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)):
        params = member.source.params
        record = read_member(folder, index)
        outcome = protocol_outcome(record.trajectory, encounter(
            settings, CASES[params["case"]], float(params["ego_speed_kmh"]),
            float(params["impact_fraction"]), float(member.sample_time_s)), settings)
        out.append({"track": track, "method": method, "member": index,
                    "scenario": member.name, "case": params["case"],
                    "nominal_speed_kmh": float(params["nominal_speed_kmh"]),
                    "speed_kmh": float(params["ego_speed_kmh"]),
                    "impact_fraction": float(params["impact_fraction"]),
                    "hit": outcome.hit, "impact_speed_kmh": outcome.impact_speed_kmh,
                    "impact_time_s": outcome.impact_time_s,
                    "parked_car_contact": outcome.other_contact,
                    "steps_off_road": outcome.steps_off_road,
                    "least_gap_m": outcome.least_gap_m,
                    "termination": record.info.termination})
    return out


def _by_case(table: pd.DataFrame) -> list[dict]:
    """Per track, method and case (and ``all``): tests, tests avoided, the mean and largest
    impact speed of the hits, tests with a parked car touched, tests that left the road."""
    out: list[dict] = []
    if table.empty:
        return out
    for (track, method), part in table.groupby(["track", "method"], sort=False):
        for case, rows in [("all", part), *part.groupby("case", sort=False)]:
            hits = rows[rows["hit"]]
            out.append({"track": track, "method": method, "case": case,
                        "tests": int(len(rows)), "avoided": int((~rows["hit"]).sum()),
                        "avoided_share": float((~rows["hit"]).mean()),
                        "impact_speed_mean_kmh": float(hits["impact_speed_kmh"].mean())
                        if len(hits) else float("nan"),
                        "impact_speed_max_kmh": float(hits["impact_speed_kmh"].max())
                        if len(hits) else float("nan"),
                        "avoided_up_to_kmh": _avoided_up_to(rows),
                        "parked_car_contacts": int(rows["parked_car_contact"].sum()),
                        "tests_off_road": int((rows["steps_off_road"] > 0).sum())})
    return out


def _avoided_up_to(rows: pd.DataFrame) -> float:
    """The highest nominal test speed (km/h) up to which every test was avoided (NaN when the
    slowest was hit)."""
    speeds = sorted(rows["nominal_speed_kmh"].unique())
    best = float("nan")
    for speed in speeds:
        if rows[rows["nominal_speed_kmh"] == speed]["hit"].any():
            break
        best = float(speed)
    return best


def _ledger(tables: dict[str, pd.DataFrame], claims_cfg: Any, track: str) -> list[dict]:
    """The claims (C0-C5) of improved against each other method of one track (the baseline
    first, then the peers), on each run's own window (``c2_window=own``, as among recorded
    pedestrians: no shared jerk window). Each comparison is its own ledger (Holm over its
    claims), so the peers do not change the verdict against the baseline."""
    from pipeline.analysis.claims.ledger import family_ledger

    if "improved" not in tables:
        return []
    own = dataclasses.replace(claims_cfg, c2_window="own")
    out = []
    for comparison in [m for m in tables if m != "improved"]:
        ledger = family_ledger({m: tables[m] for m in ("improved", comparison)}, own, None,
                               "improved", (comparison,), sensitivity=False)
        out += [{"track": track, "claim": row.claim_id, "comparison": row.comparison,
                 "outcome": str(row.outcome), "pairs": int(row.result.n_pairs),
                 "estimate": _finite(row.result.estimate),
                 "ci_low": _finite(row.result.ci_low), "ci_high": _finite(row.result.ci_high)}
                for row in ledger]
    return out


def _finite(value: Any) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if np.isfinite(value) else None
