"""Claims stage: the paper's claims mapped to metrics, and four-outcome verdicts on given runs.

Each claim names one primary metric (the outcome is taken on it) and secondary metrics shown
beside it; C0 (safety: collisions) comes first. Over a scenario family a claim is judged on the
paired differences ``d = improved - comparison`` (``d < 0`` is the claimed improvement) as
*supported*, *contradicted*, *equivalent* or *inconclusive* (:data:`OUTCOME_RULE`); on the single
paper scenario the words are *better*, *worse* or *within margin*. Statistics come from
``scipy.stats``: the paired bootstrap interval (``bootstrap``, BCa where defined), the Wilcoxon
signed-rank or sign test (``wilcoxon``, ``binomtest``), McNemar's exact test on discordant
collision pairs (``binomtest``); Holm's adjustment over the six claims is written out (SciPy has
none). C2 can be read on a window common to both runs of a pair (``claims.c2_window``).
"""

# The code is in modules of one concern: catalogue, statistics, ledger, windows, multiplicity.
from pipeline.analysis.claims.catalogue import (
                                                ALL_CLAIMS,
                                                CLAIMS,
                                                FORCE_CLAIMS,
                                                OUTCOME_RULE,
                                                OUTCOMES,
                                                SAFETY,
                                                SINGLE_RULE,
                                                Claim,
                                                Outcome,
                                                claims_of,
                                                force_claims,
)
from pipeline.analysis.claims.ledger import (
                                                LEDGER_COLUMNS,
                                                Ledger,
                                                LedgerRow,
                                                claims_table,
                                                family_ledger,
                                                outcome_counts,
                                                single_scenario_outcome,
)
from pipeline.analysis.claims.memo import IntervalMemo
from pipeline.analysis.claims.multiplicity import adjust_answer, claim_level
from pipeline.analysis.claims.statistics import (
                                                PAIRS,
                                                WILCOXON_ENUMERATED_MAX_PAIRS,
                                                PairedResult,
                                                bootstrap_interval,
                                                compare,
                                                decide,
                                                hodges_lehmann,
                                                hodges_lehmann_on,
                                                holm,
                                                judge,
                                                newcombe_paired_interval,
                                                paired_differences,
                                                paired_test,
                                                probability_of_improvement,
                                                wilcoxon_pratt_pvalue,
)
from pipeline.analysis.claims.windows import (
                                                COMMON_C2_METRIC,
                                                WINDOW_RULES,
                                                common_window,
                                                common_window_claim,
                                                common_window_pairs,
                                                common_window_tables,
)

__all__ = ["Claim", "CLAIMS", "SAFETY", "ALL_CLAIMS", "FORCE_CLAIMS", "claims_of", "force_claims", "Outcome", "OUTCOMES", "OUTCOME_RULE",
           "SINGLE_RULE", "hodges_lehmann", "hodges_lehmann_on", "bootstrap_interval",
           "probability_of_improvement", "paired_test", "WILCOXON_ENUMERATED_MAX_PAIRS",
           "wilcoxon_pratt_pvalue", "holm", "decide", "newcombe_paired_interval", "PAIRS",
           "paired_differences", "PairedResult", "compare", "judge", "single_scenario_outcome",
           "claims_table", "LEDGER_COLUMNS", "LedgerRow", "Ledger", "family_ledger",
           "outcome_counts", "COMMON_C2_METRIC", "WINDOW_RULES", "common_window",
           "common_window_claim", "common_window_pairs", "common_window_tables",
           "adjust_answer", "claim_level", "IntervalMemo"]
