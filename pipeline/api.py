"""A Python API for notebooks, in python-control's style: functions that take Hydra overrides
(or a composed config) and return typed results.

>>> from pipeline import api
>>> run = api.simulate(["method=improved"])                      # one run, the paper scenario
>>> run.trajectory[["time_s", "X_m", "Y_m"]].head()              # a pandas DataFrame
>>> run.metrics.value("reaction_delay_s")                        # Table 1's metrics
>>> fam = api.simulate_family(["method=baseline", "scenario.family.size=20"])
>>> ledger = api.compare(api.simulate_family(["method=improved", "scenario.family.size=20"]),
...                      {"baseline": fam})                      # the claims ledger
>>> ledger.to_frame()

Nothing is written unless ``out_dir`` is given (then the same run folders as the commands).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pipeline.analysis.claims.ledger import Ledger, family_ledger
from pipeline.analysis.metrics.criteria import compute_metrics
from pipeline.analysis.metrics.results import RunMetrics
from pipeline.analysis.settings import ClaimsConfig
from pipeline.analysis.tally import Tally
from pipeline.config import CONF_DIR, ExperimentConfig, register_configs, to_experiment_config
from pipeline.errors import plain_value

__all__ = ["FamilyResult", "RunResult", "compare", "compose", "simulate", "simulate_family",
           "warm_compiled_kernels"]

#: The runs whose compiled kernels ``warm_compiled_kernels`` puts in numba's cache, in two lanes
#: (one per core): the path frame (the default, the engine's groups on Clarabel), the fixed
#: frame, the baseline on DAQP (the tune's backend: the groups' DAQP call), the pursuit path and
#: the Appendix-A track; beside them a speed rule, whose members step outside the engine's groups
#: (pipeline/loop/lateral_group.py: the lateral MPCs' batched path frame and solves of
#: pipeline/loop/controller/lateral_rows.py and a lone member's kernels), with the ledgers' and
#: the collision oracle's kernels.
WARM_LANES: tuple[tuple[tuple[str, ...], ...], tuple[tuple[str, ...], ...]] = (
    ((), ("controller.frame=fixed",), ("method=baseline", "controller.backend=daqp"),
     ("controller.path_reference=pursuit",),
     ("experiment=kinematic", "planner=improved", "hydra.mode=RUN")),
    (("planner.velocity_planning=true",),
     ("planner.velocity_planning=true", "controller.backend=daqp")))
#: Every warm run
WARM_RUNS: tuple[tuple[str, ...], ...] = WARM_LANES[0] + WARM_LANES[1]


def warm_compiled_kernels() -> None:
    """Compile the closed loop's numba kernels into numba's on-disk cache, a few steps of each
    of :data:`WARM_RUNS` (``make install`` calls it: a first ``make reproduce`` then loads them
    in every experiment and worker instead of compiling them in each at once), and the
    ledgers' bootstrap kernel (:mod:`pipeline.analysis.claims.compiled`) and the collision
    oracle's search (:mod:`pipeline.analysis.metrics.compiled`).

    The two lanes of :data:`WARM_LANES` compile side by side where there are two cores (the
    second in a process of its own: 36 against 61 s on 2 cores, measured on an empty cache),
    then this process loads the second lane's kernels from the cache (a few seconds), so that
    it holds every kernel as one that compiled them all would."""
    import os

    if (os.cpu_count() or 1) < 2:
        _warm_lane(WARM_RUNS, True)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as side:
        beside = side.submit(_warm_lane, WARM_LANES[1], True)
        _warm_lane(WARM_LANES[0], False)
        beside.result()
    _warm_lane(WARM_LANES[1], True)


def _warm_lane(runs: tuple[tuple[str, ...], ...], statistics: bool) -> None:
    """The kernels of ``runs`` in numba's cache (:func:`~pipeline.studies.experiment.
    warm_compiled_kernels`), and with ``statistics`` the ledgers' and the collision oracle's."""
    from pipeline.studies.experiment import warm_compiled_kernels as warm

    warm([compose(list(overrides)) for overrides in runs])
    if statistics:
        from pipeline.analysis.claims.compiled import warm_kernel
        from pipeline.analysis.metrics.compiled import warm_kernel as warm_reach

        warm_kernel()  # the Hodges-Lehmann bootstrap's search (every ledger's intervals)
        warm_reach()  # the collision oracle's manoeuvres (a family member's collision)


def compose(overrides: list[str] | None = None) -> ExperimentConfig:
    """The validated configuration for Hydra ``overrides`` (as on the command line), e.g.
    ``compose(["method=baseline", "planner.rho0_m=3"])``; a bad value raises
    :class:`pipeline.errors.ConfigError` naming the key and what is allowed."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    overrides = _override_list(overrides)
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return to_experiment_config(hydra_compose(config_name="config", overrides=overrides))


@dataclass(frozen=True)
class RunResult:
    """One closed-loop run.

    Attributes
    ----------
    config : ExperimentConfig
    trajectory : pandas.DataFrame
        One row per step (columns: :func:`pipeline.loop.simulate.simulate`).
    metrics : RunMetrics
        Table 1's metrics (``metrics.value(name)``, ``metrics.to_json()``).
    termination : str
        ``goal_line``, ``max_steps`` or ``non_finite_state``.
    """

    config: ExperimentConfig
    trajectory: pd.DataFrame
    metrics: RunMetrics
    termination: str


@dataclass(frozen=True)
class FamilyResult:
    """A scenario family of one method.

    Attributes
    ----------
    config : ExperimentConfig
    table : pandas.DataFrame
        One row per member: its metrics (``family_metrics.csv``).
    tally : Tally
        Collisions, non-recoveries, fallbacks.
    """

    config: ExperimentConfig
    table: pd.DataFrame
    tally: Tally

    @property
    def method(self) -> str:
        return self.config.method_name


def _config(overrides: list[str] | None, config: ExperimentConfig | None) -> ExperimentConfig:
    if config is not None and overrides:
        raise ValueError("give overrides or a config, not both")
    if config is not None and not isinstance(config, ExperimentConfig):
        raise TypeError(f"config is a {type(config).__name__}; allowed: an ExperimentConfig "
                        "(api.compose)")
    return config if config is not None else compose(overrides)


def _override_list(overrides: object) -> list[str]:
    """``overrides`` as a list of strings; a bare string (which Python would split into
    characters) or anything else is refused in one line."""
    if overrides is None:
        return []
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, (list, tuple)) \
            or not all(isinstance(o, str) for o in overrides):
        raise TypeError(f"overrides is {plain_value(overrides)}; allowed: a list of strings "
                        "such as ['method=improved', 'planner.beta=0.5']")
    return list(overrides)


def simulate(overrides: list[str] | None = None, *, config: ExperimentConfig | None = None,
             out_dir: Path | None = None) -> RunResult:
    """Run one scenario (the paper's unless the overrides choose another).

    Parameters
    ----------
    overrides : list of str, optional
        Hydra overrides, e.g. ``["method=improved", "planner.beta=0.5"]``.
    config : ExperimentConfig, optional
        A composed configuration instead of overrides.
    out_dir : Path, optional
        Also write the run folder (config, trajectory, metrics, manifest) there.
    """
    from pipeline.loop.scenario import build_scenario
    from pipeline.loop.simulate import simulate as closed_loop
    from pipeline.studies.experiment import run_experiment, trajectory_context

    cfg = _config(overrides, config)
    if cfg.scenario.family is not None:
        raise ValueError("this configuration is a scenario family: use simulate_family")
    if out_dir is not None:
        from pipeline.store.runs import read_run

        run_experiment(cfg, Path(out_dir), resume=False)
        record = read_run(Path(out_dir))
        return RunResult(cfg, record.trajectory, record.metrics, record.info.termination)
    result = closed_loop(cfg, build_scenario(cfg.scenario))
    metrics = compute_metrics(result.table, trajectory_context(cfg), cfg.metrics)
    return RunResult(cfg, result.trajectory, metrics, result.termination)


def simulate_family(overrides: list[str] | None = None, *,
                    config: ExperimentConfig | None = None,
                    out_dir: Path | None = None) -> FamilyResult:
    """Run every member of a scenario family for one method (``scenario=family`` is added
    when the overrides choose no family); members run on ``scenario.family.n_jobs`` workers.
    Without ``out_dir`` the run folders go to a temporary folder that is removed."""
    from pipeline.studies.experiment import run_family

    if config is None:
        overrides = _override_list(overrides)
        if not any(o.startswith("scenario=") for o in overrides):
            overrides = ["scenario=family"] + overrides
    cfg = _config(overrides, config)
    if cfg.scenario.family is None:
        raise ValueError("this configuration has no scenario family (add scenario=family)")
    if out_dir is not None:
        table = run_family(cfg, Path(out_dir), progress=False)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            table = run_family(cfg, Path(tmp), progress=False)
    return FamilyResult(cfg, table, Tally.of(table))


def compare(treatment: FamilyResult, controls: dict[str, FamilyResult] | FamilyResult,
            claims=None) -> Ledger:
    """The claims ledger (C0-C5, four outcomes, Holm over the claims) of ``treatment`` against
    each control, paired by scenario; ``claims`` (a ``ClaimsConfig``) defaults to the
    treatment's own settings."""
    if isinstance(controls, FamilyResult):
        controls = {controls.method: controls}
    if not isinstance(treatment, FamilyResult):
        raise TypeError(f"api.compare: the treatment is a {type(treatment).__name__}; allowed: "
                        "a FamilyResult (api.simulate_family)")
    if not isinstance(controls, dict) or not controls:
        raise TypeError(f"api.compare: controls is {type(controls).__name__} "
                        f"{'(empty)' if isinstance(controls, dict) else ''}".rstrip()
                        + "; allowed: a FamilyResult or a dict of name -> FamilyResult")
    for name, family in controls.items():
        if not isinstance(family, FamilyResult):
            raise TypeError(f"api.compare: the control {name!r} is a {type(family).__name__}; "
                            "allowed: a FamilyResult (api.simulate_family)")
        _check_pairable(treatment, name, family)
    if claims is not None and not isinstance(claims, ClaimsConfig):
        raise TypeError(f"api.compare: claims is a {type(claims).__name__}; allowed: a "
                        "ClaimsConfig (e.g. api.compose([...]).claims) or None")
    names = tuple(controls)
    if treatment.method in names:
        raise ValueError(f"the treatment {treatment.method!r} is also a control")
    tables = {treatment.method: treatment.table, **{n: f.table for n, f in controls.items()}}
    return family_ledger(tables, claims if claims is not None else treatment.config.claims,
                         None, treatment.method, names)


def track_of(config: ExperimentConfig) -> str:
    """``kinematic`` (Appendix A's kinematic MPC) or ``lateral`` (the paper's model, and the
    peers that drive it)."""
    return "kinematic" if config.controller.kind == "kinematic_mpc" else "lateral"


def _check_pairable(treatment: FamilyResult, name: str, control: FamilyResult) -> None:
    """Refuse, in one line naming the control and the key, a control whose members are not
    the treatment's: another track, or another scenario family (its draws or its base
    scenario; ``scenario.family.n_jobs`` only says how it ran)."""
    import dataclasses

    ours, theirs = track_of(treatment.config), track_of(control.config)
    if ours != theirs:
        raise ValueError(f"api.compare: the control {name!r} is a {theirs} family and the "
                         f"treatment {treatment.method!r} a {ours} one; allowed: families of "
                         "one track (compose both with, or both without, "
                         "experiment=kinematic)")

    def scenario_fields(config: ExperimentConfig) -> dict:
        scenario = config.scenario
        family = dataclasses.asdict(scenario.family) if scenario.family is not None else {}
        family.pop("n_jobs", None)
        fields = {f"scenario.{k}": v for k, v in dataclasses.asdict(scenario).items()
                  if k != "family"}
        return {**fields, **{f"scenario.family.{k}": v for k, v in family.items()}}

    mine, other = scenario_fields(treatment.config), scenario_fields(control.config)
    for key in mine:
        if mine[key] != other.get(key):
            raise ValueError(f"api.compare: the control {name!r} ran another scenario family "
                             f"({key}={plain_value(other.get(key))} against the treatment's "
                             f"{plain_value(mine[key])}); allowed: the same family for every "
                             "method, members paired by scenario")
