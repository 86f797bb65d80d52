"""One safe reader for every file a user hands a study: tune and multiverse spaces, figure
styles, verify's reference tables.

Each reader refuses, in one line naming the file (:class:`InputFileError`, a
:class:`~pipeline.errors.ConfigError`: the commands print it and exit 2), what could hang it or
give a silent wrong answer:

- a path that is not a regular file (a folder, a pipe that would block the read);
- a file over a size limit (:data:`MAX_YAML_BYTES`, :data:`MAX_TABLE_BYTES`);
- text that is not UTF-8 (the byte offset named);
- a YAML document whose aliases would expand it past :data:`MAX_YAML_NODES` nodes (an "alias
  bomb": 1 KB that expands to billions of nodes); the count is taken on the parsed node graph,
  each shared node counted once per reference without building anything, so the refusal is
  immediate and its message never expands an alias;
- a YAML mapping that holds a key twice (YAML keeps the last one silently);
- a table that is empty, or that holds the same key twice (a duplicated row).
"""

from __future__ import annotations

import io
import stat
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.errors import ConfigError

#: the largest YAML settings file read (bytes): a space or a style is a few kilobytes
MAX_YAML_BYTES = 1_000_000
#: the most nodes a YAML document may hold once its aliases are expanded
MAX_YAML_NODES = 100_000
#: the largest table read (bytes): a reference table is a few kilobytes
MAX_TABLE_BYTES = 50_000_000


class InputFileError(ConfigError):
    """A user-given file that cannot be read safely; the message is one line naming it."""

    def __init__(self, path: Path | str, reason: str, allowed: str) -> None:
        ValueError.__init__(self, f"input error: {path}: {reason}; allowed: {allowed}")
        self.key, self.value, self.allowed = str(path), None, allowed
        self.path, self.reason = Path(path), reason

    def __str__(self) -> str:
        return str(self.args[0])


def read_text(path: Path, what: str, max_bytes: int) -> str:
    """The UTF-8 text of the regular file ``path`` (``what``: what it should be, for the
    message); :class:`InputFileError` for a missing path, a folder, a device or pipe, a file
    over ``max_bytes`` or text that is not UTF-8."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise InputFileError(path, "no such file", what) from None
    except OSError as exc:
        raise InputFileError(path, f"cannot be read ({exc.strerror or exc})", what) from None
    if stat.S_ISDIR(mode):
        raise InputFileError(path, "a folder, not a file", what)
    if not stat.S_ISREG(mode):
        raise InputFileError(path, "not a regular file (a device or a pipe)", what)
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise InputFileError(path, f"cannot be read ({exc.strerror or exc})", what) from None
    if len(data) > max_bytes:
        raise InputFileError(path, f"larger than {max_bytes} bytes",
                             f"{what} of at most {max_bytes} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(path, f"not UTF-8 text (byte {exc.start}: "
                             f"{data[exc.start:exc.start + 1]!r})", f"{what} in UTF-8") from None


def _expanded_size(node, limit: int) -> int:
    """How many nodes the YAML node graph ``node`` holds with every alias expanded (a node
    reached twice counts twice), stopping once past ``limit``; each distinct node is visited
    once (memoised), so a graph of a few hundred nodes is counted at once whatever it
    expands to."""
    import yaml

    sizes: dict[int, int] = {}
    # iterative post-order walk: a deep document never reaches Python's recursion limit
    stack: list[tuple[Any, bool]] = [(node, False)]
    on_path: set[int] = set()
    while stack:
        current, expanded = stack.pop()
        key = id(current)
        if key in sizes:
            continue
        if isinstance(current, yaml.SequenceNode):
            children = list(current.value)
        elif isinstance(current, yaml.MappingNode):
            children = [n for pair in current.value for n in pair]
        else:
            sizes[key] = 1
            continue
        if not expanded:
            if key in on_path:  # a recursive alias: infinite when expanded
                return limit + 1
            on_path.add(key)
            stack.append((current, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
            continue
        on_path.discard(key)
        sizes[key] = min(limit + 1, 1 + sum(sizes.get(id(c), limit + 1) for c in children))
    return sizes.get(id(node), limit + 1)


def _refuse_repeated_key(node, source: Path | str, what: str) -> None:
    """:class:`InputFileError` for a mapping that holds a key twice (YAML keeps the last one
    silently: ``replicates: 2`` then ``replicates: 3`` ran 3 replicates); each distinct node is
    visited once."""
    import yaml

    seen: set[int] = set()
    stack = [node]
    while stack:
        current = stack.pop()
        if id(current) in seen:
            continue
        seen.add(id(current))
        if isinstance(current, yaml.SequenceNode):
            stack.extend(current.value)
        elif isinstance(current, yaml.MappingNode):
            lines: dict[str, int] = {}
            for key, value in current.value:
                stack.extend((key, value))
                if not isinstance(key, yaml.ScalarNode) or key.tag == "tag:yaml.org,2002:merge":
                    continue
                line = key.start_mark.line + 1
                if key.value in lines:
                    raise InputFileError(source, f"the key {key.value!r} is there twice (lines "
                                         f"{lines[key.value]} and {line}: YAML would keep the "
                                         "last silently)", f"{what} with each key once")
                lines[key.value] = line


def load_yaml(path: Path, what: str, max_bytes: int = MAX_YAML_BYTES,
              max_nodes: int = MAX_YAML_NODES) -> Any:
    """The content of the YAML file ``path`` (None for an empty one), read safely (see the
    module docstring); invalid YAML is one line with the parser's first line."""
    path = Path(path)
    return parse_yaml(read_text(path, what, max_bytes), path, what, max_nodes)


def parse_yaml(text: str, source: Path | str, what: str,
               max_nodes: int = MAX_YAML_NODES) -> Any:
    """The content of the YAML ``text`` (``source``: the file or option it came from, for the
    message), with the alias limit of :func:`load_yaml`."""
    import yaml

    loader = yaml.SafeLoader(text)
    try:
        try:
            node = loader.get_single_node()
            if node is not None and _expanded_size(node, max_nodes) > max_nodes:
                raise InputFileError(source, f"its aliases expand to more than {max_nodes} "
                                     "nodes (an alias bomb, or a recursive alias)",
                                     f"{what} with few aliases")
            if node is not None:
                _refuse_repeated_key(node, source, what)
            return None if node is None else loader.construct_document(node)
        except yaml.YAMLError as exc:
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputFileError(source, f"not valid YAML ({first})", what) from None
    finally:
        loader.dispose()


def load_json(path: Path, what: str, max_bytes: int = MAX_TABLE_BYTES) -> Any:
    """The content of the JSON file ``path``, read safely (one line for anything wrong)."""
    import json

    text = read_text(path, what, max_bytes)
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise InputFileError(path, f"not valid JSON ({str(exc).splitlines()[0]})",
                             what) from None


def read_table(path: Path, what: str, key: tuple[str, ...] | None = None,
               max_bytes: int = MAX_TABLE_BYTES) -> pd.DataFrame:
    """The CSV table ``path``, read safely: an empty file or a table without rows, a file
    pandas cannot parse, or (with ``key``) a missing key column or a key held by two rows,
    each one line naming the file."""
    path = Path(path)
    text = read_text(path, what, max_bytes)
    if not text.strip():
        raise InputFileError(path, "empty (no header, no rows)", f"{what} with a header and "
                             "at least one row")
    try:
        table = pd.read_csv(io.StringIO(text))
    except (ValueError, pd.errors.ParserError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputFileError(path, f"not a readable CSV table ({first})", what) from None
    if table.empty:
        raise InputFileError(path, "a header without rows", f"{what} with at least one row")
    if key:
        missing = [k for k in key if k not in table.columns]
        if missing:
            raise InputFileError(path, f"no column {', '.join(missing)}",
                                 f"{what} with the key columns {', '.join(key)}")
        keys = table[list(key)].astype(str)
        repeated = keys[keys.duplicated(keep=False)]
        if len(repeated):
            first = ", ".join(repeated.iloc[0])
            count = int((keys == repeated.iloc[0]).all(axis=1).sum())
            raise InputFileError(path, f"the row {first} ({', '.join(key)}) is there {count} "
                                 "times (a duplicated row)",
                                 f"{what} with each {', '.join(key)} once")
    return table
