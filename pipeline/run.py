"""Entry point of one closed-loop run or family: ``python -m pipeline.run [hydra overrides]``.

The work is done by :func:`pipeline.studies.experiment.run_experiment` and
:func:`~pipeline.studies.experiment.run_family` (tests and notebooks call them); ``main`` wraps
them with Hydra and turns configuration errors into one line on stderr and exit code 2 (set
``HYDRA_FULL_ERROR=1`` for the full traceback).
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

import pandas as pd

from pipeline.analysis.objectives import objective_values
from pipeline.analysis.tally import Tally
from pipeline.config import CONF_DIR, register_configs, to_experiment_config
from pipeline.errors import (FolderBusyError, describe_config_error, interrupted_exit_code,
                             stop_on_signals, stopped_line)
from pipeline.store.runs import folder_lock
from pipeline.studies.experiment import RunSummary, run_experiment, run_family
from pipeline.studies.slurm import register_launcher

__all__ = ["RunSummary", "hydra_main", "main", "run_experiment", "run_family"]

log = logging.getLogger(__name__)

# Hydra composes configs in worker processes too (joblib, submitit), which import this module
register_configs()
register_launcher()


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def hydra_main(cfg: DictConfig) -> float | tuple[float, ...]:
    """Hydra task: validate, run, log where the results are; return ``tune.objectives`` (one
    float, or a tuple for several), which is what a Hydra sweeper optimizes."""
    from hydra.core.hydra_config import HydraConfig

    try:
        experiment = to_experiment_config(cfg)
        _check_targets(experiment)
    except Exception as exc:  # noqa: BLE001 - config errors become one line; others re-raise
        message = describe_config_error(exc)
        if message is None or os.environ.get("PIPELINE_USER_FULL_ERROR") == "1":
            raise
        # SystemExit passes Hydra's job wrapper untouched: one line, exit code 2
        print(message, file=sys.stderr)
        raise SystemExit(2) from None
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        with folder_lock(out_dir):
            return _run(experiment, out_dir)
    except FolderBusyError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def _run(experiment, out_dir: Path) -> float | tuple[float, ...]:
    """The run or family of :func:`hydra_main`, into ``out_dir`` (locked)."""
    objectives = experiment.tune.objectives
    if experiment.scenario.family is not None:
        table = run_family(experiment, out_dir)
        tally = Tally.of(table)
        values = objective_values(table, objectives)
        log.info("%s on %s (%d scenarios): %d collisions, %d not recovered; %s -> %s",
                 experiment.method_name, experiment.scenario.name, tally.scenarios,
                 tally.collisions, tally.not_recovered, _describe(objectives, values), out_dir)
        return values[0] if len(values) == 1 else values
    summary = run_experiment(experiment, out_dir)
    m = summary.flat()
    values = objective_values(pd.DataFrame([m]), objectives)
    log.info("%s%s on %s: min clearance %.3f m, collision %s, time to goal %s s; %s -> %s",
             "skipped (complete) " if summary.skipped else "", m["method"], m["scenario"],
             m["min_clearance_m"] if m["min_clearance_m"] is not None else float("nan"),
             m["collision"], m["time_to_goal_s"], _describe(objectives, values), out_dir)
    return values[0] if len(values) == 1 else values


def _check_targets(experiment) -> None:
    """A planner or controller of the user's own must import before anything runs (one line
    naming the key otherwise)."""
    from pipeline.validation import resolve_target

    for key, target in (("planner._target_", experiment.planner._target_),
                        ("controller._target_", experiment.controller._target_)):
        if target:
            resolve_target(key, target)


def _describe(objectives, values) -> str:
    """``mean reaction_delay_s = 0.41`` for the log (what a sweeper receives)."""
    return ", ".join(f"{o.label} = {v:.4g}" for o, v in zip(objectives, values))


def main() -> None:
    """Console entry: run Hydra; configuration errors exit 2 with one line on stderr."""
    original = os.environ.get("HYDRA_FULL_ERROR")
    user_wants_trace = original == "1"
    os.environ["PIPELINE_USER_FULL_ERROR"] = "1" if user_wants_trace else "0"
    os.environ["HYDRA_FULL_ERROR"] = "1"  # let exceptions reach us instead of Hydra's printer
    stop_on_signals()
    try:
        hydra_main()
    except KeyboardInterrupt as exc:
        # completed members and runs are kept (each written atomically); rerunning the same
        # command resumes them
        print(stopped_line(exc, "completed runs and family members"), file=sys.stderr)
        sys.exit(interrupted_exit_code(exc))
    except Exception as exc:  # noqa: BLE001 - turned into a message and an exit code
        if user_wants_trace:
            raise
        message = describe_config_error(exc)
        if message is not None:
            print(message, file=sys.stderr)
            sys.exit(2)
        if isinstance(exc, OSError) and exc.filename:
            # an output folder that cannot be made or written (a file in the way, no
            # permission, a full disk): the run wrote nothing half-way
            print(f"error: cannot write {exc.filename}: {exc.strerror or exc} (choose another "
                  "output folder with hydra.run.dir=... or hydra.sweep.dir=...)",
                  file=sys.stderr)
            sys.exit(2)
        print(f"error: {type(exc).__name__}: {exc} (set HYDRA_FULL_ERROR=1 for the traceback)",
              file=sys.stderr)
        sys.exit(1)
    finally:
        if original is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = original


if __name__ == "__main__":
    main()
