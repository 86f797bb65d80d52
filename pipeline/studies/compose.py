"""One composer for every study's runs: a function from a run's overrides to its typed
configuration, with Hydra's composition done once per set of structural overrides (the
multiverse, the tuning, the NMPC and speed checks all compose through it)."""

from __future__ import annotations

import copy
import functools
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from pipeline.config import CONF_DIR


def composer(extra: list[str]):
    """A function composing one run's config (with ``extra`` overrides), and the SLURM
    launcher's settings when ``extra`` selects ``hydra/launcher=slurm`` (else None)."""
    from pipeline.config import register_configs
    from pipeline.studies.slurm import register_launcher

    register_configs()
    register_launcher()
    # Hydra's own settings stay out of a run's config, except the search path: a user's config
    # folder (their own method) must be found when composing every run
    run_overrides = [o for o in extra if not o.startswith(("hydra/", "hydra."))
                     or o.startswith("hydra.searchpath")]
    launcher = _slurm_launcher(extra)
    # Hydra composes the defaults list and merges every config file on each call, and the
    # typed schema checks every node (together most of a second); the runs of a multiverse or
    # a tuning differ mostly in values. So each set of structural overrides (config groups,
    # Hydra's own, additions, deletions) is composed and typed once, and a run's plain
    # `dotted.key=value` overrides are set on the sections of the typed config they touch
    # (OmegaConf.update, merge=True, as Hydra applies them after composing; the schema checks
    # their types: _with_section_values), or on a deep copy of it where a section cannot say
    # it alone. Anything else, a config with interpolations, or any failure takes Hydra's
    # whole path.
    typed_bases: dict[tuple, Any] = {}
    fallbacks: list[list[str]] = []
    make = _run_composer(run_overrides, typed_bases, fallbacks, {})
    # for inspection (tests): the structures Hydra composed, the runs that took its whole path
    make.typed_bases, make.fallbacks = typed_bases, fallbacks
    return make, launcher


def _slurm_launcher(extra: list[str]) -> dict | None:
    """The SLURM launcher's settings when ``extra`` selects ``hydra/launcher=slurm``."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    launcher = None
    # every choice of a Hydra group is composed, so that one that is not an option
    # (hydra/launcher=slrum, which the studies ignored and ran here) is one line
    if any(o.lstrip("+~").startswith("hydra/") for o in extra):
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            full = compose(config_name="config", overrides=extra, return_hydra_config=True)
        if any(o.startswith("hydra/launcher=slurm") for o in extra):
            settings = OmegaConf.to_container(full.hydra.launcher, resolve=False)
            launcher = settings if isinstance(settings, dict) else None
    return launcher


def _hydra_compose(overrides: list[str]):
    """The config Hydra composes with ``overrides`` (its whole path)."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=overrides)


def _typed_base(typed_bases: dict[tuple, Any], structural: tuple):
    """The typed config of a set of structural overrides, composed once (None when it has
    interpolations: a run's value could change what they read)."""
    from omegaconf import OmegaConf

    from pipeline.config import typed_config

    if structural not in typed_bases:
        cfg = _hydra_compose(list(structural))
        # an interpolation could read a key a run overrides: only plain values are shared
        plain = OmegaConf.to_container(cfg, resolve=False) \
            == OmegaConf.to_container(cfg, resolve=True)
        typed_bases[structural] = typed_config(cfg) if plain else None
    return typed_bases[structural]


def _with_values(base, values: list[str], parser, base_object=None,
                 memo: dict | None = None):
    """A copy of the typed ``base`` with the value overrides set, as the experiment config;
    None for a sweep override or any failure (Hydra's path then says what is wrong).

    With ``base_object`` (``base`` as its dataclasses, and the values they fill:
    :func:`followers_of`), only the sections the values touch are typed again
    (:func:`_with_section_values`); a deep copy of the whole typed config otherwise."""
    from omegaconf import OmegaConf

    try:
        parsed = parser.parse(values)
        if not any(o.is_sweep_override() for o in parsed):
            if base_object is not None:
                obj, followers = base_object
                cfg = _with_section_values(obj, parsed, {} if memo is None else memo,
                                           followers)
                if cfg is not None:
                    return cfg
            cfg = copy.deepcopy(base)
            for override in parsed:
                OmegaConf.update(cfg, override.key_or_group, override.value(), merge=True)
            return OmegaConf.to_object(cfg)
    except Exception:  # whatever is wrong, Hydra's path says it
        pass
    return None


#: sections kept typed by :func:`_with_section_values` (per composer)
SECTION_MEMO_SIZE = 256


def _with_section_values(base_object, parsed, memo: dict,
                         followers: Sequence[tuple[str, ...]] = ()) -> Any:
    """``base_object`` (the typed config's dataclasses) with each value override set in its
    section: the section (the dataclass holding the key) is typed by OmegaConf, the values
    set there (its type checks and conversions) and turned back into its dataclass (its range
    checks), and every dataclass above it rebuilt around it (theirs). The same config as
    setting the values on a deep copy of the whole typed config, at a fraction of its cost (a
    tuning composes a config for every trial). None when a key's section is not a dataclass
    (a dict, a list): the whole path then. ``memo`` keeps the sections already typed, keyed
    by the section object they were set on (held by the composer's bases: never reused for
    another) and the values. ``followers``: the values the schema fills from another
    section (:func:`followers_of`), filled again once the values are set.

    The whole path (None) also for a value that interpolates and for a key set both as a
    section and inside it."""
    import dataclasses

    keys = [o.key_or_group for o in parsed]
    values = [o.value() for o in parsed]
    # the whole path for what a section cannot say alone: a value that interpolates (it
    # reads the whole config), a key set both as a section and inside it (their order)
    if any("${" in repr(v) for v in values) or any(
            other.startswith(key + ".") for key in keys for other in keys):
        return None
    sections: dict[str, list[tuple[str, Any]]] = {}
    for key, value in zip(keys, values, strict=True):
        section, _, leaf = key.rpartition(".")
        sections.setdefault(section, []).append((leaf, value))
    # each top-level section rebuilt with its values, the whole config once at the end (its
    # checks across sections see every value at once, as Hydra's path does)
    tops: dict[str, Any] = {}
    fields = {f.name for f in dataclasses.fields(base_object)}
    for section, items in sections.items():
        path = section.split(".")
        if path[0] not in fields:
            return None
        chain = _chain(tops.get(path[0], getattr(base_object, path[0])), path[1:])
        if chain is None:
            return None
        rebuilt = _typed_section(chain[-1], section, items, memo,
                                 own=_section(base_object, path) is chain[-1])
        tops[path[0]] = _rebuilt(chain, path[1:], rebuilt)
    # a value the schema fills from another section when it is null (metrics.goal_tolerance_m
    # follows scenario.goal_tolerance_m) is null again, unless set here: the whole config's
    # check fills it from the values set
    for follower in followers:
        if ".".join(follower) in keys:
            continue
        if len(follower) == 1:
            tops[follower[0]] = None
            continue
        chain = [tops.get(follower[0], getattr(base_object, follower[0]))]
        for name in follower[1:-1]:
            chain.append(getattr(chain[-1], name))
        tops[follower[0]] = _rebuilt(chain, list(follower[1:-1]),
                                     dataclasses.replace(chain[-1], **{follower[-1]: None}))
    return dataclasses.replace(base_object, **tops) if tops else base_object


def _chain(top, path: list[str]) -> list | None:
    """The dataclasses from ``top`` down ``path`` (attribute names), or None when a step is
    not a dataclass field or the last is not a dataclass."""
    import dataclasses

    chain = [top]
    for name in path:
        holder = chain[-1]
        if not dataclasses.is_dataclass(holder) or name not in {
                f.name for f in dataclasses.fields(holder)}:
            return None
        chain.append(getattr(holder, name))
    if not dataclasses.is_dataclass(chain[-1]) or isinstance(chain[-1], type):
        return None
    return chain


def _typed_section(section_object, section: str, items: list[tuple[str, Any]], memo: dict,
                   own: bool) -> Any:
    """``section_object`` with ``items`` (leaf, value) set through OmegaConf (its type checks
    and conversions, then the dataclass's own checks). A section set to the same values as
    before (a tuning's family, seed and backend on every trial) is the same dataclass: typed
    once (OmegaConf takes ~3 ms a section), when it is ``own`` (a section of the base itself,
    alive as long as the composer: one rebuilt here is a new object whose id a later one may
    take)."""
    from omegaconf import OmegaConf

    key = (id(section_object), section, repr(items))
    rebuilt = memo.get(key) if own else None
    if rebuilt is None:
        rebuilt = _replaced_section(section_object, items)
    if rebuilt is None:
        node = OmegaConf.structured(section_object)
        OmegaConf.set_readonly(node, False)
        for leaf, value in items:
            OmegaConf.update(node, leaf, value, merge=True)
        rebuilt = OmegaConf.to_object(node)
        if own:
            if len(memo) >= SECTION_MEMO_SIZE:
                memo.clear()
            memo[key] = rebuilt
    return rebuilt


def _replaced_section(section_object, items: list[tuple[str, Any]]) -> Any:
    """``section_object`` with ``items`` set by ``dataclasses.replace`` (its own checks run),
    when every value already has its field's plain type (float, int, str or bool, or None
    where the field is optional), so that OmegaConf's typing would change nothing but an int
    set where a float is declared, which becomes that float here too; None otherwise
    (OmegaConf's path: its checks and conversions). About 0.1 ms against OmegaConf's 3-5 ms
    a section."""
    import dataclasses

    hints = _field_types(type(section_object))  # type: ignore[arg-type]
    values: dict[str, Any] = {}
    for leaf, value in items:
        plain = _plain_type(hints.get(leaf))
        if plain is None:
            return None
        kind, optional = plain
        if value is None and optional:
            values[leaf] = None
        elif type(value) is kind:
            values[leaf] = value
        elif kind is float and type(value) is int:
            values[leaf] = float(value)
        else:
            return None
    return dataclasses.replace(section_object, **values)


def _plain_type(hint: Any) -> tuple[type, bool] | None:
    """``(type, optional)`` of an annotation that is a plain type or an optional one."""
    import types
    import typing

    if hint in (float, int, str, bool):
        return hint, False
    args = typing.get_args(hint)
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 2 \
            and type(None) in args:
        other = args[0] if args[1] is type(None) else args[1]
        if other in (float, int, str, bool):
            return other, True
    return None


@functools.lru_cache(maxsize=64)
def _field_types(cls: type) -> dict[str, Any]:
    import typing

    return typing.get_type_hints(cls)


def _rebuilt(chain: list, path: list[str], section) -> Any:
    """The config ``chain[0]`` with the section at ``path`` (``chain``: the objects along it)
    replaced by ``section``, every dataclass above it rebuilt (their checks run again)."""
    import dataclasses

    for name, holder in zip(reversed(path), reversed(chain[:-1]), strict=True):
        section = dataclasses.replace(holder, **{name: section})
    return section


def followers_of(base, base_object) -> list[tuple[str, ...]]:
    """The paths of the values that are null in the typed config ``base`` and filled in its
    dataclasses ``base_object`` (a schema's ``__post_init__`` fills them from another
    section): a run's value overrides may change what they follow."""
    import dataclasses

    from omegaconf import DictConfig, OmegaConf

    out: list[tuple[str, ...]] = []

    def walk(node, obj, path: tuple[str, ...]) -> None:
        for f in dataclasses.fields(obj):
            if f.name not in node or OmegaConf.is_missing(node, f.name):
                continue
            raw, value = node[f.name], getattr(obj, f.name)
            if raw is None and value is not None:
                out.append(path + (f.name,))
            elif dataclasses.is_dataclass(value) and isinstance(raw, DictConfig):
                walk(raw, value, path + (f.name,))

    walk(base, base_object, ())
    return out


def _section(config, path: list[str]):
    """The object at ``path`` (attribute names) in ``config``."""
    for name in path:
        config = getattr(config, name)
    return config


_PLAIN_INT = re.compile(r"[+-]?(0|[1-9][0-9]*)")
_PLAIN_FLOAT = re.compile(r"[+-]?(((0|[1-9][0-9]*)\.[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?"
                          r"|(0|[1-9][0-9]*)[eE][+-]?[0-9]+)")
_PLAIN_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: words Hydra reads as another type than text (case-insensitive)
_NOT_TEXT = {"true", "false", "null", "inf", "nan"}


@dataclass(frozen=True)
class PlainValueOverride:
    """``dotted.key=value`` with a plain number or word as its value, read as Hydra reads it
    (:class:`OverrideReader`): the parts of Hydra's ``Override`` the composer uses."""

    key_or_group: str
    plain: Any

    def value(self) -> Any:
        return self.plain

    @staticmethod
    def is_sweep_override() -> bool:
        return False


class OverrideReader:
    """Hydra's override parser with two shortcuts (a tuning composes a config for every trial,
    and the parser takes about half a millisecond an override): an override seen before is
    read once (kept, up to ``MEMO`` of them), and ``dotted.key=value`` with a plain integer,
    decimal number or word as its value is read directly, as Hydra's grammar reads it (a
    decimal ``1.5``, ``1e-3`` as a float, ``3`` as an int, ``constant`` as text; ``true``,
    ``null``, ``inf``, ``nan``, anything quoted, bracketed or otherwise special: Hydra's
    parser)."""

    MEMO = 4096

    def __init__(self) -> None:
        from hydra.core.override_parser.overrides_parser import OverridesParser

        self.parser = OverridesParser.create()
        self.memo: dict[str, Any] = {}

    def parse(self, texts: Sequence[str]) -> list:
        out = []
        for text in texts:
            parsed = self.memo.get(text)
            if parsed is None:
                parsed = self.plain(text) or self.parser.parse_overrides([text])[0]
                if len(self.memo) >= self.MEMO:
                    self.memo.clear()
                self.memo[text] = parsed
            out.append(parsed)
        return out

    @staticmethod
    def plain(text: str) -> PlainValueOverride | None:
        """``text`` read without the parser, or None when it is not plain."""
        key, sep, value = text.partition("=")
        if not sep or not _is_value_override(text) \
                or not all(part.isidentifier() for part in key.split(".")):
            return None
        if _PLAIN_INT.fullmatch(value):
            return PlainValueOverride(key, int(value))
        if _PLAIN_FLOAT.fullmatch(value):
            return PlainValueOverride(key, float(value))
        if _PLAIN_WORD.fullmatch(value) and value.lower() not in _NOT_TEXT:
            return PlainValueOverride(key, value)
        return None


def _run_composer(run_overrides: list[str], typed_bases: dict[tuple, Any],
                  fallbacks: list[list[str]], base_objects: dict[tuple, Any]):
    """The function composing one run's config: from its typed base where it can (its
    dataclasses kept in ``base_objects``), else by Hydra's whole path (noted in
    ``fallbacks``)."""
    from omegaconf import OmegaConf

    from pipeline.config import to_experiment_config

    parser = OverrideReader()
    sections: dict = {}

    def make(overrides: list[str]):
        every = list(overrides) + run_overrides
        values = [o for o in every if _is_value_override(o)]
        structural = tuple(o for o in every if not _is_value_override(o))
        base = _typed_base(typed_bases, structural)
        if base is not None:
            if structural not in base_objects:
                try:
                    obj = OmegaConf.to_object(base)
                    base_objects[structural] = (obj, followers_of(base, obj))
                except Exception:  # a base out of range: each run says so
                    base_objects[structural] = None
            cfg = _with_values(base, values, parser, base_objects[structural], sections)
            if cfg is not None:
                return cfg
        fallbacks.append(every)
        return to_experiment_config(_hydra_compose(every))

    return make


def _is_value_override(text: str) -> bool:
    """``dotted.key=value`` without a prefix: a value Hydra applies after composing (not a
    config group, an addition, a deletion or one of Hydra's own settings)."""
    key = text.split("=", 1)[0]
    return "=" in text and "." in key and not key.startswith(("+", "~", "hydra")) \
        and not any(ch in key for ch in "/@")
