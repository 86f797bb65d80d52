"""Hostile class: the report's ``--treatment`` and ``--controls``.

``python -m pipeline.report RUNS --treatment nope`` exited 0 with an empty answer. Now a
treatment or control with no runs under RUNS, a treatment among its controls, an empty or
repeated control list exit 2 with one line listing the allowed names, before anything is read
or written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.commands import CommandError
from pipeline.report import _compared_methods, main, methods_in


@pytest.fixture(scope="module")
def runs(small_reproduce) -> Path:
    """The session's :func:`small_reproduce` (read-only): the paper scenario and a family of
    improved and the baseline."""
    return small_reproduce


@pytest.mark.parametrize("options, line", [
    (["--treatment", "nope"],
     "error: --treatment nope: no runs of that method under {runs}; allowed: baseline, "
     "improved"),
    (["--treatment", "improved", "--controls", "improved"],
     "error: --treatment improved is also in --controls improved; allowed: controls other "
     "than the treatment"),
    (["--controls", "baseline,nope"],
     "error: --controls nope: no runs of that method under {runs}; allowed: baseline, "
     "improved"),
    (["--controls", ","],
     "error: --controls ',' is invalid; allowed: comma-separated method names, e.g. "
     "baseline,baseline_matched"),
    (["--controls", "baseline,baseline"],
     "error: --controls baseline,baseline names a method twice; allowed: each method once"),
    (["--treatment", ""], "error: --treatment '' is invalid; allowed: a method name"),
])
def test_a_treatment_or_control_that_judges_nothing_is_one_line(runs, tmp_path, capsys,
                                                                options, line):
    """``python -m pipeline.report RUNS --treatment nope`` and the like: exit 2, the line."""
    out = tmp_path / "report"
    assert main([str(runs), "--out", str(out), *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [line.format(runs=runs)]
    assert not out.exists()


def test_the_methods_are_read_from_run_and_family_records(runs):
    assert methods_in(runs) == {"improved", "baseline"}


_NAMES = st.text(alphabet="abcdefgimnoprstuvx_", min_size=1, max_size=12)


@settings(max_examples=200, deadline=None)
@given(treatment=st.one_of(st.none(), _NAMES),
       controls=st.one_of(st.none(), st.lists(_NAMES, min_size=1, max_size=3)))
def test_accepted_exactly_when_every_name_has_runs_and_none_repeats(runs, treatment, controls):
    """Property (oracle: the rules written out): accepted <=> every name given has runs, no
    control repeats and the treatment is not a control."""
    args = argparse.Namespace(runs=runs, treatment=treatment,
                              controls=None if controls is None else ",".join(controls))
    known = {"improved", "baseline"}
    given_names = ([treatment] if treatment is not None else []) + list(controls or [])
    ok = all(n in known for n in given_names) and len(set(controls or [])) == len(
        controls or []) and treatment not in (controls or [])
    try:
        assert _compared_methods(args) == tuple(controls or ())
    except CommandError as exc:
        assert not ok and len(str(exc).splitlines()) == 1
    else:
        assert ok
