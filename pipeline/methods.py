"""The method registry: a method's label, citation, colour, order and role live in its preset
(``conf/method/<name>.yaml``, the ``run:`` block beside ``run.method``), and every reader (the
report's order and figures, the peers' section, the bench) asks this module instead of
keeping a list of its own. A run's config carries the same keys (``run.label`` ...), so a
method of one's own, from one's own config folder, brings its label with its runs.

The keys are presentation: they never enter a run's config hash
(:data:`PRESENTATION_KEYS`, left out by :meth:`pipeline.config.ExperimentConfig.config_hash`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from pipeline.config import CONF_DIR

__all__ = ["PRESENTATION_KEYS", "ROLES", "MethodInfo", "method_info", "method_registry"]

#: The ``run.*`` keys that describe a method and are no part of what a run depends on.
PRESENTATION_KEYS = ("label", "citation", "description", "color", "order", "role")
#: What a method is to the claims: the paper's treatment, a control, a peer the paper names,
#: a reference (a method for comparison only); empty: a method of one's own.
ROLES = ("", "treatment", "control", "peer", "reference")
#: The order of a method without one (after every registered method, then by name).
UNORDERED = 1000


@dataclass(frozen=True)
class MethodInfo:
    """One method as the report names it: its label (a phrase), the work it comes from, its
    colour in every figure (``#rrggbb``; empty: a stable colour from its name), its place in
    tables and legends, its role, and the presets that run it (``conf/method/<preset>.yaml``:
    one per track)."""

    name: str
    label: str = ""
    citation: str = ""
    color: str = ""
    order: int = UNORDERED
    role: str = ""
    presets: tuple[str, ...] = ()
    #: what the method is, in one sentence (the report's glossary and its hover text)
    description: str = ""

    @property
    def title(self) -> str:
        """``label (citation)``, or the label, or the name."""
        label = self.label or self.name
        return f"{label} ({self.citation})" if self.citation else label


@functools.lru_cache(maxsize=4)
def method_registry(conf_dir: Path = CONF_DIR) -> dict[str, MethodInfo]:
    """Every method the presets of ``conf_dir/method`` run, by its ``run.method`` name (a
    method with a preset per track, e.g. ``vo`` and ``vo_kinematic``, is one entry: the keys
    of its first preset in name order that gives them)."""
    import yaml

    found: dict[str, MethodInfo] = {}
    for path in sorted(Path(conf_dir, "method").glob("*.yaml")):
        run = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get("run") or {}
        name = str(run.get("method") or path.stem)
        known = found.get(name)
        if known is None:
            found[name] = MethodInfo(
                name, str(run.get("label") or ""), str(run.get("citation") or ""),
                str(run.get("color") or ""), int(run.get("order", UNORDERED)),
                str(run.get("role") or ""), (path.stem,), str(run.get("description") or ""))
        else:
            found[name] = MethodInfo(known.name, known.label or str(run.get("label") or ""),
                                     known.citation or str(run.get("citation") or ""),
                                     known.color or str(run.get("color") or ""), known.order,
                                     known.role, (*known.presets, path.stem),
                                     known.description or str(run.get("description") or ""))
    return found


def method_info(name: str, run: object | None = None) -> MethodInfo:
    """The method ``name`` as registered; ``run`` (a run's ``run`` block, e.g.
    ``cfg.run``) fills what its own config says first (a method of one's own). A name
    without either gets its name as its label."""
    known = method_registry().get(name, MethodInfo(name))
    if run is None:
        return known
    def own(key: str, default):
        value = getattr(run, key, None)
        return value if value not in (None, "", UNORDERED) else default
    return MethodInfo(name, own("label", known.label), own("citation", known.citation),
                      own("color", known.color), int(own("order", known.order)),
                      own("role", known.role), known.presets,
                      own("description", known.description))
