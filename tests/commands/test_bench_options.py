"""Hostile class: ``python -m pipeline.bench`` options out of range.

``python -m pipeline.bench --quick --steps 0`` (or ``--repeats 0``, ``--steps -5``) measured for
15 s and then stopped with a traceback (``KeyError: 'N'``); ``--family-size 0`` and an ``--out``
that is a file were found only after the whole benchmark. Now each is one line naming the
option and its allowed range, exit 2, before anything is measured.
"""

from __future__ import annotations

import pytest

from benchmarks.command import main


@pytest.mark.parametrize("option, value, line", [
    ("--steps", "0", "error: --steps=0 is invalid; allowed: an integer in [1, 100000]"),
    ("--steps", "-5", "error: --steps=-5 is invalid; allowed: an integer in [1, 100000]"),
    ("--repeats", "0", "error: --repeats=0 is invalid; allowed: an integer in [1, 1000]"),
    ("--family-size", "0",
     "error: --family-size=0 is invalid; allowed: an integer in [1, 100000]"),
])
def test_an_option_out_of_range_is_one_line_before_any_measurement(tmp_path, capsys, option,
                                                                    value, line):
    """``python -m pipeline.bench --quick --out D --steps 0`` (and the others): exit 2 with the
    line above; nothing is written."""
    out = tmp_path / "bench"
    assert main(["--quick", "--out", str(out), option, value]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [line]
    assert not out.exists()


def test_an_out_that_is_a_file_is_one_line_before_any_measurement(tmp_path, capsys):
    """``python -m pipeline.bench --quick --out FILE``: exit 2, ``error: --out=FILE is invalid;
    allowed: a folder (new, or one the benchmark wrote before), not a file``."""
    out = tmp_path / "a_file"
    out.write_text("keep me")
    assert main(["--quick", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: --out={out} is invalid; allowed: a folder (new, or one the benchmark wrote "
        "before), not a file"]
    assert out.read_text() == "keep me"


def test_smoke_without_quick_is_one_line_before_any_measurement(tmp_path, capsys):
    """``--smoke`` shrinks the quick run only: without ``--quick`` exit 2 with one line."""
    out = tmp_path / "bench"
    assert main(["--smoke", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: --smoke is invalid without --quick; allowed: --quick --smoke"]
    assert not out.exists()
