"""Hostile class: run overrides that would silently change the tune's own design.

``python -m pipeline.tune --space quick --out D scenario.family.seed=5`` made the training family
the held-out one, ``method=baseline`` tuned the baseline against itself and
``scenario.family.size=3`` ran families of 3 while ``summary.json`` said otherwise. Now an
override of anything the tune sets (its methods, its families' seeds and sizes, its QP backend,
the settings it tunes, presets that set them) exits 2 with one line naming the key, before
anything is written; every other override runs on both sides and ``summary.json`` records it.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.config import CONF_DIR
from pipeline.errors import ConfigError
from pipeline.studies.overrides import override_key, refuse_controlled, related
from pipeline.studies.tune import load_tune_space
from pipeline.studies.tune.space import search_space
from pipeline.studies.tune.study import controlled_keys
from pipeline.tune import main

QUICK = load_tune_space(CONF_DIR / "tune" / "quick.yaml")
SPACES = {m: search_space(m) for m in QUICK.methods}
CONTROLLED = controlled_keys(QUICK, SPACES)


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


#: The refusal table of ``apf-mpc tune``'s design keys: (override, the key it names, a
#: fragment of what is allowed); never the whole sentence.
DESIGN_REFUSALS = [
    ("scenario.family.seed=5", "scenario.family.seed", "training_seed"),
    ("method=baseline", "method", "choose them in its space file"),
    ("scenario.family.size=3", "scenario.family.size", "training_size"),
    ("planner.beta=0.5", "planner.beta", "planner.beta is tuned"),
    ("controller.backend=cvxpy", "controller.backend", "heldout_backend"),
]


@pytest.mark.parametrize("override, key, allowed", DESIGN_REFUSALS)
def test_an_override_of_the_tunes_design_is_one_line_and_writes_nothing(tmp_path, capsys,
                                                                       override, key, allowed):
    """``apf-mpc tune --space quick --out D <override>``: exit 2, one line naming the override,
    the key and what is allowed; nothing written."""
    out = tmp_path / "D"
    assert main(["--space", "quick", "--out", str(out), override]) == 2
    line = _one_line(capsys)
    assert f"the override {override} is refused: {key} is the study's own design" in line
    assert allowed in line.split("allowed:", 1)[1]
    assert not out.exists()


@pytest.mark.parametrize("override, key", [
    ("scenario.family={seed: 5}", "scenario.family (it sets scenario.family.seed)"),
    ("scenario=paper_sudden_obstacle", "scenario (it sets scenario.family.seed)"),
    ("+scenario.family.seed=5", "scenario.family.seed"),
    ("~scenario.family.size", "scenario.family.size"),
    ("planner=baseline", "planner (it sets planner.step_size)"),
    ("experiment=kinematic", "experiment"),
    ("ablation=improved", "ablation"),
    ("run.method=x", "run.method"),
    ("claims.controls=[baseline]", "claims.controls"),
    ("tune.objectives=[]", "tune.objectives (part of tune)"),
])
def test_every_spelling_of_a_controlled_key_is_refused(override, key):
    """Groups above a controlled key, additions, deletions and presets name the key too."""
    with pytest.raises(ConfigError) as info:
        refuse_controlled([override], CONTROLLED, "tune")
    message = str(info.value)
    assert f"the override {override} is refused: {key} is the study's own design" in message
    assert len(message.splitlines()) == 1


@pytest.mark.parametrize("override", ["scenario.family.n_jobs=1", "controller.horizon=12",
                                      "vehicle.mass_kg=1600", "hydra/launcher=slurm",
                                      "hydra.searchpath=[file:///tmp]", "metrics.threat_margin_m=0.4"])
def test_overrides_of_what_both_sides_share_are_allowed(override):
    # a refusal raises (and fails the test with the line it printed); an allowed override
    # passes through and returns nothing
    assert refuse_controlled([override], CONTROLLED, "tune") is None


#: dotted keys made of config-like words
_WORDS = st.sampled_from(["scenario", "family", "seed", "size", "planner", "beta", "method",
                          "controller", "backend", "horizon", "vehicle", "mass_kg", "n_jobs",
                          "claims", "controls", "run", "tune", "metrics", "step_size"])


@settings(max_examples=300, deadline=None)
@given(parts=st.lists(_WORDS, min_size=1, max_size=4), prefix=st.sampled_from(["", "+", "++", "~"]))
def test_an_override_is_refused_exactly_when_it_touches_a_controlled_key(parts, prefix):
    """Property: for any key, refusal <=> the key is a controlled key, above one or below one
    (oracle: the prefix relation on dotted paths, written out here)."""
    key = ".".join(parts)
    touches = any(key == c or key.startswith(c + ".") or c.startswith(key + ".")
                  for c in CONTROLLED)
    refused = True
    try:
        refuse_controlled([f"{prefix}{key}=1"], CONTROLLED, "tune")
    except ConfigError as exc:
        assert len(str(exc).splitlines()) == 1 and key in str(exc)
    else:
        refused = False
    assert refused == touches
    assert override_key(f"{prefix}{key}=1") == key
    assert any(related(key, c) for c in CONTROLLED) == touches


def test_a_preset_that_changes_a_family_seed_is_caught_in_the_composed_run(tmp_path):
    """The second line of defence: whatever set it, a composed run whose seed, size, backend
    or tuned setting is not the tune's stops with one line naming the key (the override here
    reaches the runner only because the first check is bypassed)."""
    from pipeline.studies.tune.search import Runner

    runner = Runner(QUICK, tmp_path, ["scenario.family.seed=5"], log=lambda m: None)
    with pytest.raises(ConfigError) as info:
        runner.job("improved", "trial", {"planner.beta": 0.5}, "training", 0)
    assert "tune: improved's run scenario.family.seed=5 is invalid; allowed: 1, what the tune " \
        "sets" in str(info.value)
    runner = Runner(QUICK, tmp_path, [], log=lambda m: None)
    job = runner.job("improved", "trial", {"planner.beta": 0.5}, "training", 1)
    assert job.cfg.scenario.family.seed == QUICK.training_seeds[1]
    assert job.cfg.planner.beta == 0.5


def test_the_kinematic_tracks_own_keys_are_controlled_too(tmp_path):
    """``--set track=kinematic``: the track sets the controller, the start speed and the run
    length; an override of any of them is one line, and a composed run holds them."""
    from pipeline.studies.tune.search import Runner

    space = load_tune_space(CONF_DIR / "tune" / "quick.yaml", [
        "track=kinematic", "backend=clarabel_direct", "heldout_backend=clarabel_direct"])
    controlled = controlled_keys(space, SPACES)
    for override in ("scenario.n_steps=50", "scenario.initial_speed_mps=3", "controller=nmpc"):
        with pytest.raises(ConfigError, match="refused"):
            refuse_controlled([override], controlled, "tune")
    job = Runner(space, tmp_path, [], log=lambda m: None).job("improved", "default", {},
                                                              "heldout")
    assert job.cfg.scenario.n_steps == 100 and job.cfg.scenario.initial_speed_mps == 0.0


def test_a_launcher_that_is_not_an_option_is_one_line(tmp_path, capsys):
    """``python -m pipeline.tune --space quick --out D hydra/launcher=slrum``: exit 2,
    ``config error: hydra/launcher='slrum' is not a known option; allowed: basic, joblib,
    local_cores, robust_slurm, sequential, slurm, submitit_local, submitit_slurm`` (the tune
    ignored the misspelt launcher and ran every family here)."""
    out = tmp_path / "D"
    assert main(["--space", "quick", "--out", str(out), "hydra/launcher=slrum"]) == 2
    line = _one_line(capsys)  # the key, and the allowed options (not the whole list's words)
    assert "hydra/launcher='slrum'" in line and "allowed:" in line
    assert {"basic", "slurm", "submitit_local"} <= set(line.split("allowed:")[1].replace(",", " ").split())
    assert not (out / "runs").exists()
