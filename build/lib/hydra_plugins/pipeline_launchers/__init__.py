"""Hydra discovers launchers in the ``hydra_plugins`` namespace (and only there): this defines
the project's SLURM launcher there; the implementation is :mod:`pipeline.studies.slurm`."""

import pipeline.studies.slurm as _impl


class RobustSlurmLauncher(_impl.RobustSlurmLauncherBase):
    """``hydra/launcher=slurm``: see :mod:`pipeline.studies.slurm`."""
