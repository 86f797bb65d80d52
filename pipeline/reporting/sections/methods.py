"""What every page carries: the rules from numbers to outcomes with each claim's margin, every
metric's definition, the interpretation register with the values the runs used, and the
provenance (command, commit, packages, machine)."""

from __future__ import annotations

import datetime as dt
import importlib.metadata
import os
import platform
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from markupsafe import Markup, escape

from pipeline.analysis.claims import ALL_CLAIMS, OUTCOME_RULE, SINGLE_RULE, Claim, claims_of
from pipeline.config import INTERPRETATION_REGISTER, ClaimsConfig
from pipeline.numerics import numerical_kernels

PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "numba", "control", "cvxpy", "clarabel",
            "daqp", "optuna", "hydra-core", "omegaconf", "jinja2")


@dataclass(frozen=True)
class Provenance:
    """Command, git commit and dirty flag (the project's tracked files modified; generated
    folders and untracked files do not count), package versions, date and machine."""

    command: str
    git_commit: str
    git_dirty: bool
    python: str
    packages: dict[str, str]
    date_utc: str
    machine: str
    #: the tracked files modified since the commit (at most :data:`MODIFIED_SHOWN` of them)
    modified: tuple[str, ...] = ()
    #: how many tracked files were modified in all
    n_modified: int = 0


@dataclass(frozen=True)
class MethodsSection:
    """The rules, the margins and the claims' definitions, the metrics' definitions, the
    register, the provenance."""

    family_rule: str
    verdict_rule: str
    margins: tuple[dict, ...]
    claim_defs: tuple[Claim, ...]
    metrics_doc: tuple[Markup, ...]
    register: tuple[dict, ...]
    prov: Provenance


#: how many modified tracked files provenance names
MODIFIED_SHOWN = 10


def tracked_changes(porcelain: str) -> tuple[str, ...]:
    """The paths of ``git status --porcelain --untracked-files=no``'s lines (a rename's new
    name); untracked files (``??``) never count: a generated folder is not a change to the
    project."""
    paths = []
    for line in porcelain.splitlines():
        parts = line.strip().split(maxsplit=1)
        if len(parts) < 2 or parts[0] in ("??", "!!"):
            continue
        paths.append(parts[1].split(" -> ")[-1].strip('"'))
    return tuple(paths)


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance(command: str) -> Provenance:
    """Command, git commit and dirty flag, package versions, date and machine (with the numerical
    kernels in effect, :func:`pipeline.numerics.numerical_kernels`)."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    status = _git("status", "--porcelain", "--untracked-files=no")
    changed = tracked_changes(status) if status != "unknown" else ()
    return Provenance(command, _git("rev-parse", "HEAD"), bool(changed),
                      sys.version.split()[0], versions,
                      dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
                      f"{platform.system()} {platform.machine()}, {os.cpu_count()} cores; kernels: "
                      + ", ".join(f"{name} {value}" for name, value in numerical_kernels().items()),
                      changed[:MODIFIED_SHOWN], len(changed))


#: What the register shows for a key a run's settings do not have (a key of another controller
#: kind: pure pursuit has no half-planes).
NOT_A_KEY = "n/a (not a key of this run's settings)"


class _Absent:
    """A key a run's settings do not have (not a key of its controller kind's schema)."""


def _lookup(config: dict, dotted: str):
    node = config
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return _Absent()
        node = node[part]
    return node


def register_value(value: object) -> str:
    """A config value as the register's "used" column shows it: a claim catalogue (a mapping
    of entries with a margin) as each claim's margin, a whole config section (a vehicle, a
    controller) by its name, any other value as it prints."""
    if isinstance(value, dict) and value and all(
            isinstance(v, dict) and "margin" in v for v in value.values()):
        return ", ".join(f"{k} {v['margin']}" for k, v in value.items())
    if isinstance(value, dict) and "name" in value:
        return str(value["name"])
    if isinstance(value, _Absent):
        return NOT_A_KEY
    return "null (not set)" if value is None else str(value)


def register_rows(configs_by_method: dict[str, dict]) -> list[dict]:
    """Interpretation register with the value each method's run used."""
    rows = []
    for entry in INTERPRETATION_REGISTER:
        keys = [k.strip() for k in entry.config_key.split(",")]
        # the value each run used, one line per distinct value ("all runs" when they agree)
        groups: dict[str, list[str]] = {}
        for method, config in configs_by_method.items():
            values = [register_value(_lookup(config, k)) for k in keys]
            # a run whose settings have none of the keys (pure pursuit's half-planes): once
            value = NOT_A_KEY if set(values) == {NOT_A_KEY} else "; ".join(values)
            groups.setdefault(value, []).append(method)
        used = [("all runs" if len(groups) == 1 else ", ".join(methods), value)
                for value, methods in groups.items()]
        rows.append({"topic": entry.topic, "paper says": entry.paper_says,
                     "default reading": entry.default, "alternatives": entry.alternatives,
                     "config key": entry.config_key, "used": used})
    return rows


def metrics_doc() -> list[Markup]:
    """Bullet paragraphs of the metric definitions (from :mod:`pipeline.analysis.metrics`);
    the docstring's **Name** becomes bold, everything else is escaped text."""
    import pipeline.analysis.metrics as metrics_module

    doc = metrics_module.__doc__ or ""
    bullets: list[str] = []
    current: list[str] = []
    for line in doc.splitlines():
        if line.startswith("* "):
            if current:
                bullets.append(" ".join(current))
            current = [line[2:].strip()]
        elif current and line.strip():
            current.append(line.strip())
        elif current:
            bullets.append(" ".join(current))
            current = []
    if current:
        bullets.append(" ".join(current))
    return [Markup(re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>",
                          str(escape(_plain(b))))) for b in bullets]


def _plain(text: str) -> str:
    """A docstring's reStructuredText as plain words for the page: ``code`` unquoted and a
    cross-reference (``:func:`pkg.mod.name```, ``:class:`~pkg.Name```) reduced to its last
    name (the page once showed the raw markup)."""
    text = re.sub(r":(?:class|func|mod|meth|data|attr):`~?([^`]+)`",
                  lambda m: m.group(1).rsplit(".", 1)[-1], text)
    return text.replace("``", "")


def methods_section(cfg: ClaimsConfig | None, configs_by_method: dict[str, dict],
                    command: str) -> MethodsSection:
    """The section; no margins listed when no run carries claims settings (a sweep-only
    page)."""
    from pipeline.reporting.format import fmt

    claims = claims_of(cfg) if cfg is not None else ALL_CLAIMS
    margins = tuple({"claim": c.claim_id, "margin": fmt(cfg.margins[c.claim_id]),
                     "reason": cfg.margin_reasons[c.claim_id]} for c in claims) \
        if cfg is not None else ()
    return MethodsSection(OUTCOME_RULE, SINGLE_RULE, margins, tuple(claims),
                          tuple(metrics_doc()), tuple(register_rows(configs_by_method)),
                          provenance(command))
