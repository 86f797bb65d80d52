"""Hostile class: a multiverse space file whose settings are out of range.

``python -m pipeline.multiverse --space S`` with ``robust_share: 5`` in S ran the whole
multiverse and labelled every verdict "sensitive (100 % agree)"; ``robust_share: .nan`` never
said robust, ``fragile_share`` above ``robust_share`` said fragile where it meant robust, and
``simulation_pool: -3``, ``n_resamples: -1``, ``min_pairs: -1`` or ``family_seed: -1`` ran (or
failed only after every family had been simulated). Now each is one line naming the setting and
its allowed range, exit 2, before anything runs.
"""

from __future__ import annotations

import pytest

from pipeline.config import CONF_DIR
from pipeline.multiverse import main

QUICK = (CONF_DIR / "multiverse" / "quick.yaml").read_text()


@pytest.mark.parametrize("setting, line", [
    ("robust_share: 5",
     "config error: multiverse space: robust_share=5.0 is invalid; allowed: a number in "
     "[0.0, 1.0]"),
    ("robust_share: .nan",
     "config error: multiverse space: robust_share=nan is invalid; allowed: a finite number "
     "(not NaN or inf)"),
    ("fragile_share: 0.95",
     "config error: multiverse space: fragile_share=0.95 is invalid; allowed: a number in "
     "[0.0, 0.9]"),
    ("simulation_pool: -3",
     "config error: multiverse space: simulation_pool=-3 is invalid; allowed: an integer in "
     "[1, 100000]"),
    ("n_resamples: -1",
     "config error: multiverse space: n_resamples=-1 is invalid; allowed: an integer in "
     "[99, 1000000]"),
    ("min_pairs: -1",
     "config error: multiverse space: min_pairs=-1 is invalid; allowed: an integer in "
     "[0, 1000000]"),
    ("family_seed: -1",
     "config error: multiverse space: family_seed=-1 is invalid; allowed: an integer in "
     "[0, 2147483647]"),
])
def test_a_setting_out_of_range_is_one_line_before_anything_runs(tmp_path, capsys, setting,
                                                                 line):
    """``python -m pipeline.multiverse --space S --out D`` (S: the quick space with the setting
    above): exit 2 with the line above; D is not made."""
    key = setting.split(":")[0]
    text = "\n".join(row for row in QUICK.splitlines() if not row.startswith(key + ":"))
    space = tmp_path / "space.yaml"
    space.write_text(text + "\n" + setting + "\n")
    out = tmp_path / "out"
    assert main(["--space", str(space), "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [line]
    assert not out.exists()
