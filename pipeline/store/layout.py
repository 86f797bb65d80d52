"""Where everything lives under the outputs root: one owner of its layout.

:class:`OutputsLayout` takes the folders from the studies' registry
(:mod:`pipeline.store.study_registry`: each study names the folders it writes) and their names
from ``conf/paths/default.yaml`` (a folder is named as its key unless that file renames it), and
answers "which folder holds X" for the report, the studies' commands and the checks, so that no
other module names a section's folder. Which sections hold the runs the claims are judged on
(``make reproduce``'s), which ones are studies with results of their own, and which families
carry the model checks are properties of the registry, not lists kept by hand.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError

#: The renames file (section -> folder name under the outputs root).
PATHS_FILE = CONF_DIR / "paths" / "default.yaml"


@dataclass(frozen=True)
class OutputsLayout:
    """The outputs root and the folder name of each section under it (see the module
    docstring): ``layout.folder("tune")`` is the path, ``layout.tune`` the folder's name."""

    root: Path
    names: Mapping[str, str] = field(default_factory=dict)
    #: the sections whose ``<section>/<method>`` run is a method's default run
    claims_sections: tuple[str, ...] = ()
    #: the sections whose families' model checks the validity table pools
    validity_sections: tuple[str, ...] = ()

    @classmethod
    def load(cls, root: Path, paths_file: Path = PATHS_FILE) -> OutputsLayout:
        """The layout of ``root``: every registered study's folders, renamed as
        ``paths_file`` says."""
        import yaml

        from pipeline.store.study_registry import load_studies

        studies = load_studies()
        names = {key: key for study in studies for key in study.folders}
        data = yaml.safe_load(Path(paths_file).read_text()) or {} \
            if Path(paths_file).is_file() else {}
        for key, value in data.items():
            if key not in names:
                raise ConfigError(f"paths.{key}", value, f"one of {sorted(names)}")
            if not isinstance(value, str) or not value or "/" in value or value in (".", ".."):
                raise ConfigError(f"paths.{key}", value, "a folder name (no '/')")
        names.update(data)
        return cls(Path(root), MappingProxyType(names),
                   tuple(k for s in studies for k in s.claims_folders),
                   tuple(k for s in studies for k in s.validity_folders))

    def __getattr__(self, section: str) -> str:
        """The folder name of ``section`` (``layout.tune``)."""
        names = self.__dict__.get("names", {})
        if section in names:
            return str(names[section])
        raise AttributeError(section)

    def folder(self, section: str) -> Path:
        """The folder of ``section`` (a layout key) under the root."""
        if section not in self.names:
            raise KeyError(f"no study writes a folder {section!r}; registered: "
                           f"{', '.join(self.names)}")
        return self.root / self.names[section]

    @property
    def sections(self) -> tuple[str, ...]:
        """Every section's key, in the registry's order."""
        return tuple(self.names)

    @property
    def canonical(self) -> tuple[str, ...]:
        """Folder names of the sections whose ``<section>/<method>`` run is a method's default
        run (``make reproduce``'s), judged before any other run of the same method."""
        return tuple(self.names[k] for k in self.claims_sections)

    @property
    def not_main_runs(self) -> tuple[str, ...]:
        """Folder names under the root that hold studies or families read by their own
        sections, never among the runs of the claims (the paper scenario, the family)."""
        return tuple(name for key, name in self.names.items()
                     if key not in self.claims_sections)
