"""A fair fight (``make tune``): both methods tuned by the same rules until their fronts stop
moving, in independent replicates, each judged on its own held-out family and settled by a
binomial test over the replicates
(:func:`pipeline.studies.tune.study.run_tuning`; the rules: :mod:`.space`, the loop:
:mod:`.search`, fronts and convergence: :mod:`.pareto`)."""

from pipeline.studies.tune.pareto import (
    COMPROMISE_RULE,
    closest_to_ideal,
    convergence_point,
    distances_to_ideal,
    dominates,
    hypervolume,
    hypervolume_history,
    pareto_mask,
)
from pipeline.studies.tune.search import Convergence, make_study, optimize
from pipeline.studies.tune.space import TuneSpace, default_budget, load_tune_space, search_space
from pipeline.studies.tune.study import (
    ANSWER_RULE,
    NoFeasibleSettingError,
    answer_in_counts,
    front_points,
    run_tuning,
)

__all__ = ["ANSWER_RULE", "COMPROMISE_RULE", "Convergence", "NoFeasibleSettingError", "TuneSpace",
           "answer_in_counts", "closest_to_ideal", "convergence_point", "default_budget",
           "distances_to_ideal", "dominates", "front_points", "hypervolume",
           "hypervolume_history", "load_tune_space", "make_study", "optimize", "pareto_mask",
           "run_tuning", "search_space"]
