"""The claim catalogue (issue 57, item 1, claims): a claim is one entry
(``conf/claim/<id>.yaml``: its metric, direction, margin and the margin's reason); the claims settings' margins and reasons, the ids the settings check, the score
study's metric-to-claim map and the Holm family's size read it. The oracle is what the five
places held before, pinned here."""

from __future__ import annotations

import re
from pathlib import Path

from pipeline.analysis.claims.catalogue import ALL_CLAIMS, CLAIM_IDS
from pipeline.analysis.settings import ClaimsConfig

MARGINS_BEFORE = {"C0": 0.02, "C1": 0.05, "C2": 0.1, "C3a": 0.05, "C3b": 0.1, "C4": 0.1,
                  "C5": 0.5}
CLAIM_OF_BEFORE = {"collision": "C0", "reaction_delay_s": "C1",
                   "lateral_jerk_rms_mps3": "C2", "repulsion_unneeded_share": "C3a",
                   "repulsion_onset_ttc_s": "C3b", "recovery_time_s": "C4",
                   "oscillation_count": "C5"}
ROOT = Path(__file__).resolve().parents[2]


def test_the_settings_and_the_score_study_read_the_catalogue():
    from pipeline.studies.score import CLAIM_OF

    assert CLAIM_IDS == ("C0", "C1", "C2", "C3a", "C3b", "C4", "C5")
    cfg = ClaimsConfig()
    assert cfg.margins == MARGINS_BEFORE
    assert cfg.margin_reasons["C1"] == ("half a sample time (Ts = 0.1 s): the resolution the "
                                        "paper's 10 Hz loop can act on")
    assert all(cfg.margin_reasons[c.claim_id] == c.margin_reason for c in ALL_CLAIMS)
    assert CLAIM_OF == CLAIM_OF_BEFORE


def test_no_claim_id_is_listed_outside_the_catalogue():
    """conf/config.yaml no longer lists the margins by claim (a comment names them), and no
    module but the catalogue spells the claim-id tuple."""
    config = (ROOT / "conf" / "config.yaml").read_text()
    assert not re.search(r"^\s+C3a:", config, flags=re.M)
    spelled = [p for p in (ROOT / "pipeline").rglob("*.py")
               if '"C0", "C1", "C2", "C3a", "C3b", "C4", "C5"' in p.read_text()]
    assert spelled == []
