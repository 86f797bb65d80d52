"""Hostile class: run overrides that would silently change the multiverse's design.

``python -m pipeline.multiverse --space quick method=baseline`` ran the baseline in place of
every method, and an override of a simulation dimension's key replaced every specification's
value (the dimension varied nothing). Now such an override exits 2 with one line naming the
key, before anything is written; every other override runs for every method and
``space.json`` records it.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.multiverse import main
from pipeline.studies.multiverse import load_space
from pipeline.studies.multiverse.study import controlled_keys
from pipeline.studies.overrides import refuse_controlled

QUICK = load_space(CONF_DIR / "multiverse" / "quick.yaml")
CONTROLLED = controlled_keys(QUICK)


@pytest.mark.parametrize("override, line", [
    ("method=baseline",
     "config error: multiverse: the override method=baseline is refused: method is the study's "
     "own design; allowed: no method override: the study runs the methods it compares (choose "
     "them in its space file)"),
    ("planner.beta=2",
     "config error: multiverse: the override planner.beta=2 is refused: planner.beta is the "
     "study's own design; allowed: no override: planner.beta is the multiverse dimension "
     "planner.beta (edit its values in the space file)"),
    ("vehicle.mass_kg=1600",
     "config error: multiverse: the override vehicle.mass_kg=1600 is refused: vehicle.mass_kg "
     "is the study's own design; allowed: no override: vehicle.mass_kg is the multiverse "
     "dimension vehicle.mass_and_inertia (edit its values in the space file)"),
    ("scenario.family.size=3",
     "config error: multiverse: the override scenario.family.size=3 is refused: "
     "scenario.family.size is the study's own design; allowed: no override: the multiverse sets "
     "its family's size (the space's family_size)"),
    ("planner.step_size=0.4",
     "config error: multiverse: the override planner.step_size=0.4 is refused: "
     "planner.step_size is the study's own design; allowed: no override: the matched "
     "baseline's step follows the dimension planner.step_max_m"),
])
def test_an_override_of_the_multiverses_design_is_one_line_and_writes_nothing(
        tmp_path, capsys, override, line):
    """``python -m pipeline.multiverse --space quick --out D <override>``: exit 2, the line."""
    out = tmp_path / "D"
    assert main(["--space", "quick", "--out", str(out), override]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [line]
    assert not out.exists()


@pytest.mark.parametrize("override", ["scenario.family.n_jobs=1", "controller.backend=cvxpy",
                                      "controller.horizon=12", "claims.treatment=improved",
                                      "metrics.reaction_obstacle=first_visible",
                                      "hydra/launcher=slurm"])
def test_overrides_every_method_shares_are_allowed(override):
    """The QP backend (space.json records each method's), the claims' methods and an
    analysis dimension's default (the user's value becomes the default specification) are
    the user's to choose."""
    # a refusal raises (and fails the test with the line it printed); an allowed override
    # passes through and returns nothing
    assert refuse_controlled([override], CONTROLLED, "multiverse") is None


_WORDS = st.sampled_from(["scenario", "family", "seed", "size", "appear_time_s", "planner",
                          "beta", "step_max_m", "step_size", "method", "vehicle", "mass_kg",
                          "controller", "backend", "n_jobs", "metrics", "claims"])


@settings(max_examples=300, deadline=None)
@given(parts=st.lists(_WORDS, min_size=1, max_size=3), prefix=st.sampled_from(["", "+", "~"]))
def test_an_override_is_refused_exactly_when_it_touches_a_dimension_or_the_family(parts,
                                                                                  prefix):
    """Property: refusal <=> the key is one the multiverse sets (a simulation dimension's
    config keys, the family's seed and size, the method presets), above or below one."""
    key = ".".join(parts)
    sets = {d for dim in QUICK.of("simulation") for d in dim.config_keys} | {
        "scenario.family.size", "scenario.family.seed", "planner.step_size", "method",
        "run.method", "experiment", "hparams_search", "ablation", "sweep"}
    touches = any(key == c or key.startswith(c + ".") or c.startswith(key + ".") for c in sets)
    try:
        refuse_controlled([f"{prefix}{key}=1"], CONTROLLED, "multiverse")
    except ConfigError as exc:
        assert touches and len(str(exc).splitlines()) == 1 and key in str(exc)
    else:
        assert not touches


def test_a_launcher_that_is_not_an_option_is_one_line(tmp_path, capsys):
    """``python -m pipeline.multiverse --space quick --out D hydra/launcher=slrum``: exit 2,
    ``config error: hydra/launcher='slrum' is not a known option; allowed: basic, joblib,
    local_cores, robust_slurm, sequential, slurm, submitit_local, submitit_slurm`` (the
    multiverse ignored the misspelt launcher and simulated every family here)."""
    out = tmp_path / "D"
    assert main(["--space", "quick", "--out", str(out), "hydra/launcher=slrum"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "config error: hydra/launcher='slrum' is not a known option; allowed: basic, joblib, "
        "local_cores, robust_slurm, sequential, slurm, submitit_local, submitit_slurm"]
    assert not (out / "runs").exists()
