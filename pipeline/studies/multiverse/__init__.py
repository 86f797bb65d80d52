"""How robust is each verdict: a multiverse over every registered choice (``make multiverse``).

``python -m pipeline.multiverse [--space default|quick|PATH] [--out outputs/multiverse]
[OVERRIDE ...]`` reads a space (``conf/multiverse/<space>.yaml``): dimensions, each a config key
with its defensible values (the first is the default) and a stage. *Simulation* dimensions change
the runs; *analysis* dimensions (metric readings and thresholds, statistics) only re-score them.
A simulation dimension may vary the world every method meets (``scenario.*``: speed, appearance
time, obstacle kinds and count; ``vehicle.*``: mass and inertia, tyres), set for every method so
pairs stay paired; its values may be lists, or labelled bundles of several keys.

1. **Design**: the default specification, every one-at-a-time change, then a seeded sample until
   ``n_specifications``; sampled specifications draw their simulation choices from a pool of
   ``simulation_pool`` seeded combinations, so runs are shared (Steegen et al. 2016; Simonsohn,
   Simmons and Nelson 2020).
2. **Runs**: every distinct simulation configuration runs ``baseline``, ``baseline_matched`` and
   ``improved`` on the same family (``family_size`` >= 100 scenarios), one family folder per
   config hash under ``runs/``; a folder already complete comes back from its hash, never
   recomputed (resume after an interruption loses nothing). The lateral MPC's QP runs on the
   space's ``backend`` (``daqp`` by default: the same condensed QP as the reference
   ``clarabel_direct``, its first input within 1e-6, the QP about 3x faster); a run override
   ``controller.backend=...`` wins, and ``space.json`` records each method's backend.
3. **Re-scoring**: a specification whose metric settings differ from the runs' recomputes the
   metrics from the stored trajectories (cached under ``rescored/``).
4. **Analysis**: per specification, claim and comparison the claims ledger (estimate, interval,
   Holm-adjusted test, outcome); per claim and comparison the share of specifications with each
   outcome, a robustness label (:data:`ROBUSTNESS_RULE`), how much each dimension moves the
   estimate and which of its values flip the outcome.

Its result is :class:`pipeline.studies.results.MultiverseResult` (the design, every
specification's ledger rows, the robustness table, the per-dimension effects); the command draws
one specification curve per claim and the report's Robustness section reads them. Extra
arguments are Hydra overrides applied to every run (e.g. ``scenario.family.n_jobs=2``).

The modules: :mod:`.space` (the space file), :mod:`.design`, :mod:`.runs` (families and
re-scoring), :mod:`.robustness` (the analysis), :mod:`.study` (all of it in order).
"""

from pipeline.config import CONF_DIR
from pipeline.studies.compose import composer
from pipeline.studies.multiverse.design import (
                                                analysis_settings,
                                                build_design,
                                                family_config,
                                                matches,
                                                qp_backend,
                                                simulation_key,
                                                simulation_overrides,
                                                value_text,
                                                with_user_defaults,
)
from pipeline.studies.multiverse.robustness import (
                                                ROBUSTNESS_RULE,
                                                analyse_specification,
                                                robustness,
)
from pipeline.studies.multiverse.runs import (
                                                family_table,
                                                rescore_family,
                                                run_families,
                                                run_simulations,
)
from pipeline.studies.multiverse.space import (
                                                METHODS,
                                                QP_BACKENDS,
                                                Dimension,
                                                Space,
                                                hydra_value,
                                                load_space,
)
from pipeline.studies.multiverse.study import run_multiverse

__all__ = ["CONF_DIR", "METHODS", "QP_BACKENDS", "ROBUSTNESS_RULE", "Dimension", "Space",
           "analyse_specification", "analysis_settings", "build_design", "composer", "hydra_value",
           "family_config", "family_table", "load_space", "matches", "qp_backend",
           "rescore_family", "robustness", "run_families", "run_multiverse",
           "run_simulations", "simulation_key", "simulation_overrides", "value_text",
           "with_user_defaults"]
