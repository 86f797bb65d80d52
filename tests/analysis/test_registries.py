"""The claim catalogue as a registry (issue 57, item 1): a claim is one YAML
(``conf/claim/<id>.yaml``: its text, metric, which way is better, margin and the margin's
reason); a claim of one's own from a folder on ``hydra.searchpath`` (``+claim=<id>``) is judged
in the ledger with its margin and shown in the report, without touching the package. The oracle
for its number is a Hodges-Lehmann estimate recomputed here from the families' tables."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from pipeline.config import CONF_DIR, register_configs, to_experiment_config

ROOT = Path(__file__).resolve().parents[2]

#: a claim of one's own: the least clearance is larger (higher is better)
CLAIM = '''# @package claims.catalogue.C9
text: keeps more room to the obstacle
metric: min_clearance_m
better: higher
secondary: []
kind: paired
margin: 0.05
margin_reason: five centimetres of clearance, the planted test's own margin
'''

SIX = ["scenario.family.size=6", "scenario.family.n_jobs=1"]


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory):
    """The user's folder: ``conf/claim/C9.yaml``."""
    root = tmp_path_factory.mktemp("user")
    (root / "conf" / "claim").mkdir(parents=True)
    (root / "conf" / "claim" / "C9.yaml").write_text(CLAIM)
    return root


def _compose(overrides: list[str], hydra_node: bool = False):
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=overrides,
                       return_hydra_config=hydra_node)


def _config(overrides: list[str]):
    return to_experiment_config(_compose(overrides))


def test_a_claim_from_a_user_folder_is_judged_with_its_margin(user_folder):
    """+claim=C9 appends the user's claim to the catalogue: the package's seven keep their
    order and margins, C9 comes last with its own."""
    search = f"hydra.searchpath=[file://{user_folder / 'conf'}]"
    claims = _config(["+claim=C9", search]).claims
    assert claims.claim_ids == ("C0", "C1", "C2", "C3a", "C3b", "C4", "C5", "C9")
    assert claims.margins["C9"] == 0.05 and claims.margins["C5"] == 0.5
    assert _config([]).claims.claim_ids == claims.claim_ids[:-1]
    fewer = _config(["claim=[C0,C1,C9]", search]).claims
    assert fewer.claim_ids == ("C0", "C1", "C9")


@pytest.fixture(scope="module")
def planted_report(user_folder, tmp_path_factory):
    """improved and the baseline on the paper scenario and a 6-member family (with C9); the
    report of it."""
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_experiment, run_family

    search = f"hydra.searchpath=[file://{user_folder / 'conf'}]"
    root = tmp_path_factory.mktemp("outputs")
    for method in ("baseline", "improved"):
        run_experiment(_config([f"method={method}"]), root / "paper" / method)
        run_family(_config([f"method={method}", "scenario=family", "+claim=C9", search] + SIX),
                   root / "family" / method, progress=False)
    out = build_report(root, tmp_path_factory.mktemp("report"), "pytest", figure_jobs=1).parent
    return root, out


def test_the_planted_claim_has_its_row_and_its_number(planted_report):
    """The claims ledger has C9 against the baseline, its estimate the Hodges-Lehmann median
    of baseline - improved minimum clearance (higher is better) over the pairs where neither
    collided, recomputed here from the families' tables; the report shows its row and its
    margin's reason."""
    root, out = planted_report
    ledger = pd.read_csv(out / "tables" / "claims_ledger.csv")
    row = ledger[(ledger["claim"] == "C9") & (ledger["comparison"] == "baseline")].iloc[0]
    assert row["metric"] == "min_clearance_m" and row["margin"] == 0.05
    tables = {m: pd.read_csv(root / "family" / m / "family_metrics.csv")
              for m in ("improved", "baseline")}
    merged = tables["improved"].merge(tables["baseline"], on="scenario", suffixes=("_i", "_b"))
    kept = merged[~(merged["collision_i"].astype(bool) | merged["collision_b"].astype(bool))]
    d = (kept["min_clearance_m_b"] - kept["min_clearance_m_i"]).to_numpy(float)
    walsh = (d[:, None] + d[None, :])[np.triu_indices(d.size)] / 2.0
    assert int(row["n_pairs"]) == d.size
    assert row["estimate"] == pytest.approx(float(np.median(walsh)), abs=1e-12)
    # the Methods' margins on the appendix page beside the report
    assert "five centimetres of clearance, the planted test" in \
        (out / "appendix.html").read_text()
    html = (out / "index.html").read_text()
    family = html[html.index('id="family"'):]
    assert ">C9<" in family and "keeps more room to the obstacle" in html


def test_a_run_folder_with_margins_tables_reads_as_the_catalogue():
    """A run's config.yaml written before the catalogue (claims.margins, claims.margin_reasons)
    reads as the package's catalogue with those margins; an unknown claim there is refused by
    its key."""
    from pipeline.config import experiment_config_from_data
    from pipeline.errors import ConfigError

    data = dataclasses.asdict(_config(["method=improved"]))
    claims = {k: v for k, v in data["claims"].items() if k != "catalogue"}
    old = {**data, "claims": {**claims, "margins": {"C0": 0.02, "C1": 0.07, "C2": 0.1,
                                                    "C3a": 0.05, "C3b": 0.1, "C4": 0.1,
                                                    "C5": 0.5},
                              "margin_reasons": {"C1": "an older reason"}}}
    read = experiment_config_from_data(old).claims
    assert read.margins["C1"] == 0.07 and read.margin_reasons["C1"] == "an older reason"
    assert read.claim_ids == _config([]).claims.claim_ids
    old["claims"]["margins"]["C7"] = 1.0
    with pytest.raises(ConfigError) as raised:
        experiment_config_from_data(old)
    assert raised.value.key == "claims.margins.C7"
