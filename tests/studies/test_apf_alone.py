"""What each APF does by itself (issue 40, part 4): ``controller.collision_constraints``, the
``apf_alone`` experiment of ``make reproduce`` and its ledger in the report.

The switch is tested against an independent oracle of "no half-planes":
``controller.constraint_activation_m=0`` (no obstacle is ever near enough to be constrained)
gives the same closed loop, bit for bit, on every backend and both tracks; the default gives
another one, in which the straight-to-goal peer ``mpc_no_apf`` (no APF: only the half-planes
can steer it round the obstacle) keeps clear of the obstacle it drives through without them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline import api
from pipeline.errors import ConfigError
from pipeline.loop.controller import collision_halfplanes, kinematic_halfplanes

OFF = "controller.collision_constraints=false"
ORACLE = "controller.constraint_activation_m=0"

#: Every way the MPC's half-planes are stated: the lateral QP's backends, both frames, the lateral
#: NMPC, and Appendix A's kinematic track (LTV-QP and NMPC).
BACKENDS = {
    "clarabel_direct": ["method=mpc_no_apf"],
    "daqp": ["method=mpc_no_apf", "controller.backend=daqp"],
    "cvxpy": ["method=mpc_no_apf", "controller.backend=cvxpy"],
    "fixed_frame": ["method=mpc_no_apf", "controller.frame=fixed"],
    "lateral_nmpc": ["method=mpc_no_apf", "controller.backend=nmpc"],
    "kinematic": ["experiment=kinematic", "planner=mpc_no_apf"],
    "kinematic_nmpc": ["experiment=kinematic", "planner=mpc_no_apf", "controller.backend=nmpc"],
}


@pytest.mark.parametrize("backend", list(BACKENDS))
def test_switch_off_is_the_closed_loop_without_half_planes(backend):
    overrides = BACKENDS[backend]
    on = api.simulate(overrides)
    off = api.simulate(overrides + [OFF])
    oracle = api.simulate(overrides + [ORACLE])
    assert on.config.controller.collision_constraints is True
    assert off.config.controller.collision_constraints is False
    # off: exactly the loop in which no obstacle is ever constrained
    pd.testing.assert_frame_equal(off.trajectory, oracle.trajectory, check_exact=True)
    assert off.metrics.value("min_clearance_m") == oracle.metrics.value("min_clearance_m")
    # on: the half-planes push the straight-to-goal reference round the obstacle; without
    # them the vehicle drives into it (the paper scenario's obstacle sits on the line)
    clear_on = on.metrics.value("min_clearance_m")
    clear_off = off.metrics.value("min_clearance_m")
    assert clear_off < 0.0, clear_off
    assert clear_on > clear_off + 0.3, (clear_on, clear_off)
    # no slack is ever spent without half-planes (there is nothing to violate)
    assert float(off.trajectory["max_slack_m"].max()) == 0.0


def test_switch_empties_both_tracks_half_plane_rows(make_config):
    """The rows themselves: an obstacle 3 m ahead binds with the switch on (a nonzero gain at
    the stations it covers, the disk's exact width as bound) and gives only empty rows
    ``0 y + s >= 0`` with it off, on the lateral and the kinematic track."""
    lateral = make_config([])
    vehicle = lateral.vehicle
    stations = np.linspace(0.3, 3.0, 10)
    obstacle = np.tile([3.0, 0.1], (10, 1, 1))
    radii = np.array([0.5])
    off_cfg = dataclasses.replace(lateral.controller, collision_constraints=False)
    G, h = collision_halfplanes(stations, np.zeros(10), np.zeros(2), obstacle, radii, vehicle,
                                lateral.controller)
    reach = 0.5 + vehicle.footprint_radius_m + lateral.controller.safety_margin_m
    covered = np.abs(stations - 3.0) < reach
    assert covered.any() and np.all(G[covered, 0] == -1.0)  # the reference passes below
    np.testing.assert_allclose(h[covered, 0],
                               -0.1 + np.sqrt(reach ** 2 - (stations[covered] - 3.0) ** 2))
    G_off, h_off = collision_halfplanes(stations, np.zeros(10), np.zeros(2), obstacle, radii,
                                        vehicle, off_cfg)
    assert not G_off.any() and not h_off.any()

    kin = make_config(["experiment=kinematic", "planner=improved"])
    states = np.zeros((4, 11))
    states[0] = np.linspace(0.0, 3.0, 11)
    reference = np.stack([np.linspace(0.3, 3.0, 10), np.full(10, 0.8)])
    parts = kinematic_halfplanes(states, reference, obstacle, radii, kin.vehicle, kin.controller)
    assert np.abs(parts[1]).max() > 0.5 and parts[2].max() > 0.0
    parts_off = kinematic_halfplanes(states, reference, obstacle, radii, kin.vehicle,
                                     dataclasses.replace(kin.controller,
                                                         collision_constraints=False))
    assert not any(p.any() for p in parts_off)


def test_switch_is_checked_and_enters_the_run_hash(make_config):
    """A word that is not a boolean names the key; off and on never share a run folder's
    hash (the default's is still the one pinned before the key existed: tests/studies/test_pins.py)."""
    cfg = make_config(["method=improved"])
    with pytest.raises(ConfigError, match="controller.collision_constraints"):
        dataclasses.replace(cfg.controller, collision_constraints="no")
    off = make_config(["method=improved", OFF])
    assert off.config_hash() != cfg.config_hash()


# --- the experiment -----------------------------------------------------------------------

def test_the_experiment_composes_every_method_without_half_planes(make_config):
    """``experiment=apf_alone`` as ``make run-apf-alone`` runs it: a multirun over the three
    methods of the ledger and no APF, each job a scenario family with the half-planes off,
    written under ``apf_alone`` (the layout's folder, kept out of the default ledger)."""
    from conftest import CONF_DIR
    from hydra import compose, initialize_config_dir

    from pipeline.store.layout import OutputsLayout

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=apf_alone"],
                      return_hydra_config=True)
    methods = cfg.hydra.sweeper.params["method"].split(",")
    assert sorted(methods) == ["baseline", "baseline_matched", "improved", "mpc_no_apf"]
    assert cfg.hydra.mode.name == "MULTIRUN"
    layout = OutputsLayout.load(Path("outputs"))
    assert Path(cfg.hydra.sweep.dir).name == layout.apf_alone
    assert layout.apf_alone in layout.not_main_runs
    for method in methods:
        job = make_config(["experiment=apf_alone", f"method={method}"])
        assert job.run.method == method and job.scenario.family is not None
        assert job.controller.collision_constraints is False
        default = make_config([f"method={method}", "scenario=family"])
        # the same family and MPC, only the half-planes off
        assert job.scenario == default.scenario
        assert dataclasses.replace(job.controller, collision_constraints=True) \
            == default.controller
    makefile = (CONF_DIR.parent / "Makefile").read_text()
    experiment = makefile[makefile.index("\nexperiment:"):makefile.index("\n# the experiments")]
    assert "run-apf-alone" in experiment and "$(RUNS)/apf_alone" in experiment
    assert "experiment=apf_alone hydra.sweep.dir=$(RUNS)/apf_alone" in makefile


# --- the opening summary's sentence, by its rule -------------------------------------------

def _rows(without, with_=None):
    from pipeline.reporting.sections.apf_alone import CollisionRow

    methods = ("improved", "baseline", "baseline_matched", "mpc_no_apf")
    with_ = with_ or (None,) * 4
    return tuple(CollisionRow(m, 200, w, 0, c) for m, w, c in zip(methods, without, with_,
                                                                   strict=True))


def test_safety_sentence_states_the_counts_and_who_avoids():
    from pipeline.reporting.sections.apf_alone import safety_sentence

    # the issue's measurement: the constraints avoid 163 of 183, improved's APF 147 of 183
    assert safety_sentence(_rows((36, 175, 168, 183), (21, 18, 19, 20)), "improved") == (
        "Without the MPC's collision constraints improved's APF alone collides in 36 of 200 "
        "scenarios, "
        "baseline's in 175, baseline_matched's in 168 and no APF (mpc_no_apf) in 183; with "
        "them they collide in 21, 18, 19 and 20: the MPC's constraints do most of the avoiding "
        "(163 of no APF's 183 collisions by themselves), and improved's APF is what avoids "
        "when they are absent (147 of 183).")
    # weak constraints, two APFs that avoid by themselves
    text = safety_sentence(_rows((20, 40, 150, 183), (15, 30, 120, 150)), "improved")
    assert "avoid less than half of the collisions (33 of no APF's 183" in text
    assert "improved's and baseline's APFs are what avoids" in text and "(163 of 183 and " \
        "143 of 183)" in text
    # no APF avoids half of them; without the default family no counts "with them"
    text = safety_sentence(_rows((150, 175, 168, 183)), "improved")
    assert "with them" not in text and "no APF avoids half of no APF's collisions" in text


# --- the report ---------------------------------------------------------------------------

LEDGER_METHODS = ("baseline", "baseline_matched", "improved", "mpc_no_apf")
SMALL = ["scenario=family", "scenario.family.size=12", "scenario.family.n_jobs=1"]
#: what these tests do not judge, made cheap (make test sits near its ten minutes): DAQP for
#: the QPs and 999 bootstrap resamples for the report's ledgers (C0's estimate and counts,
#: which the tests check, do not depend on the resamples)
CHEAP = ["controller.backend=daqp", "claims.n_resamples=999", "claims.n_resamples_refine=999"]


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, make_config):
    """make reproduce's folders on a 12-member family: the paper scenario, the family with the
    half-planes and ``apf_alone`` without them (the same members), made once for this
    module."""
    from pipeline.studies.experiment import run_experiment, run_family

    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "baseline_matched", "improved"):
        run_experiment(make_config([f"method={method}"] + CHEAP), root / "paper" / method)
    for method in LEDGER_METHODS:
        run_family(make_config([f"method={method}"] + SMALL + CHEAP), root / "family" / method,
                   progress=False)
        run_family(make_config(["experiment=apf_alone", f"method={method}"] + SMALL[1:]
                               + CHEAP), root / "apf_alone" / method, progress=False)
    return root


def _collisions(root: Path, section: str) -> dict[str, int]:
    """Collisions per method counted from each family's table on disk (the oracle)."""
    return {m: int(pd.read_csv(root / section / m / "family_metrics.csv")["collision"]
                   .astype(bool).sum()) for m in LEDGER_METHODS}


@pytest.fixture(scope="module")
def report(outputs, tmp_path_factory):
    from pipeline.reporting.page import build_report

    out = tmp_path_factory.mktemp("report")
    build_report(outputs, out, "pytest", figure_jobs=1)
    return out


def test_report_writes_the_apf_alone_ledger(outputs, report):
    tables = report / "tables"
    ledger = pd.read_csv(tables / "claims_ledger_apf_alone.csv")
    default = pd.read_csv(tables / "claims_ledger.csv")
    assert list(ledger.columns) == list(default.columns)
    assert sorted(set(ledger["comparison"])) == ["baseline", "baseline_matched", "mpc_no_apf"]
    assert sorted(set(ledger["claim"])) == sorted(set(default["claim"]))
    # C0 is the difference of collision rates over the 12 pairs: counted from the apf_alone
    # tables, not the default family's
    without, with_ = _collisions(outputs, "apf_alone"), _collisions(outputs, "family")
    c0 = ledger[ledger["claim"] == "C0"].set_index("comparison")
    for control in ("baseline", "baseline_matched", "mpc_no_apf"):
        expected = (without["improved"] - without[control]) / 12
        assert c0.loc[control, "estimate"] == pytest.approx(expected, abs=1e-12)
        assert c0.loc[control, "n_pairs"] == 12
    # without the half-planes a straight-to-goal reference drives into the obstacles it
    # avoided with them (the half-planes are all that avoids for no APF)
    assert without["mpc_no_apf"] >= with_["mpc_no_apf"] + 6, (without, with_)
    counts = pd.read_csv(tables / "apf_alone_collisions.csv").set_index("method")
    assert counts["collisions_without_halfplanes"].to_dict() == without
    assert counts["collisions_with_halfplanes"].to_dict() == with_


def test_summary_sentence_quotes_the_counts(outputs, report):
    import re

    without, with_ = _collisions(outputs, "apf_alone"), _collisions(outputs, "family")
    lines = (report / "answer.txt").read_text().splitlines()
    sentence = next(line for line in lines
                    if line.startswith("Without the MPC's collision constraints"))
    assert lines.index(sentence) == 1  # right after the collisions, before the verdicts
    found = re.search(r"improved's APF alone collides in (\d+) of (\d+) scenarios, "
                      r"baseline's in (\d+), baseline_matched's in (\d+) and no APF "
                      r"\(mpc_no_apf\) in (\d+); with them they collide in (\d+), (\d+), "
                      r"(\d+) and (\d+)", sentence)
    assert found, sentence
    numbers = [int(x) for x in found.groups()]
    order = ("improved", "baseline", "baseline_matched", "mpc_no_apf")
    assert numbers[1] == 12
    assert numbers[:1] + numbers[2:5] == [without[m] for m in order]
    assert numbers[5:] == [with_[m] for m in order]
    avoided = without["mpc_no_apf"] - with_["mpc_no_apf"]
    assert f"({avoided} of no APF's {without['mpc_no_apf']} collisions" in sentence
    page = (report / "index.html").read_text()
    box = page[page.index('id="answer"'):page.index('id="robustness-summary"')
               if 'id="robustness-summary"' in page else page.index('id="claims-paper"')]
    assert sentence.replace("'", "&#39;") in box
    assert 'id="apf-alone"' in page and 'href="#apf-alone"' in page
    assert "controller.collision_constraints" in page


def test_report_without_apf_alone_runs_omits_the_ledger(outputs, tmp_path):
    """Outputs from before the experiment: no ledger file, no section, no sentence, a note."""
    import shutil

    from pipeline.reporting.page import build_report
    from pipeline.reporting.sections.apf_alone import MISSING_NOTE

    older = tmp_path / "outputs"
    shutil.copytree(outputs, older, ignore=shutil.ignore_patterns("apf_alone"))
    build_report(older, tmp_path / "report", "pytest", figure_jobs=1)
    assert (tmp_path / "report" / "tables" / "claims_ledger.csv").is_file()
    assert not (tmp_path / "report" / "tables" / "claims_ledger_apf_alone.csv").exists()
    assert "collision constraints" not in (tmp_path / "report" / "answer.txt").read_text()
    page = (tmp_path / "report" / "index.html").read_text()
    assert 'id="apf-alone"' not in page and MISSING_NOTE.replace("'", "&#39;") in page


def test_a_family_made_with_half_planes_is_not_the_apf_alone(outputs, tmp_path):
    """A family under apf_alone whose settings have the half-planes on is left out with its
    reason (it would judge the MPC again): without the treatment there is no ledger."""
    import shutil

    from pipeline.reporting.page import build_report
    from pipeline.store.runs import Skipped

    mixed = tmp_path / "outputs"
    shutil.copytree(outputs, mixed)
    shutil.rmtree(mixed / "apf_alone" / "improved")
    shutil.copytree(outputs / "family" / "improved", mixed / "apf_alone" / "improved")
    skipped: list[Skipped] = []
    build_report(mixed, tmp_path / "report", "pytest", skipped=skipped, figure_jobs=1)
    assert any(s.folder.name == "improved" and "half-planes on" in s.reason for s in skipped)
    assert not (tmp_path / "report" / "tables" / "claims_ledger_apf_alone.csv").exists()
