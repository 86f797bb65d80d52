"""SLURM through hydra-submitit-launcher, made safe for real clusters (``hydra/launcher=slurm``).

:class:`RobustSlurmLauncher` is hydra-submitit-launcher's ``SlurmLauncher`` with three changes:

* **fail fast**: every job's configuration is composed and validated (the same checks a job
  runs) before anything is submitted; an invalid one stops the sweep with exit code 2 and one
  line naming the job's overrides and the reason, and no array is submitted;
* **resume without resubmitting**: a job whose output folder already holds a complete run or
  family record of the same config hash (:func:`pipeline.store.runs.check`) is not submitted; a rerun
  of a finished sweep submits nothing and returns in seconds;
* **never hang**: instead of waiting on each task's result (which waits forever for a task that
  was cancelled while pending: it leaves no accounting record), the launcher polls every
  ``poll_s`` seconds; a task that is in a terminal state (cancelled, failed, timed out, node
  failure) or has left the queue without a result for ``lost_after_s`` seconds counts as
  unfinished, and the wait ends at the latest after ``max_wait_min`` minutes. The finished jobs
  are aggregated (``summary.csv``), the unfinished ones are listed with the command that resumes
  the sweep, and the command exits with code 2. A requeued task (``max_num_timeout``, node
  failure) is still in the queue, so it is still watched.

It does not need ``sacct``: a result file or the queue (``squeue``) says where a task stands.
"""

from __future__ import annotations

import logging
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Sequence

from hydra_plugins.hydra_submitit_launcher.config import SlurmQueueConf
from hydra_plugins.hydra_submitit_launcher.submitit_launcher import SlurmLauncher
from pipeline.errors import (
    EnvironmentFault,
    IncompleteSweepError,
    SweepConfigError,
    describe_config_error,
)

log = logging.getLogger(__name__)

#: SLURM states after which a task will not produce a result (unless requeued).
TERMINAL_FAILURES = ("CANCELLED", "FAILED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY",
                     "BOOT_FAIL", "DEADLINE", "PREEMPTED", "REVOKED")


@dataclass
class RobustSlurmConf(SlurmQueueConf):
    """``hydra/launcher=slurm``: hydra-submitit-launcher's SLURM settings plus the wait policy."""

    _target_: str = "hydra_plugins.pipeline_launchers.RobustSlurmLauncher"
    poll_s: float = 5.0
    lost_after_s: float = 30.0
    max_wait_min: Optional[float] = None


def register_launcher() -> None:
    """Register ``hydra/launcher=robust_slurm`` (the schema of ``conf/hydra/launcher/slurm``)
    in Hydra's ConfigStore; entry points call it beside ``register_configs``."""
    from hydra.core.config_store import ConfigStore

    ConfigStore.instance().store(group="hydra/launcher", name="robust_slurm",
                                 node=RobustSlurmConf, provider="pipeline")


def _job_folder(sweep_config) -> Path:
    """The output folder of one job (``hydra.sweep.dir`` / ``hydra.sweep.subdir``); the caller
    has set :class:`HydraConfig` to this job's config."""
    from omegaconf import OmegaConf

    return Path(str(OmegaConf.select(sweep_config, "hydra.sweep.dir"))) \
        / str(OmegaConf.select(sweep_config, "hydra.sweep.subdir"))


def _queue(array_ids: set[str]) -> set[str] | None:
    """Task ids (``123_4``) still in the queue, or None when squeue cannot be asked."""
    if not array_ids:
        return set()
    try:
        out = subprocess.run(["squeue", "-h", "-r", "-o", "%i", "-j", ",".join(sorted(array_ids))],
                             capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        # squeue refuses ids that left the queue entirely: then nothing of them is queued
        return set() if "Invalid job id" in out.stderr else None
    return {line.strip() for line in out.stdout.splitlines() if line.strip()}


def wait_for_tasks(jobs: list, poll_s: float, lost_after_s: float, max_wait_s: float
                   ) -> tuple[dict[int, Any], dict[int, str]]:
    """Poll submitit jobs until each has a result or is known not to produce one (bounded).

    Returns
    -------
    results : dict
        Position in ``jobs`` -> the task's return value.
    failed : dict
        Position -> why it did not finish (failed with an error, a terminal SLURM state, gone
        from the queue without a result for ``lost_after_s``, or still running at
        ``max_wait_s``).
    """
    start = time.monotonic()
    pending = dict(enumerate(jobs))
    gone_since: dict[int, float] = {}
    results: dict[int, Any] = {}
    failed: dict[int, str] = {}
    while pending:
        arrays = {str(job.job_id).split("_")[0] for job in pending.values()}
        queued = _queue(arrays)
        now = time.monotonic()
        for i, job in list(pending.items()):
            if job.paths.result_pickle.exists():
                try:
                    results[i] = job.results()[0]
                except Exception as exc:  # a failed task is reported
                    failed[i] = f"failed: {str(exc).strip().splitlines()[-1][:200]}"
                del pending[i]
                continue
            state = str(getattr(job, "state", "UNKNOWN")).split()[0].upper()
            if state.startswith(TERMINAL_FAILURES):
                failed[i] = state.lower()
                del pending[i]
                continue
            if queued is not None and str(job.job_id) not in queued:
                if now - gone_since.setdefault(i, now) >= lost_after_s:
                    failed[i] = "left the queue without a result (cancelled, killed or lost)"
                    del pending[i]
            else:
                gone_since.pop(i, None)
        if pending and now - start > max_wait_s:
            for i in list(pending):
                failed[i] = (f"still unfinished after {max_wait_s / 60:.0f} min (it may still "
                             "run; resume later)")
                del pending[i]
        if pending:
            time.sleep(poll_s)
    return results, failed


def wait_policy(params: dict) -> tuple[float, float, float]:
    """``poll_s``, ``lost_after_s`` and the longest wait in seconds (``max_wait_min``, default
    ``timeout_min`` x (``max_num_timeout`` + 1) + 10 minutes) of launcher settings."""
    poll = float(params.get("poll_s") or 5.0)
    lost = float(params.get("lost_after_s") or 30.0)
    wait = params.get("max_wait_min")
    timeouts = int(params.get("max_num_timeout") or 0) + 1
    minutes = float(wait) if wait is not None \
        else float(params.get("timeout_min") or 60) * timeouts + 10.0
    return poll, lost, 60.0 * minutes


#: The SLURM commands the launcher runs (submitit submits with sbatch, runs tasks with srun;
#: the wait asks squeue).
SLURM_COMMANDS = ("sbatch", "srun", "squeue")


def _last_line(exc: BaseException) -> str:
    """The last non-empty line of an error (sbatch's ``fatal: ...``), shortened."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[-1] if lines else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def check_slurm() -> None:
    """Refuse, before anything is submitted, a machine without SLURM: its commands missing
    from ``PATH``, or a controller that does not answer (``squeue``); one line
    (:class:`~pipeline.errors.EnvironmentFault`, exit 2) instead of submitit's traceback."""
    import shutil

    missing = [name for name in SLURM_COMMANDS if shutil.which(name) is None]
    if missing:
        raise EnvironmentFault(
            f"hydra/launcher=slurm needs SLURM, but {', '.join(missing)} "
            f"{'is' if len(missing) == 1 else 'are'} not on PATH; run on a cluster's login "
            "node, or leave out hydra/launcher=slurm to run here; nothing was submitted")
    try:
        answer = subprocess.run(["squeue", "-h", "-o", "%i", "-j", "0"], capture_output=True,
                                text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise EnvironmentFault(f"hydra/launcher=slurm: squeue did not answer ({exc}); nothing "
                               "was submitted") from None
    refused = answer.stderr.strip()
    if answer.returncode != 0 and "Invalid job id" not in refused:
        raise EnvironmentFault(f"hydra/launcher=slurm: SLURM does not answer here "
                               f"({_last_line(RuntimeError(refused or answer.stdout))}); run on "
                               "a cluster's login node, or leave out hydra/launcher=slurm; "
                               "nothing was submitted")


def resume_command() -> str:
    """The command line of this process, to rerun it."""
    executable = os.path.relpath(sys.executable) if sys.executable.startswith(os.getcwd()) \
        else sys.executable
    module = "pipeline.multiverse" if "multiverse" in (sys.argv[0] or "") else "pipeline.run"
    return " ".join(shlex.quote(a) for a in [executable, "-m", module, *sys.argv[1:]])


def executor_for(params: dict, folder: Path):
    """A submitit SLURM executor from hydra-submitit-launcher-style settings, for a machine
    that has SLURM (:func:`check_slurm`; the multiverse and the tuning submit through it too).
    Its ``map_array`` turns sbatch's refusal into one line
    (:class:`~pipeline.errors.EnvironmentFault`) instead of submitit's traceback."""
    import functools

    import submitit
    from omegaconf import OmegaConf

    from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf

    check_slurm()  # before submitit, whose executor refuses a machine without srun by a traceback
    params = {k: v for k, v in params.items() if k not in (
        "_target_", "poll_s", "lost_after_s", "max_wait_min", "submitit_folder")}
    init = {"folder": str(folder)}
    if "max_num_timeout" in params:
        init["slurm_max_num_timeout"] = params.pop("max_num_timeout")
    executor = submitit.AutoExecutor(cluster="slurm", **init)
    base = set(OmegaConf.structured(BaseQueueConf).keys())
    executor.update_parameters(**{k if k in base else f"slurm_{k}": v for k, v in params.items()
                                  if v is not None})
    submit = executor.map_array

    @functools.wraps(submit)
    def map_array(*args, **kwargs):
        try:
            return submit(*args, **kwargs)
        except Exception as exc:  # sbatch refused: one line, nothing submitted
            raise EnvironmentFault(f"hydra/launcher=slurm: sbatch refused the jobs "
                                   f"({_last_line(exc)}); nothing was submitted") from None

    executor.map_array = map_array  # type: ignore[method-assign]  # guarded, same call
    return executor


class RobustSlurmLauncherBase(SlurmLauncher):
    """See the module docstring. Parameters are those of :class:`RobustSlurmConf`."""

    def __init__(self, **params: Any) -> None:
        timeout = params.get("timeout_min")
        if timeout is not None and float(timeout) < 3:
            raise SweepConfigError(
                f"config error: hydra.launcher.timeout_min={timeout} is invalid; allowed: >= 3 "
                "(SLURM signals a task 120 s before its limit: a shorter limit kills it at once)")
        self.poll_s, self.lost_after_s, self.max_wait_s = wait_policy(params)
        for key in ("poll_s", "lost_after_s", "max_wait_min"):
            params.pop(key, None)
        super().__init__(**params)

    # --- before submission -------------------------------------------------------------------
    def _prepare(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int
                 ) -> tuple[list[tuple[int, list[str]]], list[Any]]:
        """Validate every job; split them into jobs to submit and complete ones (returned as
        finished :class:`hydra.core.utils.JobReturn`)."""
        from hydra.core.hydra_config import HydraConfig

        to_submit: list[Any] = []
        done: list[Any] = []
        previous = HydraConfig.instance().cfg
        try:
            self._split(job_overrides, initial_job_idx, to_submit, done)
        finally:
            HydraConfig.instance().cfg = previous
        return to_submit, done

    def _split(self, job_overrides, initial_job_idx: int, to_submit: list, done: list) -> None:
        from hydra.core.hydra_config import HydraConfig
        from hydra.core.utils import JobReturn, JobStatus, filter_overrides

        from pipeline.config import to_experiment_config
        from pipeline.store.manifest import check

        for offset, overrides in enumerate(job_overrides):
            idx = initial_job_idx + offset
            label = " ".join(filter_overrides(overrides)) or "(no overrides)"
            try:
                sweep_config = self.hydra_context.config_loader.load_sweep_config(
                    self.config, list(overrides))
                HydraConfig.instance().set_config(sweep_config)
                experiment = to_experiment_config(sweep_config)
            except Exception as exc:  # any composition error names the job
                reason = describe_config_error(exc) or f"{type(exc).__name__}: {exc}"
                raise SweepConfigError(f"{reason.rstrip()} (job #{idx}: {label}); nothing "
                                       "was submitted") from None
            folder = _job_folder(sweep_config)
            config_hash = experiment.config_hash()
            if check(folder, "run", config_hash) is None \
                    or check(folder, "family", config_hash, members=False) is None:
                done.append(JobReturn(overrides=list(overrides), cfg=sweep_config,
                                      working_dir=str(folder), status=JobStatus.COMPLETED,
                                      _return_value=None))
            else:
                to_submit.append((idx, list(overrides)))

    # --- submission and the bounded wait -------------------------------------------------------
    def launch(self, job_overrides: Sequence[Sequence[str]], initial_job_idx: int
               ) -> Sequence[Any]:
        from hydra.core.singleton import Singleton
        from hydra.core.utils import filter_overrides

        to_submit, done = self._prepare(job_overrides, initial_job_idx)
        if to_submit:
            check_slurm()
        log.info("submitting %d of %d jobs (%d complete already, not resubmitted)",
                 len(to_submit), len(job_overrides), len(done))
        if not to_submit:
            return done
        executor = executor_for(self.params, Path(str(self.params["submitit_folder"])))
        sweep_dir = Path(str(self.config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        job_params = []
        for idx, overrides in to_submit:
            log.info("\t#%d : %s", idx, " ".join(filter_overrides(overrides)))
            job_params.append((overrides, "hydra.sweep.dir", idx, f"job_id_for_{idx}",
                               Singleton.get_state()))
        jobs = executor.map_array(self, *zip(*job_params, strict=True))
        results, unfinished = self._wait(jobs, [o for _, o in to_submit],
                                         [i for i, _ in to_submit])
        if unfinished:
            self._report_incomplete(sweep_dir, unfinished, len(job_overrides))
        return done + results

    def _wait(self, jobs: list, overrides: list[list[str]], indices: list[int]
              ) -> tuple[list[Any], list[tuple[int, list[str], str]]]:
        results, failed = wait_for_tasks(jobs, self.poll_s, self.lost_after_s, self.max_wait_s)
        unfinished = [(indices[i], overrides[i], reason) for i, reason in sorted(failed.items())]
        return [results[i] for i in sorted(results)], unfinished

    def _report_incomplete(self, sweep_dir: Path, unfinished: list, total: int) -> None:
        from hydra.core.utils import filter_overrides

        from pipeline.studies.aggregate import aggregate
        from pipeline.studies.results.sweep import SUMMARY

        try:
            aggregate(sweep_dir, progress=False)
            summary = f"the finished jobs are in {sweep_dir / SUMMARY}"
        except FileNotFoundError:
            summary = "no job finished"
        lines = [f"error: {len(unfinished)} of {total} jobs did not finish:"]
        for idx, overrides, reason in unfinished:
            lines.append(f"  #{idx} {' '.join(filter_overrides(overrides))}: {reason}")
        command = resume_command()
        lines.append(f"{summary}; resume with the same command (complete jobs are not "
                     f"resubmitted):\n  {command}")
        raise IncompleteSweepError("\n".join(lines))
