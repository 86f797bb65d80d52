"""The multiverse as one study: design, runs, re-scoring, analysis, its result written."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import pandas as pd

from pipeline.analysis.claims.windows import require_own_window
from pipeline.config import MetricsConfig
from pipeline.store.lock import folder_lock
from pipeline.store.manifest import refuse_other_record
from pipeline.store.member_cache import MemberCounts
from pipeline.store.runs import read_family
from pipeline.studies.compose import composer
from pipeline.studies.multiverse.design import (
    analysis_settings,
    build_design,
    simulation_key,
    with_user_defaults,
)
from pipeline.studies.multiverse.robustness import (
    ROBUSTNESS_RULE,
    analyse_specification,
    robustness,
)
from pipeline.studies.multiverse.runs import _LogStream, rescore_family, run_simulations
from pipeline.studies.multiverse.space import Space
from pipeline.studies.overrides import PRESET_GROUPS, applied_overrides, refuse_controlled
from pipeline.studies.results.multiverse import MultiverseInfo, MultiverseResult

logger = logging.getLogger("pipeline.studies.multiverse")


def run_multiverse(space: Space, out_dir: Path, overrides: list[str] | None = None,
                   n_jobs: int = 2, log=None) -> MultiverseResult:
    """Design, runs, re-scoring and analysis, written into ``out_dir`` (the manifest last);
    returns the result (``log``: where progress lines go, the module's logger by default).
    The specification curves are the command's to draw."""
    log = log if log is not None else logger.info
    out_dir = Path(out_dir)
    # an override of what the multiverse sets itself (methods, its family, a simulation
    # dimension's keys): one line, before anything is written; every other override runs for
    # every method and is recorded in space.json
    refuse_controlled(list(overrides or []), controlled_keys(space), "multiverse")
    refuse_other_record(out_dir, ("multiverse",))
    # one study per folder at a time (a second is refused in one line), for as long as it runs
    with folder_lock(out_dir, f"multiverse {space.name}"):
        return _run_multiverse(space, out_dir, list(overrides or []), n_jobs, log)


def _run_multiverse(space: Space, out_dir: Path, overrides: list[str], n_jobs: int,
                    log) -> MultiverseResult:
    from joblib import Parallel, delayed

    compose, launcher = composer(overrides)
    # the default specification is the user's configuration (its analysis settings)
    base = compose(["method=improved", "scenario=family"])
    require_own_window(base.claims, "the multiverse")
    space = with_user_defaults(space, base)
    # what is compared with what: the user's claims.treatment and claims.controls (last: the
    # treatment)
    methods = tuple(base.claims.controls) + (base.claims.treatment,)
    space.check_methods(methods)
    design = build_design(space)
    # not trusted until the result's manifest is written last
    MultiverseResult.write_design(out_dir, design)
    # validate every composition before anything runs: a bad value stops here
    for row in design.to_dict("records"):
        analysis_settings(row, space, base)
    counts = MemberCounts()
    folders, backends = run_simulations(design, space, out_dir, compose, log, launcher, methods,
                                        counts)
    log(f"family runs: {counts.sentence()}")
    jobs = [(row, folders[simulation_key(row, space)]) for row in design.to_dict("records")]
    members, reads = _rescore_families(_metric_readings(jobs, space, base), out_dir, n_jobs,
                                       log)
    log(f"judging {len(jobs)} specifications ...")
    results = Parallel(n_jobs=n_jobs)(
        delayed(analyse_specification)(row, f, space, out_dir) for row, f in jobs)
    rows = [r for block in results for r in block]
    table = pd.DataFrame(rows).merge(design, on="spec_id")
    robust, dims = robustness(pd.DataFrame(rows), design, space)
    info = dataclasses.replace(
        _multiverse_info(space, design, len(folders), backends,
                         reads / members if members else 0.0, counts),
        overrides=tuple(applied_overrides(overrides)))
    result = MultiverseResult(info, design, table, robust, dims)
    if result.unchanged_in(out_dir):
        # a rerun of a complete study (its caches checked and repaired on the way): the
        # result is the one written, which is kept as it is, space.json and all
        log(f"{out_dir}: the result is unchanged; its files are kept as written")
        return MultiverseResult.load(out_dir)
    return result.write(out_dir)


def controlled_keys(space: Space) -> dict[str, str]:
    """The config keys the multiverse sets in its runs, each with what to do instead of
    overriding it (:func:`pipeline.studies.overrides.refuse_controlled`): an override would
    replace every specification's value, so the dimension would vary nothing."""
    keys = dict(PRESET_GROUPS)
    keys.update({
        "scenario.family.size": "no override: the multiverse sets its family's size (the "
                                "space's family_size)",
        "scenario.family.seed": "no override: the multiverse sets its family's seed (the "
                                "space's family_seed)"})
    for dim in space.of("simulation"):
        for key in dim.config_keys:
            keys.setdefault(key, f"no override: {key} is the multiverse dimension {dim.key} "
                                 "(edit its values in the space file)")
        if dim.cap:
            keys.setdefault("planner.step_size", f"no override: the matched baseline's step "
                            f"follows the dimension {dim.key}")
    return keys


def _metric_readings(jobs: list, space: Space, base) -> dict[Path, list[MetricsConfig]]:
    """Every metric reading each family needs, over the specifications ``jobs``."""
    readings: dict[Path, list[MetricsConfig]] = {}
    for row, family_folders in jobs:
        metrics, _ = analysis_settings(row, space, base)
        for folder in family_folders.values():
            readings.setdefault(Path(folder), []).append(metrics)
    return readings


def _rescore_families(readings: dict[Path, list[MetricsConfig]], out_dir: Path, n_jobs: int,
                      log) -> tuple[int, int]:
    """Re-score every family under its readings, computed in one pass over its members (each
    member read once per analysis, not once per reading); the number of members and of member
    trajectories read."""
    from joblib import Parallel, delayed

    from pipeline.errors import workers_start_deaf_to_ctrl_c
    from pipeline.studies.progress import Progress

    members = sum(len(read_family(f, members=False).table) for f in readings)
    log(f"re-scoring {members} members of {len(readings)} families under their metric "
        "readings ...")
    reads = 0
    with Progress(len(readings), "re-scoring", "family", stream=_LogStream(log)) as bar:
        with workers_start_deaf_to_ctrl_c():  # the workers start with Ctrl-C blocked
            counts = Parallel(n_jobs=n_jobs, return_as="generator_unordered")(
                delayed(rescore_family)(folder, wanted, out_dir)
                for folder, wanted in readings.items())
        for n_read in counts:
            reads += n_read
            bar.update()
    log(f"re-scoring: {reads} member trajectories read for {members} members "
        f"({len(readings)} families)")
    return members, reads


def _multiverse_info(space: Space, design: pd.DataFrame, n_simulations: int,
                     backends: dict[str, str], member_reads_per_member: float,
                     counts: MemberCounts | None = None) -> MultiverseInfo:
    """The multiverse's bookkeeping: its space, sizes, backends and robustness rule."""
    return MultiverseInfo(
        name=space.name, n_specifications=int(len(design)),
        n_simulation_configurations=n_simulations, family_size=space.family_size,
        backend=space.backend, backends=backends,
        member_reads_per_member=member_reads_per_member,
        rule=ROBUSTNESS_RULE, robust_share=space.robust_share,
        fragile_share=space.fragile_share,
        dimensions=tuple({"key": d.key, "config_key": ", ".join(d.config_keys),
                          "stage": d.stage, "group": d.group,
                          "values": [str(v) for v in d.values],
                          "settings": [str(v) for v in d.settings or ()],
                          "applies_to": list(d.applies_to or []), "why": d.why}
                         for d in space.dimensions),
        members=(counts or MemberCounts()).to_json())
