"""Hostile class: an empty ``--out``.

``python -m pipeline.nmpc_check --out "$OUT"`` with ``OUT`` unset (``--out ''``) wrote
``agreement.csv``, ``summary.json`` and ``manifest.json`` into the current folder (the
repository's root), and ``python -m pipeline.report RUNS --out ''`` wrote the report there; the
tune, the multiverse, the speed check and the benchmark took it too. Now argparse refuses it:
exit 2, the usage, and the line naming ``--out`` and what is allowed, before anything runs.
"""

from __future__ import annotations

import importlib

import pytest


@pytest.mark.parametrize("command", ["tune", "multiverse", "nmpc_check", "speed_check",
                                     "bench", "report"])
def test_an_empty_out_is_refused_before_anything_runs(tmp_path, capsys, monkeypatch, command):
    """``python -m pipeline.nmpc_check --out ''`` (and the others): exit 2, its last line
    ``apf-mpc nmpc-check: error: argument --out: '' is invalid; allowed: a folder path (an
    empty one would write into the current folder)``; the current folder stays empty."""
    monkeypatch.chdir(tmp_path)
    # the benchmark's command lives in the repository's benchmarks/, out of the package
    main = importlib.import_module("benchmarks.command" if command == "bench"
                                   else f"pipeline.{command}").main
    argv = (["runs"] if command == "report" else []) + ["--out", ""]
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.endswith("error: argument --out: '' is invalid; allowed: a folder path (an "
                         "empty one would write into the current folder)"), last
    assert list(tmp_path.iterdir()) == []
