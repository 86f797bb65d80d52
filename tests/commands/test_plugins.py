"""Hostile plug-ins and API inputs: what a planner or controller of one's own (``_target_``)
returns is checked where it enters the loop, and ``api.compare`` refuses families that cannot
be paired; each refusal is one line naming the plug-in (or family) and the field.

The command and the line the user sees, e.g.::

    $ python -m pipeline.run planner._target_=my_bad.ShortPlanner
    plug-in error: planner my_bad.ShortPlanner returned rollout().path_m = an array of shape
    (7, 2); allowed: shape (10, 2): controller.horizon = 10 points (x, y) in metres

(one line; exit code 2).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import PluginOutputError

ROOT = Path(__file__).resolve().parents[2]

PLUGINS = '''
import numpy as np
from pipeline.loop.controller import ControlStep
from pipeline.loop.planner import ApfPlanner, ApfRollout


def straight(planner, position_m, goal_m, points):
    d = np.asarray(goal_m, float) - position_m
    d = d / max(np.linalg.norm(d), 1e-9)
    path = np.array([position_m + k * 0.5 * d for k in range(points)])
    zeros = np.zeros((planner.horizon - 1, 2))
    flags = np.zeros(planner.horizon - 1, bool)
    return ApfRollout(path, zeros, zeros.copy(), flags, flags.copy())


class GoodPlanner(ApfPlanner):
    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        return straight(self, position_m, goal_m, self.horizon)


class ShortPlanner(ApfPlanner):
    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        return straight(self, position_m, goal_m, self.horizon - 3)


class FastPlanner(GoodPlanner):
    def speed(self, *args, **kwargs):
        return 1e6


class NanPlanner(ApfPlanner):
    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        out = straight(self, position_m, goal_m, self.horizon)
        out.path_m[5, 1] = np.nan
        return out


class TuplePlanner(ApfPlanner):
    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        return tuple(straight(self, position_m, goal_m, self.horizon).path_m)


class Hold:
    def __init__(self, settings, vehicle, sample_time_s, qp_cache=None):
        self.compile_count, self.compile_time_s = 0, 0.0
        self.horizon = settings.horizon

    def command(self):
        return np.zeros(1)

    def step(self, obs):
        return ControlStep(self.command(), np.zeros((1, self.horizon)), None, "optimal", 0,
                           0.0, "none", 0.0, {})


class ThreeInputs(Hold):
    def command(self):
        return np.zeros(3)


class NanInput(Hold):
    def command(self):
        return np.array([np.inf])


class WildRate(Hold):
    def command(self):
        return np.array([50.0])


class BareArray(Hold):
    def step(self, obs):
        return np.zeros(1)
'''


@pytest.fixture()
def plugins(tmp_path, monkeypatch):
    """The module ``my_bad`` (above) importable here and in subprocesses."""
    (tmp_path / "my_bad.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("my_bad", None)
    return tmp_path


def _simulate(make_config, overrides):
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate

    cfg = make_config(overrides)
    return simulate(cfg, build_scenario(cfg.scenario))


CASES = [
    (["planner._target_=my_bad.ShortPlanner"],
     "plug-in error: planner my_bad.ShortPlanner returned rollout().path_m = an array of shape "
     "(7, 2); allowed: shape (10, 2): controller.horizon = 10 points (x, y) in metres"),
    (["planner._target_=my_bad.FastPlanner"],
     "plug-in error: planner my_bad.FastPlanner returned speed() = 1000000.0 m/s; allowed: a "
     "speed in [0, 40] m/s (the range of scenario.speed_mps)"),
    (["planner._target_=my_bad.NanPlanner"],
     "plug-in error: planner my_bad.NanPlanner returned rollout().path_m = nan (non-finite); "
     "allowed: finite numbers, shape (10, 2): controller.horizon = 10 points (x, y) in metres"),
    (["planner._target_=my_bad.TuplePlanner"],
     "plug-in error: planner my_bad.TuplePlanner returned rollout() = a tuple; allowed: an "
     "ApfRollout (pipeline.loop.planner)"),
    (["controller._target_=my_bad.ThreeInputs"],
     "plug-in error: controller my_bad.ThreeInputs returned step().command = an array of shape "
     "(3,); allowed: shape (1,): [steering rate rad/s]"),
    (["controller._target_=my_bad.NanInput"],
     "plug-in error: controller my_bad.NanInput returned step().command = inf (non-finite); "
     "allowed: finite numbers, shape (1,): [steering rate rad/s]"),
    (["controller._target_=my_bad.WildRate"],
     "plug-in error: controller my_bad.WildRate returned step().command[0] (steering rate "
     "rad/s) = 50.0; allowed: [-1, 1] (the vehicle's limit)"),
    (["controller._target_=my_bad.BareArray"],
     "plug-in error: controller my_bad.BareArray returned step() = a ndarray; allowed: a "
     "ControlStep (pipeline.loop.controller)"),
    (["experiment=kinematic", "controller._target_=my_bad.NanInput"],
     "plug-in error: controller my_bad.NanInput returned step().command = an array of shape "
     "(1,); allowed: shape (2,): [acceleration m/s^2, steering angle rad]"),
]


@pytest.mark.parametrize(("overrides", "line"), CASES, ids=[c[0][-1] for c in CASES])
def test_a_bad_plugin_output_is_one_line_naming_the_plugin_and_the_field(
        plugins, make_config, overrides, line):
    with pytest.raises(PluginOutputError) as info:
        _simulate(make_config, overrides)
    assert str(info.value) == line


def test_the_command_prints_that_line_and_exits_2(plugins, tmp_path):
    """``python -m pipeline.run planner._target_=my_bad.ShortPlanner``: exit 2, one line,
    nothing written but the run folder's lock-free shell."""
    env = {**os.environ, "PYTHONPATH": f"{plugins}{os.pathsep}{ROOT}"}
    out = tmp_path / "short"
    proc = subprocess.run([sys.executable, "-m", "pipeline.run",
                           "planner._target_=my_bad.ShortPlanner", f"hydra.run.dir={out}"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = [x for x in proc.stderr.strip().splitlines() if not x.startswith("[")]
    assert lines == [CASES[0][1]]
    assert not (out / "metrics.json").exists() and not (out / ".lock").exists()


def test_good_plugins_pass_unchanged_and_builtins_are_not_wrapped(plugins, make_config):
    """The checks hand a good plug-in's outputs on as they are (the same arrays); the
    built-in planner and controller are not wrapped at all, so their runs cannot change."""
    from pipeline.loop.controller import QpCache
    from pipeline.loop.planner import ApfPlanner
    from pipeline.loop.plugins import CheckedController, CheckedPlanner
    from pipeline.loop.python_kernels import PYTHON_KERNELS
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import _loop_stages

    cfg = make_config([])
    scenario = build_scenario(cfg.scenario)
    _, _, controller, planner = _loop_stages(cfg, scenario, QpCache(), PYTHON_KERNELS)
    assert type(planner) is ApfPlanner
    assert not isinstance(controller, CheckedController)
    cfg = make_config(["planner._target_=my_bad.GoodPlanner", "controller._target_=my_bad.Hold"])
    _, _, controller, planner = _loop_stages(cfg, scenario, QpCache(), PYTHON_KERNELS)
    assert isinstance(planner, CheckedPlanner) and isinstance(controller, CheckedController)
    inner = planner.inner.rollout(scenario.start_m, scenario.goal_m,
                                  scenario.obstacles_at(0.0).only_visible())
    checked = planner.rollout(scenario.start_m, scenario.goal_m,
                              scenario.obstacles_at(0.0).only_visible())
    assert np.array_equal(inner.path_m, checked.path_m)
    result = _simulate(make_config, ["planner._target_=my_bad.GoodPlanner",
                                     "controller._target_=my_bad.Hold"])
    assert result.termination in ("goal_line", "max_steps")
    assert (result.trajectory["steering_rate_rad_s"].dropna() == 0).all()


class _Stub:
    def __init__(self, path):
        self.path = path

    def rollout(self, *args):
        from pipeline.loop.planner import ApfRollout

        n = 20
        zeros = np.zeros((n - 1, 2))
        return ApfRollout(self.path, zeros, zeros.copy(), np.zeros(n - 1, bool),
                          np.zeros(n - 1, bool))

    def speed(self, *args):
        return 3.0


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(0, 40), cols=st.integers(1, 3),
       poison=st.sampled_from([None, np.nan, np.inf, -np.inf, 1e300]))
def test_a_path_is_accepted_exactly_when_it_has_horizon_points_and_is_finite(rows, cols, poison):
    """Property: the planner boundary accepts a path iff its shape is (horizon, 2) and every
    number is finite (a huge finite one passes: no range is claimed for positions)."""
    from pipeline.loop.plugins import CheckedPlanner

    path = np.ones((rows, cols))
    if poison is not None and path.size:
        path.flat[path.size // 2] = poison
    planner = CheckedPlanner(_Stub(path), "stub.Planner", 20, 40.0)
    good = (rows, cols) == (20, 2) and bool(np.isfinite(path).all())
    if good:
        assert planner.rollout().path_m is path
    else:
        with pytest.raises(PluginOutputError) as info:
            planner.rollout()
        assert "planner stub.Planner" in str(info.value) and "\n" not in str(info.value)
        assert "rollout().path_m" in str(info.value)


@settings(max_examples=60, deadline=None)
@given(value=st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                       st.none(), st.text(max_size=3)))
def test_a_planned_speed_is_accepted_exactly_within_the_schema_range(value):
    from pipeline.loop.plugins import CheckedPlanner

    stub = _Stub(np.zeros((20, 2)))
    stub.speed = lambda *args: value
    planner = CheckedPlanner(stub, "stub.Planner", 20, 40.0)
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = None
    if number is not None and 0.0 <= number <= 40.0:
        assert planner.speed() == number
    else:
        with pytest.raises(PluginOutputError, match=r"returned speed\(\)"):
            planner.speed()


# --- api.compare: families that cannot be paired ---------------------------------------------

def _family(overrides):
    import pandas as pd

    from pipeline import api
    from pipeline.analysis.tally import Tally

    cfg = api.compose(["scenario=family", "scenario.family.size=4", *overrides])
    table = pd.DataFrame({"scenario": [f"member_{i:03d}" for i in range(4)]})
    return api.FamilyResult(cfg, table, Tally.__new__(Tally))


@pytest.mark.parametrize(("control", "line"), [
    (["experiment=kinematic", "method=baseline"],
     "api.compare: the control 'baseline' is a kinematic family and the treatment 'improved' a "
     "lateral one; allowed: families of one track (compose both with, or both without, "
     "experiment=kinematic)"),
    (["method=baseline", "scenario.family.seed=5"],
     "api.compare: the control 'baseline' ran another scenario family (scenario.family.seed=5 "
     "against the treatment's 0); allowed: the same family for every method, members paired "
     "by scenario"),
    (["method=baseline", "scenario.family.size=5"],
     "api.compare: the control 'baseline' ran another scenario family (scenario.family.size=5 "
     "against the treatment's 4); allowed: the same family for every method, members paired "
     "by scenario"),
], ids=["kinematic-vs-lateral", "other-seed", "other-size"])
def test_api_compare_refuses_families_that_cannot_be_paired(control, line):
    """``api.compare(improved_lateral, {"baseline": baseline_kinematic})`` -> ValueError with
    one line naming the control and the key (nothing is computed)."""
    from pipeline import api

    with pytest.raises(ValueError) as info:
        api.compare(_family(["method=improved"]), {"baseline": _family(control)})
    assert str(info.value) == line


def test_api_compare_refuses_what_is_not_a_family_and_allows_other_workers():
    from pipeline import api

    treatment = _family(["method=improved"])
    with pytest.raises(TypeError, match=r"^api.compare: the control 'baseline' is a DataFrame; "
                                        r"allowed: a FamilyResult"):
        api.compare(treatment, {"baseline": treatment.table})
    with pytest.raises(TypeError, match=r"^api.compare: controls is dict \(empty\)"):
        api.compare(treatment, {})
    # scenario.family.n_jobs says how a family ran, not what it is: it pairs
    from pipeline.api import _check_pairable

    _check_pairable(treatment, "baseline", _family(["method=baseline",
                                                    "scenario.family.n_jobs=1"]))


@pytest.mark.parametrize(("call", "line"), [
    (lambda api: api.compose("method=improved"),
     "overrides is 'method=improved'; allowed: a list of strings such as "
     "['method=improved', 'planner.beta=0.5']"),
    (lambda api: api.simulate_family([3]),
     "overrides is [3]; allowed: a list of strings such as ['method=improved', "
     "'planner.beta=0.5']"),
    (lambda api: api.simulate(config={"method": "improved"}),
     "config is a dict; allowed: an ExperimentConfig (api.compose)"),
    (lambda api: api.compare(_family(["method=improved"]), _family(["method=baseline"]),
                             claims={"alpha": 0.05}),
     "api.compare: claims is a dict; allowed: a ClaimsConfig (e.g. api.compose([...]).claims) "
     "or None"),
], ids=["bare-string", "not-strings", "config-dict", "claims-dict"])
def test_api_inputs_of_the_wrong_kind_are_one_line(call, line):
    """A bare string of overrides was split into characters (each a confusing Hydra error);
    now every API input of the wrong kind is refused in one line saying what is allowed."""
    from pipeline import api

    with pytest.raises(TypeError) as info:
        call(api)
    assert str(info.value) == line


BADLY_BUILT = '''
class NoArgs:
    def __init__(self):
        pass


class NoStep:
    def __init__(self, settings, vehicle, sample_time_s, qp_cache=None):
        self.compile_count, self.compile_time_s = 0, 0.0


class NoSpeed:
    def __init__(self, settings, horizon, sample_time_s):
        pass

    def rollout(self, *args):
        return None
'''


@pytest.mark.parametrize(("override", "line"), [
    ("planner._target_=my_built.NoArgs",
     "config error: planner._target_='my_built.NoArgs' is invalid; allowed: a class built as "
     "Planner(settings, horizon, sample_time_s) (too many positional arguments)"),
    ("controller._target_=my_built.NoStep",
     "plug-in error: controller my_built.NoStep has no step(); allowed: a class with step() "
     "(step(observation) -> ControlStep, see pipeline.loop.controller.base)"),
    ("planner._target_=my_built.NoSpeed",
     "plug-in error: planner my_built.NoSpeed has no speed(); allowed: a class with rollout(), "
     "speed() (subclass pipeline.loop.planner.ApfPlanner)"),
], ids=["constructor", "no-step", "no-speed"])
def test_a_plugin_that_does_not_fit_the_protocol_is_refused_before_the_run(
        tmp_path, monkeypatch, make_config, override, line):
    from pipeline.errors import describe_config_error

    (tmp_path / "my_built.py").write_text(BADLY_BUILT)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("my_built", None)
    with pytest.raises((PluginOutputError, ValueError)) as info:
        _simulate(make_config, [override])
    assert describe_config_error(info.value) == line
