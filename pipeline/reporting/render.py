"""The page: every section (:class:`Page`) rendered through ``templates/report.html.j2`` and
its one template per section (``templates/sections/``; a study's own from beside its registry
entry), in the order of the one section list (:mod:`pipeline.reporting.contents`), which also
gives the table of contents; numbers through the filters of :mod:`pipeline.reporting.format`."""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields
from typing import Any

import jinja2

from pipeline.reporting.contents import page_parts, study_template
from pipeline.reporting.explorer import explorer_href
from pipeline.reporting.format import FILTERS, interval
from pipeline.reporting.sections.ablation import AblationSection
from pipeline.reporting.sections.answer import AnswerSection
from pipeline.reporting.sections.apf_alone import ApfAloneSection
from pipeline.reporting.sections.commonroad import CommonRoadSection
from pipeline.reporting.sections.fair_fight import FairFightSection
from pipeline.reporting.sections.family import FamilySection
from pipeline.reporting.sections.kinematic import KinematicSection
from pipeline.reporting.sections.looks import LooksSection
from pipeline.reporting.sections.methods import MethodsSection
from pipeline.reporting.sections.paper import PaperSection
from pipeline.reporting.sections.pedestrians import PedestriansSection
from pipeline.reporting.sections.peers import PeersSection
from pipeline.reporting.sections.performance import PerformanceSection
from pipeline.reporting.sections.robustness import RobustnessSection
from pipeline.reporting.sections.runs_given import RunsGivenSection
from pipeline.reporting.sections.sweeps import SweepSection
from pipeline.reporting.sections.validity import ValiditySection


@dataclass(frozen=True)
class Page:
    """Every section of the report (None: not shown; ``paper`` None: a sweep-only page)."""

    paper: PaperSection | None
    answer: AnswerSection
    family: FamilySection | None
    apf_alone: ApfAloneSection | None
    peers: PeersSection | None
    kinematic: KinematicSection | None
    looks: LooksSection | None
    robustness: RobustnessSection | None
    fair_fight: FairFightSection | None
    validity: ValiditySection | None
    ablation: AblationSection | None
    sweeps: tuple[SweepSection, ...]
    performance: PerformanceSection | None
    given: RunsGivenSection
    methods: MethodsSection
    commonroad: CommonRoadSection | None = None
    pedestrians: PedestriansSection | None = None
    #: the sections of studies from outside the package: (registry entry, the study's result
    #: or None), each shown under its section's key
    study_sections: tuple[tuple[Any, Any], ...] = ()


def environment(studies: tuple = ()) -> jinja2.Environment:
    """The report's Jinja environment: its templates (and the sections' templates of
    ``studies``, registry entries), autoescaping, strict about undefined names, the number
    filters."""
    own = tuple((study_template(s.section.key), s.section.template.read_text())
                for s in studies)
    return _environment(own)


@functools.lru_cache(maxsize=8)
def _environment(own: tuple[tuple[str, str], ...]) -> jinja2.Environment:
    """:func:`environment` with the studies' templates ``own`` (name and text): one per process
    and set of templates, so each template is compiled once (Jinja keeps them, and reloads a
    package template whose file changed; compiling them again for every page cost about
    0.5 CPU-s a report)."""
    loader = jinja2.ChoiceLoader([jinja2.PackageLoader("pipeline.reporting", "templates"),
                                  jinja2.DictLoader(dict(own))])
    env = jinja2.Environment(loader=loader,
                             autoescape=jinja2.select_autoescape(["html", "j2"]),
                             undefined=jinja2.StrictUndefined)
    env.filters.update(FILTERS)
    env.globals["interval"] = interval
    env.globals["explorer_href"] = explorer_href
    return env


def render(page: Page) -> tuple[str, str]:
    """The report's page and its appendix page (:data:`~pipeline.reporting.contents.APPENDIX_PAGE`)
    as HTML (every figure must be on disk: their PNGs are inlined)."""
    context: dict[str, Any] = {f.name: getattr(page, f.name) for f in fields(page)
                               if f.name != "study_sections"}
    studies = tuple(study for study, _ in page.study_sections)
    context.update({study.section.key: value for study, value in page.study_sections})
    head, contents, body, appendix, appendix_contents = page_parts(context, studies)
    template = environment(studies).get_template("report.html.j2")
    main = template.render(**context, head_sections=head, contents=contents,
                           body_sections=body, appendix_page=False)
    # the appendix: its own sections, its contents the places on it and the way back
    return main, template.render(
        **context, head_sections=[],
        contents=[("index.html", "Back to the report"), *appendix_contents],
        body_sections=appendix, appendix_page=True)
