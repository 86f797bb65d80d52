"""Your own method in the ledger: a planner and a controller from outside the package (Hydra's
``_target_``, a config folder on ``hydra.searchpath``), judged against any other method."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]

PLANNER = '''
import numpy as np
from pipeline.loop.planner import ApfPlanner, ApfRollout


class StraightPlanner(ApfPlanner):
    """Straight at the goal in steps of params.step_m: no repulsion at all."""

    def rollout(self, position_m, goal_m, obstacles, vehicle_velocity_mps=None):
        step = float(self.settings.params["step_m"])
        d = np.asarray(goal_m, float) - position_m
        d = d / max(np.linalg.norm(d), 1e-9)
        path = np.array([position_m + k * step * d for k in range(self.horizon)])
        zeros = np.zeros((self.horizon - 1, 2))
        flags = np.zeros(self.horizon - 1, bool)
        return ApfRollout(path, zeros, zeros.copy(), flags, flags.copy())


class HoldSteering:
    """A controller of one's own: never steers (steering rate 0)."""

    def __init__(self, settings, vehicle, sample_time_s, qp_cache=None):
        self.compile_count, self.compile_time_s = 0, 0.0
        self.horizon = settings.horizon

    def step(self, obs):
        from pipeline.loop.controller import ControlStep
        plan = np.zeros((1, self.horizon))
        return ControlStep(np.zeros(1), plan, None, "optimal", 0, 0.0, "none", 0.0, {})
'''

METHOD = '''# @package _global_
defaults:
  - override /planner: improved
  - override /controller: lateral_mpc
planner:
  name: straight
  _target_: my_tmp_planner.StraightPlanner
  params: {step_m: 0.5}
run:
  method: straight
'''


def _run(args, env, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_a_planner_from_outside_the_package_runs_and_is_judged(tmp_path):
    """A temporary module and a config folder on hydra.searchpath: the user's planner runs on a
    10-scenario family (its rollouts have no repulsion, so the built-in APF did not run in its
    place) and the report judges it with --treatment against the baseline; claims.treatment in
    the run config does the same for the API's compare."""
    module = tmp_path / "mod"
    module.mkdir()
    (module / "my_tmp_planner.py").write_text(PLANNER)
    conf = tmp_path / "conf" / "method"
    conf.mkdir(parents=True)
    (conf / "straight.yaml").write_text(METHOD)
    env = {**os.environ, "PYTHONPATH": str(module)}
    runs = tmp_path / "runs"
    search = f"hydra.searchpath=[file://{tmp_path / 'conf'}]"
    # the user's planner on two workers (they import its module too); the baseline on one
    for method, extra in (("straight", [search]), ("baseline", [])):
        workers = 2 if method == "straight" else 1
        proc = _run(["pipeline.run", *extra, f"method={method}", "scenario=family",
                     "scenario.family.size=10", f"scenario.family.n_jobs={workers}",
                     f"hydra.run.dir={runs / 'family' / method}"], env)
        assert proc.returncode == 0, proc.stderr[-2000:]
        proc = _run(["pipeline.run", *extra, f"method={method}",
                     f"hydra.run.dir={runs / 'paper' / method}"], env)
        assert proc.returncode == 0, proc.stderr[-2000:]
    table = pd.read_csv(runs / "family" / "straight" / "family_metrics.csv")
    assert (table["repulsive_force_peak"].fillna(0) == 0).all()
    improved_like = pd.read_csv(runs / "family" / "baseline" / "family_metrics.csv")
    assert (improved_like["repulsive_force_peak"].fillna(0) > 0).any()
    proc = _run(["pipeline.report", str(runs), "--out", str(tmp_path / "report"),
                 "--treatment", "straight", "--controls", "baseline"], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    ledger = pd.read_csv(tmp_path / "report" / "tables" / "claims_ledger.csv")
    assert set(ledger["comparison"]) == {"baseline"} and len(ledger) == 7
    page = (tmp_path / "report" / "index.html").read_text()
    answer = page[page.index('id="answer"'):]
    answer = answer[:answer.index("</div>")]
    assert "(straight against the declared primary comparison" in answer \
        and re.search(r"</span> vs (<abbr [^>]*>)?baseline", answer)


def test_a_controller_from_outside_the_package_and_bad_targets(tmp_path):
    module = tmp_path / "mod"
    module.mkdir()
    (module / "my_tmp_planner.py").write_text(PLANNER)
    env = {**os.environ, "PYTHONPATH": str(module)}
    out = tmp_path / "hold"
    proc = _run(["pipeline.run", "method=improved",
                 "controller._target_=my_tmp_planner.HoldSteering", f"hydra.run.dir={out}"], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    trajectory = pd.read_csv(out / "trajectory.csv")
    assert (trajectory["steering_rate_rad_s"].dropna() == 0).all()
    assert (trajectory["delta_rad"].abs() < 1e-12).all()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["method"] == "improved"
    bad = _run(["pipeline.run", "planner._target_=no_such_module.Planner",
                f"hydra.run.dir={tmp_path / 'bad'}"], env)
    assert bad.returncode == 2 and "planner._target_" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    bad = _run(["pipeline.run", "controller._target_=not a path",
                f"hydra.run.dir={tmp_path / 'bad2'}"], env)
    assert bad.returncode == 2 and "controller._target_" in bad.stderr


def test_the_worked_example_runs_as_the_readme_says(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT / "examples" / "my_planner")}
    out = tmp_path / "side_step"
    proc = _run(["pipeline.run", "hydra.searchpath=[file://examples/my_planner/conf]",
                 "method=side_step", f"hydra.run.dir={out}"], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["method"] == "side_step" and not metrics["collision"]
    trajectory = pd.read_csv(out / "trajectory.csv")
    assert (trajectory["apf_rep_norm"].dropna() == 0).all()  # its own rollout, not the APF's
    assert trajectory["Y_m"].abs().max() > 1.0  # it stepped aside


def test_studies_compose_a_users_method_from_their_config_folder(monkeypatch):
    """The multiverse, the tuning and the NMPC check compose every run through one composer:
    a user's config folder given as hydra.searchpath reaches it (other hydra.* keys do not),
    so claims.treatment can name the user's method there too."""
    from pipeline.studies.multiverse import composer

    monkeypatch.syspath_prepend(str(ROOT / "examples" / "my_planner"))
    compose, launcher = composer([f"hydra.searchpath=[file://{ROOT / 'examples/my_planner/conf'}]",
                                  "hydra.job.chdir=false", "claims.treatment=side_step",
                                  "claims.controls=[baseline]"])
    cfg = compose(["method=side_step", "scenario=family"])
    assert launcher is None
    assert cfg.method_name == "side_step" and cfg.planner._target_ == "my_planner.SideStepPlanner"
    assert cfg.claims.treatment == "side_step" and cfg.claims.controls == ["baseline"]
