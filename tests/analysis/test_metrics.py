"""Metrics against closed forms on synthetic trajectories."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from builders import out_and_back, synthetic

from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.analysis.metrics.signals import TrajectoryContext, settling_time, sign_changes
from pipeline.config import MetricsConfig


def metrics_json(*args):
    """The flat ``metrics.json`` mapping of :func:`compute_metrics`."""
    return compute_metrics(*args).to_json()

CTX = TrajectoryContext(start_m=(0.0, 0.0), goal_m=(30.0, 0.0), vehicle_radius_m=1.0)


def test_settling_time_of_exponential_decay_matches_closed_form():
    t = np.arange(0.0, 10.0, 0.01)
    tau, e0, band = 0.8, -1.5, 0.1
    expected = tau * math.log(abs(e0) / band)
    assert settling_time(t, e0 * np.exp(-t / tau), band) == pytest.approx(expected, abs=0.011)


def test_settling_time_is_nan_when_never_recovering():
    t = np.arange(0.0, 5.0, 0.1)
    assert math.isnan(settling_time(t, np.full(t.size, 1.0), 0.25))
    assert math.isnan(settling_time(t, np.linspace(0.0, 2.0, t.size), 0.25))
    assert settling_time(t, np.full(t.size, 0.1), 0.25) == 0.0


def test_sign_changes_of_sinusoid():
    t = np.arange(0.0, 10.0, 0.01)
    # sin(pi t) crosses zero at t = 1, ..., 9 inside (0, 10): nine sign changes
    assert sign_changes(np.sin(np.pi * t), 0.05) == 9
    assert sign_changes(0.01 * np.sin(np.pi * t), 0.05) == 0  # all inside the band


def test_constant_curvature_arc_has_zero_jerk_and_curvature_rate():
    v, radius = 3.0, 10.0
    t = np.arange(0.0, 5.0, 0.1)
    theta = v * t / radius
    frame = synthetic(t, radius * np.sin(theta), radius * (1 - np.cos(theta)), psi=theta,
                      r=np.full(t.size, v / radius), v=v)
    m = metrics_json(frame, CTX, MetricsConfig())
    assert m["lateral_jerk_rms_run_mps3"] == pytest.approx(0.0, abs=1e-12)
    assert m["lateral_jerk_rms_mps3"] is None  # no obstacle: no avoidance window
    assert m["curvature_rate_rms_1_per_ms"] == pytest.approx(0.0, abs=1e-12)
    assert m["lateral_accel_max_mps2"] == pytest.approx(v**2 / radius)
    assert m["path_length_m"] == pytest.approx(v * t[-1], rel=1e-3)




def test_reaction_delay_clearance_and_recovery_on_a_scripted_avoidance():
    dt = 0.1
    t = np.arange(0.0, 12.0 + dt / 2, dt)
    x = 3.0 * t
    # steer from t = 3.4 s; lateral detour to -2 m between x = 9 and 21, back by x = 24
    y = -2.0 * np.clip(np.minimum((x - 6.0) / 3.0, (24.0 - x) / 3.0), 0.0, 1.0)
    delta = np.where(t >= 3.4 - 1e-9, 0.05, 0.0)
    psi = np.arctan(np.gradient(y, x))
    frame = synthetic(t, x, y, psi=psi, delta=delta, obstacle=(15.0, 0.0, 0.5), appear=3.0)
    m = metrics_json(frame, CTX, MetricsConfig())
    # the scripted detour is already 2 m aside when the obstacle appears: no threat, no clock
    assert m["threatened"] is False and m["reaction_delay_s"] is None
    old = metrics_json(frame, CTX, MetricsConfig(reaction_obstacle="first_visible",
                                                    reaction_interpolation="sample"))
    assert old["reaction_delay_s"] == pytest.approx(0.4, abs=1e-9)
    # closest approach at y = -2 right beside the obstacle: 2 - 0.5 - 1.0
    assert m["min_clearance_m"] == pytest.approx(0.5, abs=1e-9)
    assert not m["collision"]
    # the obstacle is passed when x - 15 > 1.5, i.e. x = 16.8 at t = 5.6 s
    assert m["obstacle_passed_time_s"] == pytest.approx(5.6, abs=1e-9)
    # lateral error inside 0.25 m once y > -0.25, i.e. x > 23.625 -> t = 7.9 s
    assert m["recovery_lateral_s"] == pytest.approx(7.9 - 5.6, abs=1e-9)
    assert m["max_lateral_deviation_m"] == pytest.approx(2.0)
    assert m["goal_reached"] and m["time_to_goal_s"] == pytest.approx(9.9, abs=1e-9)


def test_collision_flag_and_no_reaction():
    t = np.arange(0.0, 8.0, 0.1)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(15.0, 0.3, 0.5), appear=2.0)
    m = metrics_json(frame, CTX, MetricsConfig())
    assert m["collision"] and m["min_clearance_m"] == pytest.approx(0.3 - 1.5, abs=1e-9)
    assert m["reaction_delay_s"] is None and m["reacted"] is False


def test_repulsion_share_closed_form_and_zero_when_never_repelled():
    t = np.arange(0.0, 10.0, 0.1)
    frame = synthetic(t, 3.0 * t, np.full(t.size, -2.0), obstacle=(15.0, 0.0, 0.5), appear=0.0)
    # clearance = hypot(x - 15, 2) - 1.5 > 2 m (far) until |x - 15| < sqrt(3.5^2 - 4)
    frame["apf_rep_norm"] = 1.0
    m = metrics_json(frame, CTX, MetricsConfig())
    far = np.hypot(3.0 * t - 15.0, 2.0) - 1.5 > 2.0
    assert m["repulsive_impulse_far_share"] == pytest.approx(far.mean())
    assert m["repulsive_impulse"] == pytest.approx(t.size * 0.1)
    frame["apf_rep_norm"] = 0.0
    assert metrics_json(frame, CTX, MetricsConfig())["repulsive_impulse_far_share"] == 0.0


def two_obstacle_run(steer_from_s: float) -> pd.DataFrame:
    """Straight at 3 m/s; a harmless obstacle appears at 0.5 s far to the side, a threatening
    one at 3.0 s ahead on the path; the steering angle ramps from ``steer_from_s``."""
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size),
                      delta=np.maximum(t - steer_from_s, 0.0) * 0.5)
    frame["obs0_x_m"], frame["obs0_y_m"], frame["obs0_radius_m"] = 6.0, 8.0, 0.5
    frame["obs0_visible"] = t >= 0.5 - 1e-9
    frame["obs1_x_m"], frame["obs1_y_m"], frame["obs1_radius_m"] = 16.0, 0.3, 0.5
    frame["obs1_visible"] = t >= 3.0 - 1e-9
    return frame


def test_reaction_clock_starts_at_the_threatening_obstacle_and_interpolates():
    """Steering leaves the 0.01 rad band 0.02 s after it starts moving at 3.1 s (0.5 rad/s
    ramp): 0.12 s after the threat appears, not 2.62 s after the harmless obstacle."""
    m = metrics_json(two_obstacle_run(3.1), CTX, MetricsConfig())
    assert m["threatened"] and m["threat_appear_time_s"] == pytest.approx(3.0)
    assert m["reaction_delay_s"] == pytest.approx(0.12, abs=1e-9)
    assert m["reaction_delay_first_visible_s"] == pytest.approx(2.62, abs=1e-9)
    old = metrics_json(two_obstacle_run(3.1), CTX,
                          MetricsConfig(reaction_obstacle="first_visible",
                                        reaction_interpolation="sample"))
    assert old["reaction_delay_s"] == pytest.approx(2.7, abs=1e-9)


def test_an_obstacle_that_threatens_nothing_gives_no_reaction():
    frame = two_obstacle_run(3.1).drop(columns=[c for c in synthetic(np.zeros(2), 0, 0).columns
                                                if False])
    frame["obs1_y_m"] = 9.0  # far off the path as well
    m = metrics_json(frame, CTX, MetricsConfig())
    assert m["threatened"] is False and m["reaction_delay_s"] is None


def test_fast_obstacle_crossing_between_two_rows_is_a_collision():
    """At 100 m/s the obstacle jumps from 5 m left to 5 m right of the vehicle between two log
    rows: every row shows 3.5 m of clearance, the continuous check finds the contact."""
    t = np.round(np.arange(0.0, 4.0 + 1e-9, 0.1), 10)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size))
    frame["obs0_x_m"] = 3.0 * 2.05  # where the vehicle is halfway between rows 20 and 21
    frame["obs0_y_m"] = 5.0 - 100.0 * np.clip(t - 2.0, 0.0, None)
    frame["obs0_radius_m"], frame["obs0_visible"] = 0.5, (t >= 2.0 - 1e-9) & (t <= 2.1 + 1e-9)
    m = metrics_json(frame, CTX, MetricsConfig())
    assert m["min_clearance_sampled_m"] == pytest.approx(np.hypot(0.15, 5.0) - 1.5, abs=1e-9)
    assert m["collision"] and m["min_clearance_m"] < 0
    sampled = metrics_json(frame, CTX, MetricsConfig(collision_check="sampled"))
    assert not sampled["collision"]


def test_sinusoidal_sideslip_has_the_closed_form_jerk():
    """vy = A w cos(w t), r = 0: a_y = vy_dot = -A w^2 sin(w t), jerk RMS = A w^3 / sqrt(2) over
    whole periods; the older reading a_y = vx r sees nothing."""
    A, w = 0.2, 2.0 * np.pi / 2.0
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.001), 10)
    frame = synthetic(t, 3.0 * t, A * np.sin(w * t))
    frame["vy_mps"] = A * w * np.cos(w * t)
    m = metrics_json(frame, CTX, MetricsConfig())
    assert m["lateral_jerk_rms_run_mps3"] == pytest.approx(A * w**3 / np.sqrt(2), rel=1e-3)
    assert m["lateral_jerk_rms_vx_r_mps3"] == pytest.approx(0.0, abs=1e-12)
    old = metrics_json(frame, CTX, MetricsConfig(lateral_accel="vx_r"))
    assert old["lateral_jerk_rms_run_mps3"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("overshoot, swings, expected", [(0.0, 0, 0), (0.4, 0, 1), (0.4, 3, 4)])
def test_oscillation_counts_reversals_after_the_pass_net_of_the_manoeuvre(overshoot, swings,
                                                                         expected):
    m = metrics_json(out_and_back(overshoot, swings), CTX, MetricsConfig())
    assert m["oscillation_count"] == expected
    # the older reading counts the out-and-back's own sign changes of yaw rate as well
    old = metrics_json(out_and_back(overshoot, swings), CTX,
                          MetricsConfig(oscillation="sign_changes_whole_run"))
    assert old["oscillation_count"] == old["oscillation_whole_run_count"]


def test_repulsion_while_nothing_threatens_is_unneeded():
    """Driving 3 m beside a static obstacle: it never threatens the straight path, so under the
    threat-only reading all the repulsion is unneeded; the older clearance-band reading calls
    part of it needed."""
    t = np.arange(0.0, 10.0, 0.1)
    frame = synthetic(t, 3.0 * t, np.full(t.size, -3.0), obstacle=(15.0, 0.0, 0.5), appear=0.0)
    frame["apf_rep_norm"] = 1.0
    m = metrics_json(frame, CTX, MetricsConfig(repulsion_need="threat"))
    assert m["repulsion_unneeded_share"] == pytest.approx(1.0)
    assert m["repulsive_impulse_far_share"] < 1.0
    band = metrics_json(frame, CTX, MetricsConfig(repulsion_need="clearance_band"))
    assert band["repulsion_unneeded_share"] == pytest.approx(m["repulsive_impulse_far_share"])
    # on the obstacle's line the straight path is threatened until it is passed
    ahead = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(15.0, 0.0, 0.5), appear=0.0)
    ahead["apf_rep_norm"] = 1.0
    share = metrics_json(ahead, CTX, MetricsConfig(repulsion_need="threat",
                                                   threat_horizon_s=3.0))["repulsion_unneeded_share"]
    # threatened while 15 - x within 3 s at 3 m/s (x > 6 - reach... ) and until the contact
    assert 0.0 < share < 1.0


def test_collision_attribution_separates_unavoidable_from_avoidable():
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    # appears on top of the vehicle: nothing avoids it
    on_top = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(9.3, 0.0, 0.5), appear=3.0)
    m = metrics_json(on_top, CTX, MetricsConfig())
    assert m["collision"] and m["collision_avoidable"] is False
    # appears 12 m ahead, static: a vehicle that never steers hits it, a swerve would not
    ahead = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(21.0, 0.0, 0.5), appear=3.0)
    m = metrics_json(ahead, CTX, MetricsConfig())
    assert m["collision"] and m["collision_avoidable"] is True
    clear = synthetic(t, 3.0 * t, np.zeros(t.size), obstacle=(21.0, 4.0, 0.5), appear=3.0)
    assert metrics_json(clear, CTX, MetricsConfig())["collision_avoidable"] is None


def test_force_spent_passing_a_near_obstacle_counts_as_needed():
    """C3a (Table 2's first half): 3 m beside a static obstacle the clearance is 1.5 m, inside
    the 2 m near field while |x - 15| < sqrt(2.0+1.5)^2 - ... : the share of unneeded impulse is
    exactly the share of rows outside the near field (closed form on the sampled rows)."""
    t = np.round(np.arange(0.0, 10.0, 0.1), 10)
    x, y = 3.0 * t, np.full(t.size, -3.0)
    frame = synthetic(t, x, y, obstacle=(15.0, 0.0, 0.5), appear=0.0)
    frame["apf_rep_norm"] = 1.0
    m = metrics_json(frame, CTX, MetricsConfig())
    clearance = np.hypot(x - 15.0, y) - 0.5 - 1.0
    assert m["repulsion_unneeded_share"] == pytest.approx(np.mean(clearance > 2.0))
    assert m["repulsion_unneeded_share"] < m["repulsion_unneeded_share_threat"] == 1.0
    # a wider near field counts more of the force as needed
    wide = metrics_json(frame, CTX, MetricsConfig(near_field_m=4.0))
    assert wide["repulsion_unneeded_share"] == pytest.approx(np.mean(clearance > 4.0))


def test_onset_of_repulsion_is_timed_by_the_time_to_contact():
    """C3b (Table 2's second half): a static obstacle on the path, 3 m/s; repulsion exceeds the
    onset force from x = 6 m on: the time to contact then is (15 - 6 - reach) / 3."""
    t = np.round(np.arange(0.0, 10.0, 0.1), 10)
    x = 3.0 * t
    frame = synthetic(t, x, np.zeros(t.size), obstacle=(15.0, 0.0, 0.5), appear=0.0)
    frame["apf_rep_norm"] = np.where(x >= 6.0 - 1e-9, 2.0, 0.5)
    m = metrics_json(frame, CTX, MetricsConfig())
    reach = 0.5 + 1.0 + 0.5
    assert m["repulsion_onset_ttc_s"] == pytest.approx((15.0 - 6.0 - reach) / 3.0)
    # a higher onset force: never significant, no onset
    late = metrics_json(frame, CTX, MetricsConfig(repulsion_onset_force=5.0))
    assert late["repulsion_onset_ttc_s"] is None


def test_recovery_reading_switches_between_lateral_and_heading_settling():
    frame = out_and_back(0.0, 0)
    lateral = metrics_json(frame, CTX, MetricsConfig())
    heading = metrics_json(frame, CTX, MetricsConfig(recovery_reading="heading"))
    assert lateral["recovery_time_s"] == lateral["recovery_lateral_s"]
    assert heading["recovery_time_s"] == heading["recovery_heading_s"]
    assert heading["recovery_lateral_s"] == lateral["recovery_lateral_s"]
    assert heading["recovery_time_s"] != lateral["recovery_time_s"]


def walker_who_walks_ahead() -> pd.DataFrame:
    """A vehicle at 3 m/s along y = 0 and a walker ahead of it on its line at 1 m/s (a threat:
    the vehicle closes on it), who steps aside to y = 4 m between t = 2 and 3 s and then walks
    on at 5 m/s: the threat ends at t = 2 s, yet the vehicle is never ahead of the walker."""
    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 10)
    frame = synthetic(t, 3.0 * t, np.zeros(t.size))
    frame["obs0_x_m"] = np.where(t <= 2.0, 9.0 + t, np.where(t <= 3.0, 11.0, 11.0 + 5.0 * (t - 3.0)))
    frame["obs0_y_m"] = np.clip(4.0 * (t - 2.0), 0.0, 4.0)
    frame["obs0_radius_m"], frame["obs0_visible"] = 0.3, True
    return frame


def test_pass_reading_last_threat_passes_a_walker_who_stays_ahead():
    frame = walker_who_walks_ahead()
    ahead = metrics_json(frame, CTX, MetricsConfig())
    last = metrics_json(frame, CTX, MetricsConfig(pass_reading="last_threat"))
    assert ahead["threatened"] is True and last["threatened"] is True
    # never ahead of the walker: never passed, so no recovery and no oscillation count
    assert ahead["obstacle_passed_time_s"] is None
    assert ahead["recovered"] is False and ahead["oscillation_count"] is None
    # up to t = 1.9 s the walker walks the line at 1 m/s (a threat); from the row of t = 2.0 s
    # on it steps aside at 4 m/s (its logged velocity, forward differences), and at constant
    # velocity it is 6.7 m aside when the vehicle reaches its x: no threat from 2.0 s on
    assert last["obstacle_passed_time_s"] == pytest.approx(2.0, abs=1e-9)
    # the vehicle never left its line: settled at once, no reversal
    assert last["recovered"] is True and last["recovery_time_s"] == 0.0
    assert last["oscillation_count"] == 0


def test_pass_reading_last_threat_never_passes_an_obstacle_collided_with():
    frame = walker_who_walks_ahead()
    frame["obs0_x_m"], frame["obs0_y_m"] = 12.0, 0.0  # standing on the line: driven through
    last = metrics_json(frame, CTX, MetricsConfig(pass_reading="last_threat"))
    assert last["collision"] is True and last["obstacle_passed_time_s"] is None


def test_a_wider_recovery_band_settles_sooner():
    frame = out_and_back(0.4, 0)
    narrow = metrics_json(frame, CTX, MetricsConfig(recovery_lateral_band_m=0.1))
    wide = metrics_json(frame, CTX, MetricsConfig(recovery_lateral_band_m=0.5))
    assert wide["recovery_time_s"] < narrow["recovery_time_s"]


# --- several metric readings of one run in one pass (the multiverse's re-scoring) -------------

#: alternative values of every metric setting (the first: a second value besides the default)
READING_VALUES = {
    "reaction_steering_band_rad": [0.02], "reaction_lateral_band_m": [0.1],
    "reaction_obstacle": ["first_visible"], "reaction_interpolation": ["sample"],
    "threat_margin_m": [0.25, 1.0], "threat_horizon_s": [3.0, 2.0],
    "pass_reading": ["last_threat"],
    "threat_clearance_m": [1.0], "near_field_m": [1.0, 3.0], "lateral_accel": ["vx_r"],
    "smoothness_window": ["whole_run"], "repulsion_need": ["threat", "clearance_band"],
    "repulsion_onset_force": [0.5], "recovery_lateral_band_m": [0.15, 0.4],
    "recovery_heading_band_rad": [0.1], "recovery_heading_stop_m": [2.0],
    "recovery_reading": ["heading"], "oscillation": ["sign_changes_whole_run"],
    "lateral_sign_band_m": [0.1], "yaw_rate_sign_band_rad_s": [0.05],
    "collision_check": ["sampled"], "attribution_steering_samples": [5],
    "attribution_switch_samples": [0], "attribution_extra_s": [1.0], "goal_tolerance_m": [1.0]}


@pytest.fixture(scope="module")
def closed_loop_runs(make_config):
    """Family members of both APFs with and without collisions (avoidable and not): their
    trajectories and contexts."""
    import dataclasses

    from pipeline import api
    from pipeline.loop.scenario import family_members
    from pipeline.studies.experiment import trajectory_context

    runs = []
    for method, indices in (("baseline", (1, 47, 48)), ("improved", (0, 2))):
        cfg = make_config([f"method={method}", "scenario=family", "scenario.family.size=50"])
        members = family_members(cfg.scenario, cfg.vehicle.footprint_radius_m)
        for i in indices:
            member = dataclasses.replace(cfg, scenario=members[i])
            runs.append((api.simulate(config=member).trajectory, trajectory_context(member)))
    return runs


def _readings(base: MetricsConfig) -> list[MetricsConfig]:
    """The base, every one-at-a-time change (a criterion keyed on too few fields would hand
    the base's result to the changed reading), and seeded combinations."""
    import dataclasses

    assert set(READING_VALUES) == {f.name for f in dataclasses.fields(MetricsConfig)}
    readings = [base] + [dataclasses.replace(base, **{name: value})
                         for name, values in READING_VALUES.items() for value in values]
    rng = np.random.default_rng(0)
    for _ in range(30):
        change = {name: ([getattr(base, name)] + values)[rng.integers(len(values) + 1)]
                  for name, values in READING_VALUES.items() if rng.random() < 0.4}
        readings.append(dataclasses.replace(base, **change))
    return readings


def test_every_reading_in_one_pass_equals_each_reading_alone(closed_loop_runs):
    import json

    from pipeline.analysis.metrics.criteria import compute_metrics_readings

    readings = _readings(MetricsConfig())
    collisions = avoidable = 0
    changed = set()
    for trajectory, context in closed_loop_runs:
        together = compute_metrics_readings(trajectory, context, readings)
        alone = [compute_metrics(trajectory, context, r).to_json() for r in readings]
        assert [json.dumps(m.to_json()) for m in together] == [json.dumps(m) for m in alone]
        collisions += bool(alone[0]["collision"])
        avoidable += alone[0]["collision_avoidable"] is False
        changed |= {k for m in alone for k in m if json.dumps(m[k]) != json.dumps(alone[0][k])}
    # the runs exercise the shared criteria: collisions (one not avoidable), and readings that
    # move every reading-dependent criterion
    # the runs collide (one unavoidably), and readings move every criterion's output: a result
    # shared between readings that differ in what it reads would show here
    assert collisions >= 2 and avoidable >= 1
    assert {"min_clearance_m", "threat_appear_time_s", "reaction_delay_s",
            "lateral_jerk_rms_window_mps3", "recovery_time_s", "oscillation_count",
            "repulsion_unneeded_share", "time_to_goal_s"} <= changed


def test_each_criterion_reads_only_the_settings_it_is_shared_on(closed_loop_runs, monkeypatch):
    """A recorder in place of the settings, per criterion: the fields each one reads are
    within its ``*_READS`` (what the one-pass computation shares its result on)."""
    import inspect

    import pipeline.analysis.metrics.criteria as metrics_module

    class Recorder:
        def __init__(self, settings, log):
            self._settings, self._log = settings, log

        def __getattr__(self, name):
            self._log.add(name)
            return getattr(self._settings, name)

    declared = {"safety_block": metrics_module.SAFETY_READS,
                "threat_block": metrics_module.THREAT_READS,
                "recovery_block": metrics_module.RECOVERY_READS,
                "reaction_block": metrics_module.REACTION_READS,
                "smoothness_block": metrics_module.SMOOTHNESS_READS,
                "stability_block": metrics_module.STABILITY_READS,
                "repulsion_block": metrics_module.REPULSION_READS,
                "progress_block": metrics_module.PROGRESS_READS}
    read: dict[str, set] = {name: set() for name in declared}
    for name in declared:
        original = getattr(metrics_module, name)
        signature = inspect.signature(original)

        def recording(*args, _original=original, _signature=signature, _log=read[name],
                      **kwargs):
            bound = _signature.bind(*args, **kwargs)
            bound.arguments["thresholds"] = Recorder(bound.arguments["thresholds"], _log)
            return _original(*bound.args, **bound.kwargs)

        monkeypatch.setattr(metrics_module, name, recording)
    for trajectory, context in closed_loop_runs:
        metrics_module.compute_metrics_readings(trajectory, context, _readings(MetricsConfig()))
    for name, fields_read in read.items():
        assert fields_read, name  # the recorder saw the criterion's reads
        assert fields_read <= set(declared[name]), (name, fields_read - set(declared[name]))


@pytest.mark.parametrize("seed", range(6))
def test_time_derivative_is_numpys_gradient_bit_for_bit(seed):
    """``time_derivative`` writes out ``np.gradient``'s statements for a 1-D signal: the same
    bits (the oracle is numpy itself) on uniform and uneven clocks, repeated time stamps,
    signals with NaN and infinities, two and three samples; other shapes are numpy's."""
    from pipeline.analysis.metrics.signals import time_derivative

    rng = np.random.default_rng(seed)
    for n in (2, 3, 7, 101):
        values = rng.normal(0.0, 3.0, n)
        if seed % 2:
            values[rng.integers(0, n, 2)] = [np.nan, np.inf]
        clocks = [np.arange(n) * 0.1, np.arange(n) * 0.05 + 3.0,
                  np.cumsum(rng.uniform(0.01, 0.2, n)), np.round(np.arange(n) * 0.1, 1)]
        uneven = np.cumsum(rng.uniform(0.0, 0.2, n))
        uneven[n // 2] = uneven[n // 2 - 1]  # a repeated stamp: numpy's inf and NaN
        clocks.append(uneven)
        for t in clocks:
            with np.errstate(all="ignore"):
                got, want = time_derivative(values, t), np.gradient(values, t)
            assert got.dtype == want.dtype and got.shape == want.shape
            assert np.array_equal(got.view(np.uint64), want.view(np.uint64)), (n, t)
    with pytest.raises(ValueError):
        time_derivative(np.ones(4), np.arange(3.0))  # numpy's own refusal
    assert np.isnan(time_derivative(np.ones(1), np.zeros(1))).all()
