"""Hostile class: files a study reads that could hang it or trace back.

A 1 KB YAML alias bomb hung tune, multiverse and figure styles (the refusal message expanded
every alias); non-UTF-8 space and style files gave ``UnicodeDecodeError``. Every user-given
YAML now goes through one reader (:mod:`pipeline.store.safe_load`): the aliases are counted on
the parsed node graph before anything is built, the file's size and encoding are checked, and
each refusal is one line naming the file (exit 2).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import ConfigError
from pipeline.store.safe_load import (
    MAX_YAML_BYTES,
    InputFileError,
    load_yaml,
    parse_yaml,
    read_table,
)


def bomb(levels: int, width: int = 9) -> str:
    """``levels`` lists, each holding ``width`` aliases of the one before: width**levels
    strings once expanded."""
    lines = ["a0: &a0 [" + ",".join(['"lol"'] * width) + "]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def _run(command: str, path: Path, tmp_path: Path) -> int:
    if command == "tune":
        from pipeline.tune import main

        return main(["--space", str(path), "--out", str(tmp_path / "out")])
    if command == "multiverse":
        from pipeline.multiverse import main

        return main(["--space", str(path), "--out", str(tmp_path / "out")])
    from pipeline.report import main

    runs = tmp_path / "runs"
    runs.mkdir(exist_ok=True)
    return main([str(runs), "--out", str(tmp_path / "out"), "--figure-style", str(path)])


WHAT = {"tune": "a tune space (conf/tune/<name>.yaml)",
        "multiverse": "a multiverse space (conf/multiverse/<name>.yaml)",
        "report": "a figure style (conf/report/figure_style/<name>.yaml)"}


def _line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("command", sorted(WHAT))
def test_an_alias_bomb_is_refused_without_expanding_it(tmp_path, capsys, command):
    """``python -m pipeline.tune --space bomb.yaml`` (and the multiverse's ``--space``, the
    report's ``--figure-style``): a 1 KB file of 9 levels (9**9 strings), and one of 40 levels
    (9**40: never finishes if anything expands it), each exit 2 with one short line."""
    for levels in (9, 40):
        path = tmp_path / "bomb.yaml"
        path.write_text(bomb(levels))
        assert levels > 9 or len(path.read_bytes()) < 1100
        assert _run(command, path, tmp_path) == 2
        line = _line(capsys)
        assert line.startswith(f"input error: {path}: ") and "aliases" in line
        assert "100000" in line and f"allowed: {WHAT[command]}" in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", sorted(WHAT))
def test_a_file_that_is_not_utf8_is_one_line_naming_it(tmp_path, capsys, command):
    path = tmp_path / "latin1.yaml"
    path.write_bytes("name: caf\u00e9\n".encode("latin-1"))
    assert _run(command, path, tmp_path) == 2
    line = _line(capsys)
    assert line.startswith(f"input error: {path}: ") and "UTF-8" in line and "byte 9" in line
    assert f"allowed: {WHAT[command]}" in line


@pytest.mark.parametrize("command", sorted(WHAT))
def test_a_pipe_a_folder_and_a_huge_file_are_refused_before_reading(tmp_path, capsys,
                                                                    command):
    """A named pipe would block the read forever; a folder; a file over the size limit."""
    pipe = tmp_path / "pipe.yaml"
    os.mkfifo(pipe)
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    huge = tmp_path / "huge.yaml"
    huge.write_text("# " + "x" * MAX_YAML_BYTES + "\n")
    for path, reason in ((pipe, "not a regular file (a device or a pipe)"),
                         (folder, "a folder, not a file"),
                         (huge, f"larger than {MAX_YAML_BYTES} bytes")):
        assert _run(command, path, tmp_path) == 2
        line = _line(capsys)
        assert line.startswith(f"input error: {path}: {reason}; allowed: "), line


def test_a_recursive_alias_and_a_deep_document_are_refused_or_read():
    with pytest.raises(InputFileError, match="recursive alias"):
        parse_yaml("a: &a [1, *a]\n", "x.yaml", "a space")
    # 3000 nested lists: read (the count never recurses), as PyYAML itself reads it
    deep = "[" * 300 + "]" * 300
    assert parse_yaml(deep, "x.yaml", "a space") is not None
    assert parse_yaml("", "x.yaml", "a space") is None


@settings(max_examples=200, deadline=None)
@given(widths=st.lists(st.integers(1, 6), min_size=1, max_size=6),
       limit=st.integers(5, 2000))
def test_the_alias_limit_counts_the_expanded_document_exactly(widths, limit):
    """Property: a chain of lists, level i holding widths[i] aliases of level i-1 (level 0:
    widths[0] strings), is read when its expanded node count is within the limit and refused
    otherwise (oracle: the count in closed form, a mapping node, one key and one value per
    level)."""
    lines, sizes = [], []
    for i, w in enumerate(widths):
        items = ['"x"'] * w if i == 0 else [f"*a{i - 1}"] * w
        lines.append(f"a{i}: &a{i} [{', '.join(items)}]")
        sizes.append(1 + w * (1 if i == 0 else sizes[-1]))
    expanded = 1 + sum(1 + s for s in sizes)
    text = "\n".join(lines) + "\n"
    if expanded <= limit:
        data = parse_yaml(text, "x.yaml", "a space", max_nodes=limit)
        assert len(data[f"a{len(widths) - 1}"]) == widths[-1]
    else:
        with pytest.raises(InputFileError, match=f"more than {limit} nodes"):
            parse_yaml(text, "x.yaml", "a space", max_nodes=limit)


def test_a_set_value_goes_through_the_same_limits(tmp_path):
    """``python -m pipeline.tune --space quick --set 'rungs=<bomb>'``: one line, no hang."""
    from pipeline.config import CONF_DIR
    from pipeline.studies.tune import load_tune_space

    value = "{" + bomb(40).replace("\n", ", ").rstrip(", ") + "}"
    with pytest.raises(ConfigError) as info:
        load_tune_space(CONF_DIR / "tune" / "quick.yaml", [f"rungs={value}"])
    assert str(info.value).startswith("input error: --set rungs: its aliases expand")


@pytest.mark.parametrize("text, reason", [
    ("", "empty (no header, no rows)"),
    ("track,method,x\n", "a header without rows"),
    ("track,method,x\nlateral,improved,1\nlateral,improved,2\n",
     "the row lateral, improved (track, method) is there 2 times (a duplicated row)"),
    ("track,x\nlateral,1\n", "no column method"),
])
def test_tables_empty_headless_duplicated_or_keyless_are_refused(tmp_path, text, reason):
    path = tmp_path / "t.csv"
    path.write_text(text)
    with pytest.raises(InputFileError) as info:
        read_table(path, "a table", ("track", "method"))
    assert str(info.value).startswith(f"input error: {path}: {reason}; allowed: ")
    path.write_text("track,method,x\nlateral,improved,1\nkinematic,improved,2\n")
    assert len(read_table(path, "a table", ("track", "method"))) == 2
    assert load_yaml(path, "a table") is not None  # a CSV line is a YAML string


@pytest.mark.parametrize("command", sorted(WHAT))
def test_a_key_given_twice_is_one_line_naming_it_and_its_lines(tmp_path, capsys, command):
    """``python -m pipeline.tune --space twice.yaml`` (and the multiverse's ``--space``, the
    report's ``--figure-style``) where the file sets ``dpi`` on lines 1 and 3: exit 2,
    ``input error: twice.yaml: the key 'dpi' is there twice (lines 1 and 3: YAML would keep the
    last silently); allowed: ... with each key once`` (YAML kept the last one: a space with
    ``replicates: 2`` and, further down, ``replicates: 3`` ran 3 replicates)."""
    path = tmp_path / "twice.yaml"
    path.write_text("dpi: 100\nwidth_in: 6\ndpi: 300\n")
    assert _run(command, path, tmp_path) == 2
    line = _line(capsys)
    assert line.startswith(f"input error: {path}: ") and "'dpi'" in line and "twice" in line
    assert "lines 1 and 3" in line and f"allowed: {WHAT[command]}" in line
    assert not (tmp_path / "out").exists()


def test_a_key_given_twice_in_a_set_value_or_a_nested_mapping_is_refused():
    """``--set 'objectives=[{metric: a, metric: b}]'``: one line naming ``--set objectives``;
    a merge key (``<<``) given twice is YAML's own and stays allowed."""
    with pytest.raises(InputFileError, match=r"--set objectives: the key 'metric' is there "
                       r"twice \(lines 1 and 1"):
        parse_yaml("[{metric: a, metric: b}]", "--set objectives", "a YAML value")
    assert parse_yaml("a: &a {x: 1}\nb: &b {y: 2}\nc: {<<: *a, <<: *b}\n", "f", "x")["c"] \
        == {"x": 1, "y": 2}
