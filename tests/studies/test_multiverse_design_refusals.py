"""The multiverse refuses designs it cannot draw and dimensions that apply to no method it runs
(issue 62, item 6): one line each, exit 2, before anything runs. ``n_specifications:
100000000`` over a handful of possible specifications once spun without a line, and
``applies_to: [nope]`` ran, changing no run."""

from __future__ import annotations

import re

import pytest

from pipeline.config import CONF_DIR
from pipeline.multiverse import main
from pipeline.studies.multiverse.design import build_design
from pipeline.studies.multiverse.space import load_space

QUICK = (CONF_DIR / "multiverse" / "quick.yaml").read_text()

#: argv edit of the quick space, exit code, key, a fragment of the allowed range
REFUSALS = [
    (("n_specifications: 16", "n_specifications: 100000000"), 2,
     "multiverse space: n_specifications", "an integer in [1, 41]"),
    (("applies_to: [improved], values: [0.25", "applies_to: [nope], values: [0.25"), 2,
     "multiverse space: dimensions[0].applies_to", "methods the multiverse runs: baseline"),
]


@pytest.mark.parametrize("edit, code, key, allowed", REFUSALS)
def test_a_design_it_cannot_draw_is_one_line_before_anything_runs(tmp_path, capsys, edit, code,
                                                                  key, allowed):
    assert edit[0] in QUICK
    space = tmp_path / "space.yaml"
    space.write_text(QUICK.replace(edit[0], edit[1]))
    out = tmp_path / "out"
    assert main(["--space", str(space), "--out", str(out)]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and allowed in err[0], err
    assert not [p for p in out.rglob("*") if p.is_file() and not p.name.startswith(".")]


def test_drawable_counts_the_distinct_specifications_build_design_draws(tmp_path):
    """Oracle: a space small enough to enumerate (2 x 2 simulation values, 3 analysis values:
    12 combinations, a pool that covers the four simulation choices) draws exactly
    ``drawable()`` distinct specifications when asked for that many."""
    small = re.sub(r"dimensions:.*", "", QUICK, flags=re.S) + (
        "dimensions:\n"
        "  - {key: planner.beta, stage: simulation, values: [0.25, 1.0]}\n"
        "  - {key: planner.rho0_m, stage: simulation, values: [3.0, 4.0]}\n"
        "  - {key: claims.estimator, stage: analysis, values: [hodges_lehmann, median, mean]}\n")
    small = small.replace("simulation_pool: 2", "simulation_pool: 64")
    path = tmp_path / "small.yaml"
    path.write_text(small.replace("n_specifications: 16", "n_specifications: 12"))
    space = load_space(path)
    assert space.drawable() == 12
    design = build_design(space)
    columns = ["planner.beta", "planner.rho0_m", "claims.estimator"]
    assert len(design) == 12 and not design.duplicated(subset=columns).any()
    path.write_text(small.replace("n_specifications: 16", "n_specifications: 13"))
    with pytest.raises(Exception, match=r"n_specifications.*\[1, 12\]"):
        load_space(path)
