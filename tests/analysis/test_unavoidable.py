"""The "unavoidable" label: the per-run oracle (:func:`collision_is_avoidable`: constant and
two-phase manoeuvres within the track's actuators) and the published label across every method
that ran the same scenario (:mod:`pipeline.analysis.unavoidable`, the report's inputs).

Oracles: an independent integration of the kinematic bicycle (SciPy's ``solve_ivp``, the
rate-limited steering in closed form) for the planted geometry, closed-form kinematics for the
acceleration case, hand-counted planted tables, and the raw ``family_metrics.csv`` of a
``make reproduce`` outputs folder read with pandas alone.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from pipeline.analysis.claims.ledger import outcome_counts
from pipeline.analysis.metrics.context import trajectory_context
from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.analysis.metrics.signals import TrajectoryContext
from pipeline.analysis.tally import Tally
from pipeline.analysis.unavoidable import (
    AVOIDED_BY,
    LABEL,
    RUN_LABEL,
    collision_rows,
    label_across_methods,
)
from pipeline.config import MetricsConfig
from pipeline.errors import ConfigError
from pipeline.reporting.inputs import FamilyInputs, label_collisions

OUTPUTS = Path(__file__).resolve().parents[2] / "outputs"


def trajectory(t: np.ndarray, x: np.ndarray, v: np.ndarray,
               obstacles: list[tuple[float, float, float, float, float]]) -> pd.DataFrame:
    """A run along the x axis (heading 0, no steering) with the simulator's columns; each
    obstacle ``(x, y, radius, vx, appear_s)`` moves along x at ``vx``, visible from
    ``appear_s`` on."""
    n = len(t)
    columns = {"time_s": t, "X_m": x, "Y_m": np.zeros(n), "psi_rad": np.zeros(n),
               "vx_mps": v, "vy_mps": np.zeros(n), "r_rad_s": np.zeros(n),
               "delta_rad": np.zeros(n)}
    for j, (ox, oy, radius, ovx, appear) in enumerate(obstacles):
        columns |= {f"obs{j}_x_m": ox + ovx * t, f"obs{j}_y_m": np.full(n, oy),
                    f"obs{j}_radius_m": np.full(n, radius),
                    f"obs{j}_visible": t >= appear - 1e-9}
    return pd.DataFrame(columns)


def avoidable(frame: pd.DataFrame, context: TrajectoryContext, **metrics) -> bool | None:
    return compute_metrics(frame, context, MetricsConfig(**metrics)).to_json()[
        "collision_avoidable"]


# --- the per-run oracle ------------------------------------------------------------------------

#: A corridor: at 5 m/s an obstacle appears 6 m ahead (x = 11, on the line) at t = 1 s, and
#: walls of obstacles line the road from x = 12 on at y = +-4.2 (radius 0.5, vehicle 1 m).
#: Braking is off (1e-6 m/s^2): only steering can help.
SPEED, APPEAR_S = 5.0, 1.0
CORRIDOR = [(11.0, 0.0, 0.5, 0.0, APPEAR_S)] + [(12.0 + k, side * 4.2, 0.5, 0.0, APPEAR_S)
                                               for k in range(30) for side in (1, -1)]
STEERING_ONLY = TrajectoryContext((0.0, 0.0), (60.0, 0.0), 1.0, braking_mps2=1e-6)


def corridor_clearance(phases: list[tuple[float, float]], end_s: float) -> float:
    """The smallest clearance to the corridor's obstacles of the exact kinematic bicycle (L =
    2.5 m, 5 m/s) from the appearance until ``end_s``, steering toward each phase's target
    ``(start_s, target_rad)`` at 1 rad/s (closed form), integrated by ``solve_ivp``."""
    def delta_at(time: float) -> float:
        delta = 0.0
        ends = [start for start, _ in phases[1:]] + [math.inf]
        for (start, target), stop in zip(phases, ends, strict=True):
            if time <= start:
                break
            held = min(time, stop) - start
            delta += float(np.clip(target - delta, -held, held))
        return delta

    def rates(time: float, state: np.ndarray) -> list[float]:
        return [SPEED * math.cos(state[2]), SPEED * math.sin(state[2]),
                SPEED * math.tan(delta_at(time)) / 2.5]

    solution = solve_ivp(rates, (APPEAR_S, end_s), [SPEED * APPEAR_S, 0.0, 0.0], max_step=0.005,
                         rtol=1e-9, atol=1e-9, dense_output=True)
    x, y, _ = solution.sol(np.linspace(APPEAR_S, end_s, 4000))
    return min(float(np.min(np.hypot(x - ox, y - oy))) - radius - 1.0
               for ox, oy, radius, _, _ in CORRIDOR)


def test_two_phase_manoeuvres_find_the_gap_that_constant_steering_misses():
    """Swerve and straighten out: every constant steering target (the earlier oracle) ends in
    the obstacle or a wall, a swerve left until t = 1.6 s and right after it clears all; the
    switch search (metrics.attribution_switch_samples) decides the label."""
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    frame = trajectory(t, SPEED * t, np.full(t.size, SPEED), CORRIDOR)
    # straight on, the vehicle touches the obstacle at x = 11 - 1.5 (t = 1.9 s); the check runs
    # 2 s beyond it
    end = (11.0 - 1.5) / SPEED + MetricsConfig().attribution_extra_s
    for target in np.linspace(-0.4, 0.4, 9):
        assert corridor_clearance([(APPEAR_S, target)], end) < -1.0
    assert corridor_clearance([(APPEAR_S, 0.4), (1.6, -0.4)], end) > 0.1
    assert avoidable(frame, STEERING_ONLY, attribution_switch_samples=0) is False
    assert avoidable(frame, STEERING_ONLY) is True


def test_speeding_up_counts_where_the_track_commands_the_acceleration():
    """A vehicle at rest (the Appendix-A track starts so) and an obstacle closing from behind at
    1 m/s: holding still or braking is hit at t = 2.5 s, steering at rest moves nothing, and
    at 3 m/s^2 the vehicle stays ahead (1.5 t^2 > t - 2.5 for every t)."""
    t = np.round(np.arange(0.0, 6.0 + 1e-9, 0.1), 10)
    frame = trajectory(t, np.zeros(t.size), np.zeros(t.size), [(-4.0, 0.0, 0.5, 1.0, 0.0)])
    at_rest = compute_metrics(frame, STEERING_ONLY, MetricsConfig()).to_json()
    assert at_rest["collision"]
    assert all(1.5 * s**2 > s - 2.5 for s in np.linspace(0.0, 10.0, 1001))
    lateral = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)  # speed: the planner's
    kinematic = dataclasses.replace(lateral, steering_rate_max_rad_s=math.inf, accel_mps2=3.0)
    assert avoidable(frame, lateral) is False
    assert avoidable(frame, kinematic) is True



def _planted_cases() -> list[tuple[pd.DataFrame, TrajectoryContext, dict, bool]]:
    """The planted collisions above with their answers: (table, context, metrics, avoidable)."""
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    corridor = trajectory(t, SPEED * t, np.full(t.size, SPEED), CORRIDOR)
    rest_t = np.round(np.arange(0.0, 6.0 + 1e-9, 0.1), 10)
    at_rest = trajectory(rest_t, np.zeros(rest_t.size), np.zeros(rest_t.size),
                         [(-4.0, 0.0, 0.5, 1.0, 0.0)])
    lateral = TrajectoryContext((0.0, 0.0), (30.0, 0.0), 1.0)
    kinematic = dataclasses.replace(lateral, steering_rate_max_rad_s=math.inf, accel_mps2=3.0)
    return [(corridor, STEERING_ONLY, {"attribution_switch_samples": 0}, False),
            (corridor, STEERING_ONLY, {}, True),
            (at_rest, lateral, {}, False),
            (at_rest, kinematic, {}, True)]


@pytest.mark.parametrize("case", range(4))
def test_the_compiled_search_gives_the_vectorised_answer(monkeypatch, case):
    """The oracle's search manoeuvre by manoeuvre, compiled (what a family's workers run, with
    numba loaded), answers as the vectorised search on each planted collision; the compiled
    kernel is the one called when it is chosen."""
    from pipeline.analysis.metrics import geometry
    from pipeline.analysis.metrics.compiled import manoeuvre_survives_kernel

    frame, context, metrics, expected = _planted_cases()[case]
    calls = []

    def counted(*args):
        calls.append(args)
        return manoeuvre_survives_kernel(*args)

    monkeypatch.setattr(geometry, "_compiled_reach", lambda: None)
    assert avoidable(frame, context, **metrics) is expected
    monkeypatch.setattr(geometry, "_compiled_reach", lambda: counted)
    assert avoidable(frame, context, **metrics) is expected
    assert len(calls) == 1
    # the statement itself in CPython (slow: only the few constant manoeuvres)
    if metrics.get("attribution_switch_samples") == 0:
        assert geometry.manoeuvre_survives(*calls[0]) is expected



def test_each_manoeuvre_survives_alike_compiled_and_vectorised(monkeypatch):
    """Manoeuvre by manoeuvre (the compiled search stops at the first that survives, so the
    final answer alone would hide a later one's error): sixty of the corridor's manoeuvres,
    drawn with a seed, each tried alone by the vectorised and by the compiled search, give the
    same answer; both answers occur among them."""
    from pipeline.analysis.metrics import geometry
    from pipeline.analysis.metrics.compiled import manoeuvre_survives_kernel

    frame, context, metrics, _ = _planted_cases()[1]
    every = {}
    full = geometry.attribution_manoeuvres

    def kept(*args):
        every.update(full(*args))
        return every

    monkeypatch.setattr(geometry, "attribution_manoeuvres", kept)
    monkeypatch.setattr(geometry, "_compiled_reach", lambda: None)
    assert avoidable(frame, context, **metrics) is True
    chosen = np.random.default_rng(5).choice(every["switch_s"].size, 60, replace=False)
    answers = []
    for m in chosen:
        one = {key: value[m:m + 1].copy() for key, value in every.items()}
        monkeypatch.setattr(geometry, "attribution_manoeuvres", lambda *args, one=one: one)
        monkeypatch.setattr(geometry, "_compiled_reach", lambda: None)
        vectorised = avoidable(frame, context, **metrics)
        monkeypatch.setattr(geometry, "_compiled_reach", lambda: manoeuvre_survives_kernel)
        answers.append((vectorised, avoidable(frame, context, **metrics)))
    assert all(a == b for a, b in answers)
    assert {a for a, _ in answers} == {True, False}

def test_the_compiled_search_is_chosen_where_numba_is_loaded(monkeypatch):
    """numba already loaded (a family's workers): the compiled search; not loaded (a single
    run): the vectorised one, which costs less than loading numba."""
    import sys

    from pipeline.analysis.metrics import geometry
    from pipeline.analysis.metrics.compiled import manoeuvre_survives_kernel

    assert geometry._compiled_reach() is manoeuvre_survives_kernel  # imported above: loaded
    monkeypatch.delitem(sys.modules, "numba")
    assert geometry._compiled_reach() is None

def test_the_oracle_uses_each_tracks_actuators(make_config):
    """Appendix A commands [a, delta] (delta held over a sample, a in the controller's bounds);
    the lateral track commands a steering rate and its speed follows the planner."""
    kinematic = trajectory_context(make_config(["experiment=kinematic"]))
    assert kinematic.steering_rate_max_rad_s == math.inf
    assert (kinematic.braking_mps2, kinematic.accel_mps2) == (3.0, 3.0)
    wider = trajectory_context(make_config(["experiment=kinematic",
                                            "controller.accel_bounds_mps2=[-2.0,1.0]"]))
    assert (wider.braking_mps2, wider.accel_mps2) == (2.0, 1.0)
    lateral = trajectory_context(make_config([]))
    assert lateral.steering_rate_max_rad_s == 1.0
    assert (lateral.braking_mps2, lateral.accel_mps2) == (3.0, 0.0)


@pytest.mark.parametrize("value", [-1, 11, 2.5, True])
def test_switch_samples_out_of_range_name_the_key(value):
    with pytest.raises(ConfigError, match=r"metrics\.attribution_switch_samples"):
        MetricsConfig(attribution_switch_samples=value)


# --- the published label, across methods -------------------------------------------------------

def table(rows: list[tuple[str, bool, bool | None]]) -> pd.DataFrame:
    """A per-scenario table: ``(scenario, collision, collision_avoidable)`` per row."""
    return pd.DataFrame([{"scenario": s, "member": int(s[-4:]), "collision": c,
                          "collision_avoidable": a} for s, c, a in rows])


def test_a_collision_another_method_avoided_is_avoidable_and_names_it():
    improved = table([("family_s0_i0000", True, False), ("family_s0_i0001", False, None)])
    vo = table([("family_s0_i0000", False, None), ("family_s0_i0001", False, None)])
    dwa = table([("family_s0_i0000", False, None), ("family_s0_i0001", True, True)])
    out = label_across_methods({"improved": improved, "vo": vo, "dwa": dwa})
    row = out["improved"].iloc[0]
    assert row[RUN_LABEL] is True and row[LABEL] is False
    assert row[AVOIDED_BY] == "vo; dwa"
    assert row["collision_avoidable"] is True
    # dwa's own collision was avoidable by its own check; improved and vo avoided it too
    assert out["dwa"].iloc[1][RUN_LABEL] is False and out["dwa"].iloc[1][LABEL] is False
    assert out["dwa"].iloc[1][AVOIDED_BY] == "improved; vo"
    counts = {c["method"]: c for c in outcome_counts(out)}
    assert (counts["improved"]["collisions_unavoidable"],
            counts["improved"]["collisions_unavoidable_run"],
            counts["improved"]["collisions_avoidable"]) == (0, 1, 1)
    # the input tables are left as they were (the runs' own labels), and labelling the
    # labelled tables again changes nothing (the runs' own labels are kept in their column)
    assert improved["collision_avoidable"].iloc[0] is False and RUN_LABEL not in improved
    again = label_across_methods(out)
    for name, frame in out.items():
        pd.testing.assert_frame_equal(again[name], frame)
    alone = label_across_methods({"improved": out["improved"]})
    assert alone["improved"].iloc[0][RUN_LABEL] is True and alone["improved"].iloc[0][LABEL]


def test_where_every_method_collided_the_runs_own_label_stands():
    a = table([("family_s0_i0007", True, False), ("family_s0_i0008", True, True)])
    b = table([("family_s0_i0007", True, True), ("family_s0_i0008", True, False)])
    out = label_across_methods({"a": a, "b": b})
    assert list(out["a"][LABEL]) == [True, False]
    assert list(out["b"][LABEL]) == [False, True]
    assert list(out["a"][AVOIDED_BY]) == ["", ""]
    assert Tally.of(out["a"]).collisions_unavoidable == 1
    assert Tally.of(out["b"]).collisions_unavoidable == 1
    rows = collision_rows(out)
    assert list(rows["method"]) == ["a", "a", "b", "b"]
    assert list(rows[LABEL]) == [True, False, False, True]


def test_only_vouchers_of_the_same_pool_vouch():
    """A table outside the ledger (not a voucher) or of another scenario family (another pool:
    a scenario of the same name there is another scenario) shows nothing avoidable."""
    hit = table([("family_s0_i0000", True, False)])
    clean = table([("family_s0_i0000", False, None)])
    unknown = table([("family_s0_i0000", float("nan"), None)])
    tables = {"improved": hit, "variant": clean, "other_track": clean, "failed": unknown}
    out = label_across_methods(tables, vouchers=("improved", "other_track", "failed"),
                               pools={"improved": "kinematic", "variant": "kinematic",
                                      "other_track": "lateral", "failed": "kinematic"})
    assert out["improved"].iloc[0][LABEL] is True
    assert out["improved"].iloc[0][AVOIDED_BY] == ""
    # a variant's own collision is still vouched for by a ledger method of its pool
    variant_hit = label_across_methods({"improved": clean, "variant": hit},
                                       vouchers=("improved",))
    assert variant_hit["variant"].iloc[0][LABEL] is False


def _family_inputs(tables: dict[str, pd.DataFrame], settings) -> FamilyInputs:
    return FamilyInputs(tables, {m: {"method": m} for m in tables},
                        {m: settings for m in tables}, dict(tables), ())


def test_the_report_labels_each_track_across_its_sections(make_config):
    """Planted tables in the report's sections: the Appendix-A family's collision that a peer
    avoided is published as avoidable, naming the peer; the lateral family's collision on the
    same scenario name is not vouched for by the kinematic peer (another track), but by the
    APF-alone run of its own track (the MPC's constraints off: still a method that started
    there)."""
    members = make_config(["experiment=kinematic_family", "scenario.family.size=2"])
    lateral = make_config(["scenario=family", "scenario.family.size=2"])
    hit = table([("family_s0_i0000", True, False), ("family_s0_i0001", False, None)])
    clean = table([("family_s0_i0000", False, None), ("family_s0_i0001", False, None)])
    sections = {"kinematic_family": _family_inputs({"improved": hit}, members),
                "kinematic_peers": _family_inputs({"vo": clean}, members),
                "family": _family_inputs({"improved": hit}, lateral),
                "apf_alone": _family_inputs({"improved": clean}, lateral),
                "peers": None}
    out, rows = label_collisions(sections)
    kin = out["kinematic_family"].primary["improved"]
    assert kin.iloc[0][LABEL] is False and kin.iloc[0][AVOIDED_BY] == "vo"
    assert out["kinematic_family"].tables["improved"] is kin
    lat = out["family"].primary["improved"]
    assert lat.iloc[0][LABEL] is False and lat.iloc[0][AVOIDED_BY] == "improved (apf_alone)"
    assert out["peers"] is None
    assert sorted(zip(rows["section"], rows["track"], rows[AVOIDED_BY], strict=True)) == [
        ("family", "lateral", "improved (apf_alone)"),
        ("kinematic_family", "kinematic", "vo")]
    # without the APF-alone run nothing on the lateral track avoided it
    alone, _ = label_collisions({"family": sections["family"],
                                 "kinematic_peers": sections["kinematic_peers"]})
    assert alone["family"].primary["improved"].iloc[0][LABEL] is True


# --- the Appendix-A track's 25 peer scenarios of a make reproduce ---------------------------

def _raw(section: str) -> dict[str, pd.DataFrame]:
    folder = OUTPUTS / section
    return {p.parent.name: pd.read_csv(p) for p in sorted(folder.glob("*/family_metrics.csv"))}


@pytest.mark.skipif(not ((OUTPUTS / "kinematic_family").is_dir()
                         and (OUTPUTS / "kinematic_peers").is_dir()),
                    reason="needs make reproduce's outputs/kinematic_family and kinematic_peers")
def test_no_appendix_a_collision_a_peer_avoided_is_published_unavoidable():
    """From make reproduce's outputs: every collision of the Appendix-A family on the peers'
    scenarios that any peer (or ledger method) ran without a collision is published avoidable,
    naming them (the oracle: the raw tables read with pandas)."""
    from pipeline.store.collection import load_runs

    layout = ("kinematic_family", "kinematic_peers")
    labelled, _ = label_collisions({section: FamilyInputs.of(load_runs(OUTPUTS / section, []),
                                                             layout)
                                    for section in layout})
    family = labelled["kinematic_family"]
    assert family is not None
    raw = {**_raw("kinematic_family"), **_raw("kinematic_peers")}
    peers = _raw("kinematic_peers")
    shared = set.intersection(*(set(t["scenario"]) for t in peers.values()))
    assert len(shared) >= 25
    clean: dict[str, set[str]] = {}
    for method, frame in raw.items():
        for scenario in frame.loc[~frame["collision"].astype(bool), "scenario"]:
            clean.setdefault(scenario, set()).add(method)
    checked = 0
    for method, frame in family.primary.items():
        stored = raw[method].set_index("scenario")["collision_avoidable"]
        for _, row in frame[frame["collision"].astype(bool)].iterrows():
            assert row[RUN_LABEL] is (not stored[row["scenario"]])
            others = clean.get(row["scenario"], set()) - {method}
            if others:
                assert row[LABEL] is False
                assert set(row[AVOIDED_BY].split("; ")) == others
                checked += row["scenario"] in shared
            else:
                assert row[LABEL] is row[RUN_LABEL]
    assert checked > 0
    improved = family.primary["improved"]
    on_shared = improved[improved["scenario"].isin(shared) & improved["collision"].astype(bool)]
    assert not on_shared[LABEL].astype(bool).any()
    assert Tally.of(improved[improved["scenario"].isin(shared)]).collisions_unavoidable == 0


def test_the_speed_check_labels_each_variant_across_its_two_methods(monkeypatch, tmp_path):
    """make speed-check runs both methods on the same members per variant: improved's
    collision that the baseline ran clean is published avoidable in speed.csv (the run's own
    label beside it); in the other variant both collide and the run's label stands."""
    import types

    import pipeline.studies.experiment as experiment
    from pipeline.studies.speed import speed_check

    planted = {("nominal", "improved"): table([("family_s0_i0000", True, False)]),
               ("nominal", "baseline"): table([("family_s0_i0000", False, None)]),
               ("slow", "improved"): table([("family_s0_i0000", True, False)]),
               ("slow", "baseline"): table([("family_s0_i0000", True, False)])}

    def run_family(cfg, folder, **_):
        return planted[(folder.parent.name, folder.name)]

    def compose(overrides):
        speed = 1.5 if "scenario.speed_mps=1.5" in overrides else 3.0
        return types.SimpleNamespace(scenario=types.SimpleNamespace(speed_mps=speed))

    monkeypatch.setattr(experiment, "run_family", run_family)
    result = speed_check(compose, tmp_path, n_members=1, log=lambda _: None,
                         variants=("nominal", "slow"))
    rows = {(r["variant"], r["method"]): r for r in result.rows}
    assert (rows[("nominal", "improved")]["collisions_unavoidable"],
            rows[("nominal", "improved")]["collisions_unavoidable_run"]) == (0, 1)
    assert (rows[("slow", "improved")]["collisions_unavoidable"],
            rows[("slow", "baseline")]["collisions_unavoidable"]) == (1, 1)
