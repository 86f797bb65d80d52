"""Hydra discovers launchers in the ``hydra_plugins`` namespace (and only there): this defines
the project's launchers there, ``hydra/launcher=sequential`` (the default; implementation
:mod:`pipeline.studies.sequential`) and ``hydra/launcher=slurm`` (:mod:`pipeline.studies.slurm`)."""

import pipeline.studies.sequential as _sequential
import pipeline.studies.slurm as _impl


class RobustSlurmLauncher(_impl.RobustSlurmLauncherBase):
    """``hydra/launcher=slurm``: see :mod:`pipeline.studies.slurm`."""


class SequentialLauncher(_sequential.SequentialLauncherBase):
    """``hydra/launcher=sequential`` (the default): see :mod:`pipeline.studies.sequential`."""
