"""The report's sections as one ordered list: the page's template includes them in this order
and its table of contents lists their entries from it (:func:`page_parts`); a study from outside
the package adds its own section through the studies' registry (its entry's ``section``:
``key``, ``title``, ``template``, ``after``), placed after the section it names.

The reference material (how each metric and rule is defined, the compute, the interpretation
register, the provenance) stands on a second page beside the report, :data:`APPENDIX_PAGE`,
linked from the contents, so that the page with the answer and its evidence reads in one go
(issue 61: its height with every section open).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pipeline.reporting.explorer import PAGE

#: (anchor, title) entries of the table of contents; an anchor that names a page (the
#: explorer's) is linked as that page, any other as a place on this one
Entries = list[tuple[str, str]]
#: the scenario explorer, beside the report's page
EXPLORER_PAGE = PAGE
#: the page of reference material beside the report's (the sections with ``appendix``)
APPENDIX_PAGE = "appendix.html"


@dataclass(frozen=True)
class ReportSection:
    """One section: the page's value it shows (``key``), its template, its entries in the
    table of contents (from the page's values), whether it shows only beside the paper
    scenario (a sweep-only page leaves it out), whether it stands before the contents and
    whether it stands on the appendix page (:data:`APPENDIX_PAGE`)."""

    key: str
    template: str
    contents: Callable[[Mapping[str, Any]], Entries]
    paper_only: bool = False
    head: bool = False
    appendix: bool = False


def _when(key: str, anchor: str, title: str) -> Callable[[Mapping[str, Any]], Entries]:
    """One entry, shown when the page has a value for ``key``."""
    return lambda page: [(anchor, title)] if page.get(key) else []


def _exploratory(key: str, anchor: str, title: str) -> Callable[[Mapping[str, Any]], Entries]:
    """One entry marked exploratory when the study may not write the answer."""
    return lambda page: [(anchor, ("" if page[key].headline else "Exploratory: ") + title)] \
        if page.get(key) else []


def _given(page: Mapping[str, Any]) -> Entries:
    given = page["given"]
    if not (given.notes or given.other_runs or given.skipped):
        return []
    return [("given", "Runs given" + (f", {len(given.skipped)} skipped" if given.skipped
                                      else ""))]


#: Every section of the page, in its order.
SECTIONS: tuple[ReportSection, ...] = (
    ReportSection("answer", "sections/answer.html.j2",
                  lambda page: [("answer", "The answer"),
                                (EXPLORER_PAGE, "Scenario explorer: every run, animated")]
                  if page.get("family") else [], paper_only=True, head=True),
    ReportSection("paper", "sections/claims.html.j2",
                  lambda page: [("claims", "Claims: the ledger")], paper_only=True),
    ReportSection("paper", "sections/paper.html.j2",
                  lambda page: [("paths", "Figures 2 and 3, face to face"),
                                ("series", "Time series")], paper_only=True),
    ReportSection("family", "sections/family.html.j2",
                  _when("family", "family", "Scenario family"), paper_only=True),
    ReportSection("apf_alone", "sections/apf_alone.html.j2",
                  _when("apf_alone", "apf-alone", "What each APF does by itself"),
                  paper_only=True),
    ReportSection("peers", "sections/peers.html.j2",
                  _when("peers", "peers", "Against the methods the paper names"),
                  paper_only=True),
    ReportSection("kinematic", "sections/kinematic.html.j2",
                  _when("kinematic", "kinematic", "Appendix-A track (kinematic)"),
                  paper_only=True),
    # shown without the paper scenario too: make pedestrians on a fresh clone
    ReportSection("pedestrians", "sections/pedestrians.html.j2",
                  _when("pedestrians", "pedestrians", "Real motion: recorded pedestrians")),
    ReportSection("validity", "sections/validity.html.j2",
                  _when("validity", "model-validity", "Does the MPC's model hold?")),
    ReportSection("robustness", "sections/robustness.html.j2",
                  _exploratory("robustness", "robustness", "Robustness (multiverse)"),
                  paper_only=True),
    ReportSection("fair_fight", "sections/fair_fight.html.j2",
                  _exploratory("fair_fight", "fairfight", "Fair fight (tuned)"),
                  paper_only=True),
    ReportSection("ablation", "sections/ablation.html.j2",
                  _when("ablation", "ablations", "Ablations")),
    ReportSection("sweeps", "sections/sweeps.html.j2",
                  lambda page: [(f"sweep-{s.name}", f"Sweep: {s.name}")
                                for s in page["sweeps"]]),
    # reference material: the appendix page
    ReportSection("paper", "sections/paper_metrics.html.j2",
                  lambda page: [("metrics", "All metrics, paper scenario")], paper_only=True,
                  appendix=True),
    ReportSection("kinematic", "sections/kinematic_metrics.html.j2",
                  _when("kinematic", "kinematic-metrics", "All metrics, Appendix-A track"),
                  paper_only=True, appendix=True),
    ReportSection("methods", "sections/definitions.html.j2",
                  lambda page: [("definitions", "Methods: metrics, margins, rules")],
                  appendix=True),
    ReportSection("methods", "sections/compute.html.j2",
                  lambda page: [("compute", "Compute")] if page.get("paper") else [],
                  appendix=True),
    ReportSection("performance", "sections/performance.html.j2",
                  _when("performance", "performance", "Performance")),
    ReportSection("commonroad", "sections/commonroad.html.j2",
                  _when("commonroad", "commonroad", "CommonRoad scenarios")),
    ReportSection("given", "sections/given.html.j2", _given),
    ReportSection("methods", "sections/register.html.j2",
                  lambda page: [("register", "Interpretation register")], appendix=True),
    ReportSection("methods", "sections/provenance.html.j2",
                  lambda page: [("provenance", "Provenance and how to rebuild")],
                  appendix=True),
)


def study_template(key: str) -> str:
    """The template name a study's own section is rendered under."""
    return f"study/{key}.html.j2"


def sections(studies: tuple = ()) -> tuple[ReportSection, ...]:
    """:data:`SECTIONS` with the sections of ``studies`` (registry entries whose ``section``
    is a :class:`~pipeline.store.study_registry.StudySection`), each after the last section
    of the key it names (at the end when no section has that key)."""
    from pipeline.store.study_registry import StudySection

    out = list(SECTIONS)
    for study in studies:
        section = study.section
        if not isinstance(section, StudySection):
            continue
        entry = ReportSection(section.key, study_template(section.key),
                              _when(section.key, section.key.replace("_", "-"), section.title))
        places = [i for i, s in enumerate(out) if s.key == section.after]
        out.insert(places[-1] + 1 if places else len(out), entry)
    return tuple(out)


def page_parts(page: Mapping[str, Any], studies: tuple = ()
               ) -> tuple[list[str], Entries, list[str], list[str], Entries]:
    """For the page's values ``page`` (the sections of ``studies`` included): the templates
    before the contents, the contents' entries (an appendix section's as a place on
    :data:`APPENDIX_PAGE`), the templates after them, and the appendix page's templates and
    entries."""
    shown = [s for s in sections(studies) if page.get("paper") or not s.paper_only]
    return ([s.template for s in shown if s.head],
            [(f"{APPENDIX_PAGE}#{anchor}" if s.appendix else anchor, title)
             for s in shown for anchor, title in s.contents(page)],
            [s.template for s in shown if not s.head and not s.appendix],
            [s.template for s in shown if s.appendix],
            [entry for s in shown if s.appendix for entry in s.contents(page)])
