"""Where a study's families run (``apf-mpc tune --workers``): this machine's worker processes
(joblib's reusable loky pool, the default), or the persistent workers of a Dask cluster, so that
a tune's unit of work (a rung of a trial, 0.1-1 s) reaches many machines without a SLURM job's
latency per unit (``hydra/launcher=slurm`` runs a rung as an array job: seconds to minutes).

``--workers`` takes:

- ``local``: the loky pool of ``scenario.family.n_jobs`` processes here (the default);
- ``dask-local:N``: a Dask cluster of ``N`` worker processes on this machine (one thread each;
  the same code path as a real cluster, for trying it and for the tests);
- ``dask://HOST:PORT`` (or ``tcp://HOST:PORT``): the scheduler of a running Dask cluster
  (``dask scheduler`` and ``dask worker`` started by you);
- ``dask-slurm:N``: ``N`` SLURM jobs of one Dask worker each (dask-jobqueue's
  ``SLURMCluster``, submitted with ``sbatch`` from here; each worker stays for the whole study).

One coordinator per study asks, tells and hands out each family's members by index; the workers
draw them, read back those already complete, simulate the others into the output folder (a
folder every worker must reach: on a cluster, a shared file system), write each complete
family's record there and return the metrics and tables, as joblib's workers do. The numbers
do not depend on where the members ran (tested: the same trials on a local Dask cluster as on
the loky pool).
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import ConfigError

#: what ``--workers`` accepts, for its one-line refusal
ALLOWED = ("local, dask-local:N (N worker processes here), dask://HOST:PORT (a running Dask "
           "scheduler) or dask-slurm:N (N SLURM jobs of one Dask worker each)")
#: the most workers dask-local and dask-slurm start
MAX_WORKERS = 4096


@dataclass(frozen=True)
class Workers:
    """A parsed ``--workers`` (see the module): ``kind`` is ``local``, ``dask-local``,
    ``dask`` or ``dask-slurm``; ``count`` the workers to start, ``address`` the scheduler's."""

    kind: str = "local"
    count: int | None = None
    address: str | None = None

    @classmethod
    def parse(cls, text: str) -> Workers:
        """``text`` as :class:`Workers`; :class:`ConfigError` naming ``--workers`` otherwise."""
        text = (text or "").strip()
        if text == "local":
            return cls()
        counted = re.fullmatch(r"(dask-local|dask-slurm):([0-9]+)", text)
        if counted:
            count = int(counted.group(2))
            if not 1 <= count <= MAX_WORKERS:
                raise ConfigError("--workers", text, f"{counted.group(1)}:N with N in [1, "
                                  f"{MAX_WORKERS}]")
            return cls(counted.group(1), count=count)
        address = re.fullmatch(r"(?:dask|tcp)://([A-Za-z0-9_.\-]+):([0-9]{1,5})", text)
        if address and 0 < int(address.group(2)) < 65536:
            return cls("dask", address=f"tcp://{address.group(1)}:{address.group(2)}")
        raise ConfigError("--workers", text, ALLOWED)

    @property
    def local(self) -> bool:
        """Whether the families run on this machine's loky pool."""
        return self.kind == "local"

    def describe(self) -> str:
        """In words, for the log."""
        return {"local": "this machine's worker processes",
                "dask-local": f"a Dask cluster of {self.count} worker processes here",
                "dask": f"the Dask cluster at {self.address}",
                "dask-slurm": f"{self.count} SLURM jobs of one Dask worker each"}[self.kind]


@contextlib.contextmanager
def dask_executor(workers: Workers, log_folder: Path | None = None) -> Iterator:
    """A ``concurrent.futures`` executor over the Dask cluster ``workers`` names (started
    here for ``dask-local`` and ``dask-slurm``, and stopped on leaving), its tasks never
    merged by their arguments (each member chunk runs once per submission). ``dask-slurm``'s
    jobs write their SLURM logs into ``log_folder`` (Dask's ``jobqueue.slurm.log-directory``
    where it is set; else sbatch's default, ``slurm-<job>.out`` in the current folder)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("--workers", workers.kind, "local, or install the cluster extra: "
                          "pip install '.[cluster]' (Dask distributed, dask-jobqueue)") from None
    with contextlib.ExitStack() as stack:
        if workers.kind == "dask-local":
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers.count, threads_per_worker=1, processes=True,
                dashboard_address=None))
            client = stack.enter_context(Client(cluster))
        elif workers.kind == "dask-slurm":
            import dask
            from dask_jobqueue import SLURMCluster

            # one core and one worker per job; memory, time limit, queue and account from
            # Dask's jobqueue configuration where it has them (~/.config/dask/jobqueue.yaml)
            logs = dask.config.get("jobqueue.slurm.log-directory", None) or log_folder
            cluster = stack.enter_context(SLURMCluster(
                cores=1, processes=1,
                memory=dask.config.get("jobqueue.slurm.memory", None) or "2GB",
                walltime=dask.config.get("jobqueue.slurm.walltime", None) or "24:00:00",
                log_directory=str(logs) if logs is not None else None))
            cluster.scale(jobs=workers.count)
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(workers.address, timeout="30s"))
        executor = client.get_executor(pure=False)
        try:
            yield executor
        finally:
            executor.shutdown(wait=False)
