"""Reference results: the paper-scenario numbers of every method and track match
reports/reference/ (the default `make reproduce`); the full check with the family is slow."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.studies.experiment import run_experiment
from pipeline.studies.verify import verify

REFERENCE = Path(__file__).resolve().parents[2] / "reports" / "reference"
METHODS = ("baseline", "baseline_matched", "improved", "velocity_aware", "mpc_no_apf",
           "apf_pursuit")


def paper_runs(root: Path, make_config) -> None:
    for method in METHODS:
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
    # the Appendix-A track as experiment=kinematic runs it (its baseline: the printed formula)
    for planner in ("baseline_printed", "baseline_matched", "improved", "velocity_aware",
                    "mpc_no_apf"):
        run_experiment(make_config(["experiment=kinematic", f"planner={planner}"]),
                       root / "kinematic" / planner)


@pytest.fixture(scope="module")
def paper_root(tmp_path_factory, make_config):
    """The paper-scenario runs of every method and track, made once for this module."""
    root = tmp_path_factory.mktemp("reference_runs")
    paper_runs(root, make_config)
    return root


def test_paper_scenario_matches_reference(paper_root):
    assert verify(paper_root, REFERENCE) == []


def test_verify_reports_a_changed_number(paper_root, tmp_path):
    reference = tmp_path / "ref"
    reference.mkdir()
    text = (REFERENCE / "paper_metrics.csv").read_text().splitlines()
    header = text[0].split(",")
    row = text[1].split(",")
    column = header.index("min_clearance_m")
    row[column] = str(float(row[column]) + 0.01)
    (reference / "paper_metrics.csv").write_text("\n".join([text[0], ",".join(row)]
                                                           + text[2:]) + "\n")
    problems = verify(paper_root, reference)
    assert len(problems) == 1 and "min_clearance_m" in problems[0]
    # rows are matched by (track, method): the reference in another order is no difference
    (reference / "paper_metrics.csv").write_text("\n".join([text[0]] + text[1:][::-1]) + "\n")
    assert verify(paper_root, reference) == []
    # a row missing from the rerun is named by its key
    extra = text[1].split(",")
    extra[1] = "someone_else"
    (reference / "paper_metrics.csv").write_text("\n".join(text + [",".join(extra)]) + "\n")
    assert verify(paper_root, reference) == [f"paper_metrics.csv: row {extra[0]}, someone_else is "
                                           "in the reference, not in the rerun"]


@pytest.mark.slow
def test_full_reproduction_matches_reference(tmp_path):
    """``make experiment`` into a temporary folder (every experiment ``make reproduce`` runs)
    gives the reference's numbers and ledgers. Nothing less than its whole set of runs can:
    the ledgers' answer-wide Holm counts every comparison the answer makes (the APF alone,
    the peers, the Appendix-A track), so a subset of the runs has other Holm p-values."""
    import subprocess

    from pipeline.verify import report_ledgers

    repo = Path(__file__).resolve().parents[2]
    made = subprocess.run(["make", "--no-print-directory", "experiment", f"RUNS={tmp_path}"],
                          cwd=repo, capture_output=True, text=True, timeout=3600)
    assert made.returncode == 0, made.stdout[-2000:] + made.stderr[-2000:]
    assert verify(tmp_path, REFERENCE, ledgers=report_ledgers(tmp_path)) == []
    assert (REFERENCE / "claims_ledger.csv").is_file()
