"""The report's gallery of family members: the rule picks planted members."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.reporting.gallery import gallery_members

METRICS = {"C1": "reaction_delay_s", "C2": "lateral_jerk_rms_mps3", "C4": "recovery_time_s"}


def _table(n: int = 10) -> pd.DataFrame:
    return pd.DataFrame({"member": np.arange(n), "collision": False,
                         "min_clearance_m": np.linspace(0.5, 1.4, n),
                         "reaction_delay_s": 0.3, "lateral_jerk_rms_mps3": 1.0,
                         "recovery_time_s": 2.0})


def test_the_rule_picks_the_planted_members():
    treated, control = _table(), _table()
    treated.loc[[3, 5], "collision"] = True
    treated.loc[3, "min_clearance_m"], treated.loc[5, "min_clearance_m"] = -0.5, -0.1
    control.loc[7, "collision"], control.loc[7, "min_clearance_m"] = True, -0.2
    treated.loc[2, "reaction_delay_s"] = 0.9          # C1: +0.6, the largest
    treated.loc[5, "reaction_delay_s"] = 5.0          # larger, but treatment collided there
    control.loc[8, "lateral_jerk_rms_mps3"] = 4.0      # C2: -3.0
    treated.loc[2, "recovery_time_s"] = 2.5            # C4: +0.5, same member as C1
    picks = gallery_members({"improved": treated, "baseline": control}, "improved", "baseline",
                            METRICS)
    by_member = {p["member"]: p["why"] for p in picks}
    assert by_member[3] == ["improved's worst collision (-0.50 m clearance)"]
    assert by_member[7] == ["baseline's worst collision (-0.20 m clearance)"]
    assert by_member[2][0].startswith("largest C1 difference (reaction_delay_s: +0.6")
    assert by_member[2][1].startswith("largest C4 difference")
    assert by_member[8][0].startswith("largest C2 difference (lateral_jerk_rms_mps3: -3")
    # typical: the treatment's clearance nearest its median over the 7 members without a
    # collision (0.5, 0.6, 0.7, 0.9, 1.1, 1.3, 1.4 at 0, 1, 2, 4, 6, 8, 9): 0.9 at member 4
    typical = [m for m, why in by_member.items() if why[-1].startswith("typical")]
    assert typical == [4]
    assert 5 not in by_member


def test_no_gallery_without_both_methods():
    assert gallery_members({"improved": _table()}, "improved", "baseline", METRICS) == []
