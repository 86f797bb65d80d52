"""Hostile class: ``--set key=value`` on ``python -m pipeline.tune`` with a value that names a
path or is null.

``--set safety_reference=../hparams_search/improved`` passed the file check (the path left
``conf/method/``), composed the improved search space as the reference method and wrote its
runs under ``runs/hparams_search/``; ``--set 'methods=[improved, ../hparams_search/baseline]'``
was taken as a method; ``--set name=`` (null) ran a tune named ``None``. Now each is one line
naming the key and what is allowed, exit 2, before anything is written.
"""

from __future__ import annotations

import pytest

from pipeline.tune import main


@pytest.mark.parametrize("changes, line", [
    (["safety_reference=../hparams_search/improved"],
     "config error: tune.safety_reference='../hparams_search/improved' is invalid; allowed: '' "
     "(the control) or a method of conf/method/"),
    (["methods=[improved, ../hparams_search/baseline]", "matched_control=''"],
     "config error: tune.methods[1]='../hparams_search/baseline' is invalid; allowed: a method "
     "with a search space in conf/hparams_search/ (baseline, cbf_filter, dwa_kinematic, "
     "improved, mpc_dcbf, vo)"),
    (["name="],
     "config error: tune.name='' is invalid; allowed: a name of 1-100 letters, digits or _ - . "
     "+ = , (it becomes a folder name; no '/' or '..')"),
])
def test_a_path_or_null_in_set_is_one_line_before_anything_is_written(tmp_path, capsys,
                                                                       changes, line):
    """``python -m pipeline.tune --space quick --out D --set safety_reference=../hparams_search/
    improved`` (and the others): exit 2 with the line above; D is not made."""
    out = tmp_path / "tune"
    argv = ["--space", "quick", "--out", str(out)]
    for change in changes:
        argv += ["--set", change]
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().splitlines() == [line]
    assert not out.exists()
