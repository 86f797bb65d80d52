"""One closed-loop run, family or sweep: ``apf-mpc run [hydra overrides]`` (or
``python -m pipeline.run``).

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
import pandas as pd
from omegaconf import DictConfig

from pipeline.analysis.objectives import objective_values
from pipeline.analysis.tally import Tally
from pipeline.commands import run_command, run_task
from pipeline.config import CONF_DIR, register_configs, to_experiment_config
from pipeline.errors import ConfigError
from pipeline.store.lock import folder_lock
from pipeline.store.manifest import refuse_other_record
from pipeline.store.member_cache import MemberCounts
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

    out_dir = Path(HydraConfig.get().runtime.output_dir)

    def job() -> float | tuple[float, ...]:
        try:
            _require_extras(cfg)
            experiment = to_experiment_config(cfg)
            _check_targets(experiment)
        except ConfigError:
            # refused before anything ran: the folder Hydra made for the job goes with it
            _drop_hydra_only_folder(out_dir)
            raise
        # a study's folder is never a run's (a run replaced a tune's manifest.json)
        refuse_other_record(out_dir, ("run", "family"), "hydra.run.dir")
        with folder_lock(out_dir):
            return _run(experiment, out_dir)

    # the one exception table (pipeline.commands) here too: a configuration error in a
    # launcher's worker process is one line and exit 2 as well
    return run_task(job, kept=KEPT, os_error=_cannot_write, log_to_stderr=False,
                    tracebacks=os.environ.get("PIPELINE_USER_FULL_ERROR") == "1")


#: What Hydra writes into a job's folder before the job runs.
HYDRA_ONLY = {".hydra", "run.log"}


def _drop_hydra_only_folder(out_dir: Path) -> None:
    """Remove ``out_dir`` when it holds only what Hydra wrote for this job (``.hydra/`` and
    ``run.log``): a refused configuration leaves no empty run folder behind. A folder holding
    anything else (a user's ``hydra.run.dir`` with results) is left as it is."""
    import shutil

    try:
        names = {p.name for p in out_dir.iterdir()}
        if not names <= HYDRA_ONLY or any(p.is_symlink() for p in out_dir.iterdir()):
            return
        shutil.rmtree(out_dir)
        # the parents Hydra made for it under the working folder (outputs/runs/<scenario>/
        # <planner>/), if now empty; never a folder outside the working folder
        here = Path.cwd().resolve()
        for parent in out_dir.resolve().parents:
            if parent == here or here not in parent.parents or any(parent.iterdir()):
                break
            parent.rmdir()
    except OSError:
        return


def _require_extras(cfg: DictConfig) -> None:
    """The scenario's source (``scenario.source._target_``) importable and a source, and its
    optional extra (``needs_extra``, e.g. CommonRoad's) installed: one line each otherwise,
    before any other check of the configuration."""
    from pipeline.loop.scenario import source_extra

    scenario = cfg.get("scenario")
    extra = source_extra(scenario) if scenario is not None else None
    if extra is not None:
        extra.require()


def _run(experiment, out_dir: Path) -> float | tuple[float, ...]:
    """The run or family of :func:`hydra_main`, into ``out_dir`` (locked)."""
    objectives = experiment.tune.objectives
    study = _source_study(experiment)
    if study is not None:
        return study(experiment, out_dir)
    if experiment.scenario.family is not None:
        counts = MemberCounts()
        table = run_family(experiment, out_dir, counts=counts)
        log.info("%s on %s: %s", experiment.method_name, experiment.scenario.name,
                 counts.sentence())
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


def _source_study(experiment):
    """The function that runs one scenario of the experiment's source in place of the plain
    run (its ``study``, e.g. CommonRoad's run judged by the drivability checker), or None."""
    from pipeline.loop.scenario import SOURCE_KEY, source_class
    from pipeline.validation import resolve_target

    if experiment.scenario.family is not None:
        return None
    study = getattr(source_class(experiment.scenario.source_target), "study", None)
    return resolve_target(SOURCE_KEY, study) if study else None


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
    return ", ".join(f"{o.label} = {v:.4g}" for o, v in zip(objectives, values, strict=True))


KEPT = "completed runs and family members"


def _cannot_write(exc: OSError) -> str:
    """An output folder that cannot be made or written (a file in the way, no permission, a
    full disk): the run wrote nothing half-way."""
    return (f"error: cannot write {exc.filename}: {exc.strerror or exc} (choose another "
            "output folder with hydra.run.dir=... or hydra.sweep.dir=...)")


def main() -> None:
    """``python -m pipeline.run``: ``apf-mpc run`` with the same Hydra overrides."""
    from pipeline.cli import alias

    sys.exit(alias("run"))


#: Between two runs' overrides on one command line (``apf-mpc run A... --next B...``)
NEXT_RUN = "--next"
#: The overrides that name a run's folder; each run joined by ``--next`` names its own
OWN_FOLDER_KEYS = ("hydra.run.dir", "hydra.sweep.dir")


def command(argv: list[str], prog: str = "apf-mpc run") -> int:
    """``apf-mpc run [hydra overrides] [--next hydra overrides]...``: Hydra reads ``argv`` (as
    its command line) and runs through the command layer (:func:`pipeline.commands.
    run_command`): configuration errors exit 2 with one line on stderr, an unwritable output
    folder too, Ctrl-C keeps what is complete; with ``HYDRA_FULL_ERROR=1`` every error keeps
    its traceback.

    ``--next`` starts another run in the same process, after the one before it has ended
    (its imports, compiled kernels and family workers are the earlier run's: a run of a
    60-member family costs about 5 s less than in a process of its own); each run names its
    own folder (``hydra.run.dir`` or ``hydra.sweep.dir``: Hydra's default is named by the
    second, which two runs of one process can share); the first run that does not exit 0
    ends the command with its exit code, and the runs after it are not started (as
    ``cmd1 && cmd2``)."""
    runs: list[list[str]] = [[]]
    for arg in argv:
        if arg == NEXT_RUN:
            runs.append([])
        else:
            runs[-1].append(arg)
    if len(runs) > 1 and not all(runs):
        print(f"error: {NEXT_RUN} is invalid here; allowed: between two runs' overrides "
              f"({prog} A=1 {NEXT_RUN} B=2), each run with at least one", file=sys.stderr)
        return 2
    # Hydra's default folders are named by the second the run starts: two runs of one
    # process could share one and overwrite each other's files
    unnamed = [i + 1 for i, overrides in enumerate(runs) if not any(
        o.split("=", 1)[0].lstrip("+~") in OWN_FOLDER_KEYS for o in overrides)]
    if len(runs) > 1 and unnamed:
        print(f"error: {NEXT_RUN} is invalid without each run's own folder (run "
              f"{', '.join(map(str, unnamed))} has none); allowed: hydra.run.dir=<folder> "
              "(hydra.sweep.dir=<folder> for a sweep) in every run", file=sys.stderr)
        return 2
    for overrides in runs:
        code = _one_command(overrides, prog)
        if code != 0:
            return code
    return 0


def _one_command(argv: list[str], prog: str) -> int:
    """:func:`command` of one run's overrides."""
    saved = sys.argv
    sys.argv = [saved[0] if saved else prog, *argv]
    try:
        return _hydra_command()
    except SystemExit as done:  # a configuration refusal before Hydra's job (exit 2)
        return int(done.code or 0) if not isinstance(done.code, str) else 2
    finally:
        sys.argv = saved


def _hydra_command() -> int:
    """:func:`command` on ``sys.argv``."""
    original = os.environ.get("HYDRA_FULL_ERROR")
    user_wants_trace = original == "1"
    os.environ["PIPELINE_USER_FULL_ERROR"] = "1" if user_wants_trace else "0"
    os.environ["HYDRA_FULL_ERROR"] = "1"  # let exceptions reach us instead of Hydra's printer

    try:
        code = run_command(lambda: hydra_main() and None,  # its objective is no exit code
                           kept=KEPT, os_error=_cannot_write, tracebacks=user_wants_trace,
                           log_to_stderr=False,  # Hydra logs its jobs
                           code_error=lambda exc: f"error: {type(exc).__name__}: {exc} (set "
                                                  "HYDRA_FULL_ERROR=1 for the traceback)")
    finally:
        if original is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = original
    return code


if __name__ == "__main__":
    main()
