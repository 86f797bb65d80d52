"""Hostile class: verify's reference files and extra runs.

A reference with a duplicated row passed ``verify``; an empty reference CSV gave pandas'
``EmptyDataError``; a non-UTF-8 reference gave ``UnicodeDecodeError``; an extra run of the same
track and method in the outputs gave 32 false differences. Now the reference is read by the
safe loader (one line naming the file, exit 2) and an extra run is one note, "extra run X (...)
not in the reference", with the run that matches the reference compared.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from pipeline.studies.experiment import run_experiment
from pipeline.studies.verify import PAPER_FILE, verify
from pipeline.verify import main


@pytest.fixture(scope="module")
def runs(tmp_path_factory, make_config) -> Path:
    """Paper-scenario runs of improved and the baseline, and a reference made from them."""
    root = tmp_path_factory.mktemp("verify_runs")
    for method in ("improved", "baseline"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
    assert verify(root, root.parent / "reference", update=True) == []
    return root


@pytest.fixture()
def reference(runs, tmp_path) -> Path:
    folder = tmp_path / "ref"
    shutil.copytree(runs.parent / "reference", folder)
    return folder


def _lines(capsys) -> tuple[list[str], list[str]]:
    captured = capsys.readouterr()
    return captured.out.strip().splitlines(), captured.err.strip().splitlines()


def test_a_reference_with_a_duplicated_row_never_passes(runs, reference, capsys):
    """``python -m pipeline.verify RUNS REF`` with a row of REF/paper_metrics.csv twice: exit
    2, one line naming the file and the row."""
    path = reference / PAPER_FILE
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines + [lines[1]]) + "\n")
    assert main([str(runs), str(reference)]) == 2
    out, err = _lines(capsys)
    key = ", ".join(lines[1].split(",")[:2])
    assert err == [f"input error: {path}: the row {key} (track, method) is there 2 times (a "
                   f"duplicated row); allowed: a reference table ({PAPER_FILE}) with each "
                   "track, method once"]
    assert not any("OK" in line for line in out)


@pytest.mark.parametrize("text, reason", [
    (b"", "empty (no header, no rows)"),
    (b"track,method\n", "a header without rows"),
    (b"track,method\nlateral,caf\xe9\n", "not UTF-8 text (byte 24: b'\\xe9')"),
])
def test_an_empty_headless_or_non_utf8_reference_is_one_line(runs, reference, capsys, text,
                                                              reason):
    path = reference / PAPER_FILE
    path.write_bytes(text)
    assert main([str(runs), str(reference)]) == 2
    out, err = _lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"input error: {path}: {reason}; allowed: "), err
    assert out == []


def test_an_extra_run_is_one_note_not_dozens_of_differences(runs, reference, capsys,
                                                            make_config, tmp_path):
    """Another improved run on the paper scenario (another planner.beta) beside the first:
    verify compares the run that matches the reference, passes (exit 0), and names the extra
    run in one line; before, every one of its metrics was a difference."""
    outputs = tmp_path / "outputs"
    shutil.copytree(runs, outputs)
    run_experiment(make_config(["method=improved", "planner.beta=0.9"]),
                   outputs / "paper" / "improved_beta")
    assert main([str(outputs), str(reference)]) == 0
    out, err = _lines(capsys)
    assert out == ["verify: OK, matches the reference"]
    notes = [line for line in err if "extra run" in line]
    assert notes == ["paper_metrics.csv: extra run paper/improved_beta (lateral, improved) not "
                     "in the reference: another run with the same track, method; not compared"]
    # without the matching run, the other improved run is compared: its differences are real
    shutil.rmtree(outputs / "paper" / "improved")
    assert verify(outputs, reference) != []  # the extra run alone differs, its numbers listed
