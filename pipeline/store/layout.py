"""Where everything lives under the outputs root: one owner of its layout.

:class:`OutputsLayout` reads the section names from ``conf/paths/default.yaml`` and answers
"which folder holds X" for the report, the studies' commands and the checks, so that no other
module names a section's folder. Which sections hold the runs the claims are judged on
(``make reproduce``'s), which ones are studies with results of their own, and which families
carry the model checks are properties of the layout, not lists scattered over the readers.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError

#: The layout file (section -> folder name under the outputs root).
PATHS_FILE = CONF_DIR / "paths" / "default.yaml"


@dataclass(frozen=True)
class OutputsLayout:
    """The outputs root and the folder name of each section under it (see the module
    docstring; the defaults are ``conf/paths/default.yaml``'s)."""

    root: Path
    paper: str = "paper"
    kinematic: str = "kinematic"
    kinematic_readings: str = "kinematic_readings"
    family: str = "family"
    kinematic_family: str = "kinematic_family"
    frames: str = "frames"
    apf_alone: str = "apf_alone"
    nmpc_family: str = "nmpc_family"
    peers: str = "peers"
    kinematic_peers: str = "kinematic_peers"
    pedestrians: str = "pedestrians"
    pedestrians_variants: str = "pedestrians_variants"
    ablation: str = "ablation"
    interpretations: str = "interpretations"
    multiverse: str = "multiverse"
    tune: str = "tune"
    tune_unpruned: str = "tune_unpruned"
    tune_peers: str = "tune_peers"
    member_cache: str = "member_cache"
    nmpc_check: str = "nmpc_check"
    speed: str = "speed"
    sweeps: str = "sweeps"
    commonroad: str = "commonroad"

    @classmethod
    def load(cls, root: Path, paths_file: Path = PATHS_FILE) -> OutputsLayout:
        """The layout of ``root`` with the section names of ``paths_file``."""
        import yaml

        data = yaml.safe_load(Path(paths_file).read_text()) or {}
        names = {f.name for f in fields(cls)} - {"root"}
        for key, value in data.items():
            if key not in names:
                raise ConfigError(f"paths.{key}", value, f"one of {sorted(names)}")
            if not isinstance(value, str) or not value or "/" in value or value in (".", ".."):
                raise ConfigError(f"paths.{key}", value, "a folder name (no '/')")
        return cls(Path(root), **data)

    def folder(self, section: str) -> Path:
        """The folder of ``section`` (a field name) under the root."""
        return self.root / getattr(self, section)

    @property
    def sections(self) -> tuple[str, ...]:
        """Every section's field name, in the file's order."""
        return tuple(f.name for f in fields(self) if f.name != "root")

    @property
    def canonical(self) -> tuple[str, ...]:
        """Folder names of the sections whose ``<section>/<method>`` run is a method's default
        run (``make reproduce``'s), judged before any other run of the same method."""
        return (self.paper, self.family, self.kinematic)

    @property
    def not_main_runs(self) -> tuple[str, ...]:
        """Folder names under the root that hold studies or families read by their own
        sections, never among the runs of the claims (the paper scenario, the family)."""
        return (self.sweeps, self.ablation, self.interpretations, self.multiverse, self.tune,
                self.tune_unpruned, self.tune_peers, self.member_cache, self.kinematic_readings,
                self.kinematic_family, self.frames, self.apf_alone, self.nmpc_family, self.peers,
                self.kinematic_peers,
                self.pedestrians, self.pedestrians_variants, self.nmpc_check, self.speed, self.commonroad)

    @property
    def validity_sections(self) -> tuple[str, ...]:
        """The sections whose families' model checks the validity table pools: the default
        frame's, the other frame's and the Appendix-A track's."""
        return ("family", "frames", "kinematic_family")
