"""The studies' registry: one entry per study, read from its YAML (``conf/study/<name>.yaml``,
and ``study/<name>.yaml`` under every folder of ``$PIPELINE_STUDIES``, a study from outside the
package), never from a list kept by hand.

An entry says everything the rest of the pipeline asks of a study:

* ``name``: the subcommand (``apf-mpc <name>``) and ``help``, its line in ``apf-mpc --help``;
* how it runs: ``command`` (a module with ``add_arguments(parser)`` and ``run(args) -> int``)
  or ``experiment`` (a Hydra experiment of ``apf-mpc run``, written into ``--out``);
* ``folders``: the output folders it writes under the outputs root (layout keys; the folder's
  name is the key unless ``conf/paths`` renames it), which of them hold the runs the claims are
  judged on (``claims_folders``) and whose model checks the validity table pools
  (``validity_folders``);
* ``result``: its typed result (``module:Class`` with ``present(folder)`` and ``load(folder)``),
  which the report reads from the study's first folder;
* ``section``: the report section it feeds, a key of the report's section list, or for a study
  from outside the package a new section (``key``, ``title``, ``template`` beside the YAML,
  ``after``: the section it follows).

:class:`~pipeline.store.layout.OutputsLayout` (the folders), the command line
(:mod:`pipeline.cli`), the report's loader and its section list read these entries. Entries are
plain values; the modules they name are imported only when used.
"""

from __future__ import annotations

import copy
import functools
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import ConfigError

#: Folders of further study YAMLs (``<folder>/study/<name>.yaml``), separated by ``os.pathsep``.
ENV = "PIPELINE_STUDIES"
#: A study's name (a subcommand) and a layout key (a folder's default name).
NAME = r"[a-z][a-z0-9-]{0,39}"
KEY = r"[a-z][a-z0-9_]{0,39}"
TARGET = r"[A-Za-z_][A-Za-z0-9_.]*(:[A-Za-z_][A-Za-z0-9_]*)?"
FIELDS = ("name", "help", "command", "experiment", "folders", "claims_folders",
          "validity_folders", "result", "section", "order")


@dataclass(frozen=True)
class StudySection:
    """A report section brought by a study from outside the package: its key (the name the
    template reads the study's result under, and its anchor), its title in the contents, its
    template's file and the section it follows."""

    key: str
    title: str
    template: Path
    after: str


@dataclass(frozen=True)
class Study:
    """One registry entry (see the module docstring)."""

    name: str
    help: str
    source: Path
    command: str | None = None
    experiment: str | None = None
    folders: tuple[str, ...] = ()
    claims_folders: tuple[str, ...] = ()
    validity_folders: tuple[str, ...] = ()
    result: str | None = None
    section: str | StudySection | None = None
    order: int = 100

    @property
    def section_key(self) -> str | None:
        """The key of the report section the study feeds (None: none)."""
        return self.section.key if isinstance(self.section, StudySection) else self.section

    @property
    def folder(self) -> str | None:
        """The layout key of the folder its result is read from (its first)."""
        return self.folders[0] if self.folders else None


def study_folders(extra: tuple[Path, ...] = ()) -> tuple[Path, ...]:
    """The configuration folders whose ``study/`` holds entries: the package's, those of
    ``$PIPELINE_STUDIES``, then ``extra`` (each once)."""
    from pipeline.config import CONF_DIR

    named = tuple(Path(p) for p in os.environ.get(ENV, "").split(os.pathsep) if p.strip())
    folders: list[Path] = []
    for folder in (CONF_DIR, *named, *extra):
        if folder.resolve() not in [f.resolve() for f in folders]:
            folders.append(folder)
    return tuple(folders)


def load_studies(extra: tuple[Path, ...] = ()) -> tuple[Study, ...]:
    """Every registered study (``extra``: further folders, see :func:`study_folders`), by
    ``order`` then name; :class:`ConfigError` (one line naming the file and key) for an entry
    that cannot be one, a name or a folder taken twice."""
    found: dict[str, Study] = {}
    owners: dict[str, str] = {}
    for folder in study_folders(extra):
        for path in sorted((folder / "study").glob("*.yaml")):
            study = _read(path)
            if study.name in found:
                raise ConfigError(f"{path}: name", study.name,
                                  f"a study name not taken (by {found[study.name].source})")
            for key in study.folders:
                if key in owners:
                    raise ConfigError(f"{path}: folders", key,
                                      f"a folder no other study writes (study {owners[key]})")
                owners[key] = study.name
            found[study.name] = study
    return tuple(sorted(found.values(), key=lambda s: (s.order, s.name)))


def study_named(name: str) -> Study:
    """The registered study ``name``; :class:`ConfigError` naming the studies otherwise."""
    studies = {s.name: s for s in load_studies()}
    if name not in studies:
        raise ConfigError("study", name, "one of " + ", ".join(sorted(studies)))
    return studies[name]


def _read(path: Path) -> Study:
    import yaml

    try:
        data = copy.deepcopy(_yaml_of(path.read_text())) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(str(path), "(not YAML)", f"a YAML mapping ({exc})"[:200]) from None
    _check_keys(path, data)

    def text(key: str, pattern: str | None = None, required: bool = False) -> str | None:
        value = data.get(key)
        if value is None and not required:
            return None
        if not isinstance(value, str) or (pattern and not re.fullmatch(pattern, value)):
            raise ConfigError(f"{path}: {key}", value,
                              f"a string matching {pattern}" if pattern else "a string")
        return value

    def keys(key: str) -> tuple[str, ...]:
        value = data.get(key) or []
        if not isinstance(value, list) or not all(isinstance(v, str) and re.fullmatch(KEY, v)
                                                  for v in value):
            raise ConfigError(f"{path}: {key}", value, f"a list of folder keys ({KEY})")
        return tuple(value)

    name = text("name", NAME, required=True)
    assert name is not None
    command, experiment = text("command", TARGET), text("experiment", r"[A-Za-z0-9_/]+")
    if (command is None) == (experiment is None):
        raise ConfigError(f"{path}: command", command, "exactly one of command (a module) and "
                          "experiment (a Hydra experiment of apf-mpc run)")
    folders = keys("folders")
    for key in ("claims_folders", "validity_folders"):
        outside = set(keys(key)) - set(folders)
        if outside:
            raise ConfigError(f"{path}: {key}", sorted(outside), "folders of this study")
    order = data.get("order", 100)
    if isinstance(order, bool) or not isinstance(order, int):
        raise ConfigError(f"{path}: order", order, "an integer")
    return Study(name=name, help=text("help") or "", source=path, command=command,
                 experiment=experiment, folders=folders,
                 claims_folders=keys("claims_folders"),
                 validity_folders=keys("validity_folders"), result=text("result", TARGET),
                 section=_section(path, data.get("section")), order=order)


@functools.lru_cache(maxsize=256)
def _yaml_of(text: str) -> Any:
    """``yaml.safe_load`` of a study file's text, once per process and text (the registry is
    loaded by every command, the report and the layout: about 500 times in a test run, each
    parsing every file); the caller gets a copy, and every check runs on each read."""
    import yaml

    return yaml.safe_load(text)


def _check_keys(path: Path, data: object) -> None:
    """A mapping of known keys only (one line naming the first other key)."""
    if not isinstance(data, dict):
        raise ConfigError(str(path), type(data).__name__, "a mapping of " + ", ".join(FIELDS))
    unknown = sorted(set(data) - set(FIELDS))
    if unknown:
        raise ConfigError(f"{path}: {unknown[0]}", data[unknown[0]], "one of " + ", ".join(FIELDS))


def _section(path: Path, value: object) -> str | StudySection | None:
    """``section``: a key of the report's list, or a new section's mapping."""
    if value is None or (isinstance(value, str) and re.fullmatch(KEY, value)):
        return value
    allowed = "a section key, or a mapping of key, title, template (a file beside the " \
              "study's YAML) and after (the section it follows)"
    if not isinstance(value, dict) or set(value) != {"key", "title", "template", "after"} or \
            not all(isinstance(v, str) for v in value.values()) or \
            not re.fullmatch(KEY, value["key"]):
        raise ConfigError(f"{path}: section", value, allowed)
    template = path.parent / value["template"]
    if not template.is_file():
        raise ConfigError(f"{path}: section.template", value["template"],
                          f"a template file beside {path.name}")
    return StudySection(value["key"], value["title"], template, value["after"])


def resolve(target: str, key: str) -> object:
    """The object ``module:attribute`` (or the module) names; :class:`ConfigError` naming
    ``key`` when it does not import."""
    import importlib

    module_name, _, attribute = target.partition(":")
    try:
        module = importlib.import_module(module_name)
        return getattr(module, attribute) if attribute else module
    except (ImportError, AttributeError) as exc:
        raise ConfigError(key, target, f"an importable module[:attribute] ({exc})"[:200]) \
            from None
