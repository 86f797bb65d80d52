"""What a study's run overrides may touch: a study that sets keys of its runs itself (the methods
it compares, the families' seeds and sizes, the settings it tunes or varies) refuses an override
of any of them in one line naming the key, before any work starts; every other override is
applied to every run of every method (both sides of each comparison) and recorded in the
study's summary.

Without it an override came last and silently won: ``python -m pipeline.tune --space quick
scenario.family.seed=5`` made the training family the held-out one, ``method=baseline`` tuned
the baseline against itself, ``scenario.family.size=3`` ran families of 3 while the summary
said otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping

from pipeline.errors import ConfigError

#: config groups that are whole presets of a run (a method, an experiment, a search space):
#: a study composes its runs from its own; refused by every study
PRESET_GROUPS = {
    "method": "no method override: the study runs the methods it compares (choose them in "
              "its space file)",
    "run.method": "no override: each run is labelled with the method the study runs",
    "experiment": "no experiment preset: the study composes its own runs (scenario, methods, "
                  "families)",
    "hparams_search": "no search-space preset: a search space is read by make tune "
                      "(conf/hparams_search/), never composed into a run",
    "ablation": "no ablation preset: it selects a planner and a method label for every run",
    "sweep": "no sweep preset: a study's runs are its own design (make sweep runs sweeps)",
}


class ControlledOverrideError(ConfigError):
    """An override of a key the study sets itself; the message is one line naming it."""

    def __init__(self, study: str, override: str, key: str, target: str, allowed: str) -> None:
        where = "" if key == target else f" (part of {target})" \
            if key.startswith(target + ".") else f" (it sets {target})"
        ValueError.__init__(self, f"config error: {study}: the override {override} is "
                            f"refused: {key}{where} is the study's own design; allowed: "
                            f"{allowed}")
        self.key, self.value, self.allowed = key, override, allowed

    def __str__(self) -> str:
        return str(self.args[0])


def override_key(text: str) -> str | None:
    """The dotted config key (or config group) an override sets (``+a.b=1`` -> ``a.b``,
    ``~a.b`` -> ``a.b``, ``group/sub@pkg=x`` -> ``group.sub``), or None for one of Hydra's own
    settings (``hydra/launcher=slurm``, ``hydra.searchpath=...``), which no run reads."""
    key = str(text).split("=", 1)[0].strip().lstrip("+~").strip()
    key = key.split("@", 1)[0].replace("/", ".").strip(".")
    if not key or key == "hydra" or key.startswith("hydra."):
        return None
    return key


def related(key: str, controlled: str) -> bool:
    """Whether setting ``key`` changes ``controlled``: the same key, a key below it, or a key
    above it (a section or config group that replaces it whole)."""
    return key == controlled or key.startswith(controlled + ".") \
        or controlled.startswith(key + ".")


def refuse_controlled(overrides: list[str], controlled: Mapping[str, str], study: str) -> None:
    """Raise :class:`ControlledOverrideError` for the first override in ``overrides`` that sets a key of
    ``controlled`` (key -> what is allowed instead, e.g. the space setting that holds it): the
    study decides that key for its runs and an override would silently replace its design."""
    for text in overrides:
        key = override_key(text)
        if key is None:
            continue
        for target, allowed in controlled.items():
            if related(key, target):
                raise ControlledOverrideError(study, str(text), key, target, allowed)


def applied_overrides(overrides: list[str]) -> list[str]:
    """The overrides every run of a study was composed with (Hydra's own settings left out),
    as its summary records them."""
    return [str(o) for o in overrides if override_key(str(o)) is not None]
