"""Report stage: run folders and study results into one self-contained HTML page.

``python -m pipeline.report RUNS_DIR [--out reports/latest]`` (:mod:`pipeline.report`) calls
:func:`build_report`: read everything once (:class:`~pipeline.reporting.inputs.ReportInputs`),
compute every ledger once (:class:`~pipeline.reporting.verdicts.Verdicts`), write the tables,
build each section (:mod:`pipeline.reporting.sections`), render the page
(:mod:`pipeline.reporting.render`) with its figures inlined and the SVGs beside it, and write
``answer.txt``. It never simulates and never runs a study.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

from pipeline.reporting.contents import APPENDIX_PAGE
from pipeline.reporting.explorer import remove_explorer_temporaries, write_explorer
from pipeline.reporting.figure import Figures
from pipeline.reporting.figures import FigureWriter
from pipeline.reporting.inputs import ReportInputs
from pipeline.reporting.render import Page, render
from pipeline.reporting.sections.ablation import ablation_section
from pipeline.reporting.sections.answer import AnswerContext, answer_section
from pipeline.reporting.sections.apf_alone import apf_alone_section
from pipeline.reporting.sections.commonroad import commonroad_section
from pipeline.reporting.sections.fair_fight import fair_fight_section
from pipeline.reporting.sections.family import family_section
from pipeline.reporting.sections.kinematic import kinematic_section
from pipeline.reporting.sections.looks import looks_section
from pipeline.reporting.sections.methods import methods_section
from pipeline.reporting.sections.paper import paper_section
from pipeline.reporting.sections.pedestrians import pedestrians_section
from pipeline.reporting.sections.peers import peers_section
from pipeline.reporting.sections.performance import performance_section
from pipeline.reporting.sections.robustness import robustness_section
from pipeline.reporting.sections.runs_given import runs_given_section
from pipeline.reporting.sections.sweeps import sweep_section
from pipeline.reporting.sections.validity import validity_section
from pipeline.reporting.style import FigureStyle
from pipeline.reporting.tables import write_tables
from pipeline.reporting.verdicts import Verdicts, beyond_bound_shares
from pipeline.store.files import write_text_atomic
from pipeline.store.interval_memo import INTERVAL_MEMO, load_interval_memo, save_interval_memo
from pipeline.store.runs import Skipped

log = logging.getLogger("pipeline.reporting")


def build_report(run_root: Path, out_dir: Path, command: str,
                 sweep_dirs: tuple[Path, ...] = (), bench_dir: Path | None = None,
                 multiverse_dir: Path | None = None,
                 skipped: list[Skipped] | None = None, tune_dir: Path | None = None,
                 treatment: str | None = None, controls: tuple[str, ...] = (),
                 style: FigureStyle | None = None, figure_jobs: int | None = None) -> Path:
    """Write ``out_dir/index.html`` (plus figures/, tables/ and answer.txt) from the runs
    under ``run_root`` and the studies' results.

    Parameters
    ----------
    run_root : Path
        Folder with the paper, kinematic and family runs (``make reproduce``'s ``outputs``),
        or a parameter-sweep folder on its own.
    sweep_dirs : tuple of Path
        Aggregated sweep folders to add as Sweep sections.
    skipped : list, optional
        Receives every folder passed over (:class:`pipeline.store.runs.Skipped`); they are
        also listed on the page and on stderr.
    style : FigureStyle, optional
        How figures are written; the default when omitted.
    figure_jobs : int, optional
        Figures drawn at the same time, each in a forked child (:class:`FigureWriter`); None:
        the machine's cores; 1: one after the other in this process, and the explorer and its
        members written here too (otherwise in a forked child beside the page, its members in
        that child's children). The files are the same.

    Returns
    -------
    Path
        The HTML file.
    """
    out_dir = Path(out_dir)
    started = time.perf_counter()
    skipped = skipped if skipped is not None else []
    # read (and refused, if it must be) before anything is written
    inputs = ReportInputs.load(run_root, sweep_dirs, bench_dir, multiverse_dir, tune_dir,
                               treatment, controls, skipped)
    # every member of every experiment, animated (explorer.html and its data beside the page):
    # it reads the run folders alone, so it is written beside everything else (the ledgers
    # and the page keep one core busy, the explorer's children the other)
    alone = figure_jobs == 1  # nothing forked: the explorer and its members written here
    with _beside(write_explorer, run_root, out_dir, None, 1 if alone else None,
                 fork=not alone, on_stop=lambda: remove_explorer_temporaries(out_dir)) \
            as explorer:
        path = _report_page(inputs, out_dir, command, skipped, style, figure_jobs, started)
        log.info("report: the scenario explorer (%.0f s)", time.perf_counter() - started)
        explorer.result()
    return path


def _report_page(inputs: ReportInputs, out_dir: Path, command: str, skipped: list[Skipped],
                 style: FigureStyle | None, figure_jobs: int | None, started: float) -> Path:
    """:func:`build_report` but the explorer: the ledgers, tables, figures, page, answer."""
    import matplotlib

    log.info("report: the ledgers (bootstrap intervals) (%.0f s)", time.perf_counter() - started)
    # the intervals an earlier build of this folder computed for the same differences and
    # settings come back from its memo (the same numbers); `make verify` computes them all
    memo = load_interval_memo(out_dir / INTERVAL_MEMO)
    verdicts = Verdicts.compute(inputs, memo=memo)
    save_interval_memo(out_dir / INTERVAL_MEMO, memo)
    log.info("report: %d bootstrap results recalled from the last build, %d computed",
             memo.hits, memo.misses)
    write_tables(inputs, verdicts, out_dir / "tables")
    style = style or FigureStyle()
    # figures drawn in forked children beside the sections (the writer waits for them before
    # the page inlines the PNGs, and on any way out of this block)
    with matplotlib.rc_context(style.rc()), FigureWriter(style, figure_jobs) as writer:
        log.info("report: sections and figures (%.0f s)", time.perf_counter() - started)
        page = build_page(inputs, verdicts, Figures(out_dir, writer), command, skipped)
    log.info("report: writing the page (%.0f s)", time.perf_counter() - started)
    path = out_dir / "index.html"
    main, appendix = render(page)
    write_text_atomic(out_dir / APPENDIX_PAGE, appendix)
    write_text_atomic(path, main)
    if page.answer.figure:  # the answer's figure beside the page, as the page inlines it
        write_text_atomic(out_dir / "figures" / "answer_claims.svg", page.answer.figure)
    # the answer in words, for the command line (make reproduce prints it at its end)
    lines = page.answer.lines
    write_text_atomic(out_dir / "answer.txt", "\n".join(lines) + "\n" if lines else "")
    return path


class _Child:
    """What a forked child (:func:`_beside`) hands back: ``result()`` waits for it and returns
    what its function returned or raises what it raised. A child that dies without answering
    (killed, out of memory) is an error within a tenth of a second, even while a worker it
    forked still holds its end of the pipe: the child's own exit is watched, and its group is
    then stopped."""

    def __init__(self, receiver: Any, process: Any, on_stop: Callable[[], object] | None
                 ) -> None:
        self._receiver, self._process, self._on_stop = receiver, process, on_stop
        self.taken = False

    def result(self) -> Any:
        name = self._process.name
        try:
            # the child's exit by waitpid, not by its pipes: a worker it forked holds copies
            # of their ends and keeps them open
            while not self._receiver.poll(0.1):
                if not self._process.is_alive():
                    if self._receiver.poll():  # it answered, then ended
                        break
                    raise EOFError
            succeeded, value = self._receiver.recv()
        except EOFError:
            self.stop()
            raise RuntimeError(f"the report's {name} ended without an answer (exit code "
                               f"{self._process.exitcode})") from None
        except Exception as exc:  # an answer that pickled but cannot be rebuilt here
            self.stop()
            raise RuntimeError(f"the report's {name} answered what cannot be read here: "
                               f"{type(exc).__name__}: {exc}") from None
        self._process.join()
        self.taken = True
        if succeeded:
            return value
        raise value

    def stop(self) -> None:
        """Kill the child and everything it forked, reap it, remove what a killed writer
        leaves (``on_stop``)."""
        self.taken = True
        _stop_group(self._process)
        if self._on_stop is not None:
            self._on_stop()


def _answer_from_child(function, args: tuple, sender: Any) -> None:
    """In the child: lead a process group of its own (what it forks joins it, so
    :func:`_stop_group` stops them all), run ``function(*args)``, send back what came of it."""
    import os

    with contextlib.suppress(OSError):
        os.setpgid(0, 0)
    try:
        answer: tuple[bool, Any] = (True, function(*args))
    except BaseException as exc:  # handed to the parent, which raises it
        answer = (False, exc)
    try:
        sender.send(answer)
    except Exception as exc:  # a result or an error that does not pickle
        sender.send((False, RuntimeError(f"{type(answer[1]).__name__}: {answer[1]} "
                                         f"(could not be handed over: {exc})")))
    finally:
        sender.close()


def _stop_group(process: Any) -> None:
    """Kill a child of :func:`_beside` and everything it forked (its process group), then
    reap it."""
    import os
    import signal

    try:
        os.killpg(process.pid, signal.SIGKILL)
    except OSError:  # no such group (it never led one, or it is gone): the child alone
        process.kill()
    process.join()


@contextlib.contextmanager
def _beside(function, *args, fork: bool = True,
            on_stop: Callable[[], object] | None = None) -> Iterator[Any]:
    """``function(*args)`` in a forked child while the block runs (here, first, without
    ``fork`` or where the platform cannot fork): the block gets a handle whose ``result()``
    waits for it and re-raises what it raised. A child whose result the block did not take
    (the block raised: an error, Ctrl-C or SIGTERM as :class:`~pipeline.errors.Interrupted`)
    is killed on the way out with everything it forked, so nothing is written after the
    caller returns; then ``on_stop`` removes what a killed writer leaves (its temporaries)."""
    if not fork or "fork" not in multiprocessing.get_all_start_methods():
        done: Future = Future()
        try:
            done.set_result(function(*args))
        except Exception as exc:  # handed over as the child's would be
            done.set_exception(exc)
        yield done
        return
    import os

    context = multiprocessing.get_context("fork")
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_answer_from_child, args=(function, args, sender),
                              name=f"{getattr(function, '__name__', 'child')} process")
    process.start()
    sender.close()
    pid = int(process.pid or 0)
    with contextlib.suppress(OSError):  # here too, so no fork of the child escapes the group
        os.setpgid(pid, pid)
    child = _Child(receiver, process, on_stop)
    try:
        yield child
    finally:
        if not child.taken:
            child.stop()
        receiver.close()


def build_page(inputs: ReportInputs, verdicts: Verdicts, figures: Figures, command: str,
               skipped: list[Skipped]) -> Page:
    """Every section of the page (see :class:`~pipeline.reporting.render.Page`)."""
    paper = paper_section(inputs, verdicts, figures)
    family = family_section(inputs, verdicts, figures) if paper else None
    kinematic = kinematic_section(inputs, verdicts, figures) if paper else None
    robustness = robustness_section(inputs, figures)
    fair_fight = fair_fight_section(inputs, figures)
    apf_alone = apf_alone_section(inputs, verdicts) if paper else None
    peers = peers_section(inputs, verdicts) if paper else None
    return Page(
        paper=paper,
        answer=answer_section(family, robustness, fair_fight, kinematic, verdicts.claims,
                              apf_alone, peers, answer_context(inputs, verdicts, robustness)),
        family=family, apf_alone=apf_alone,
        peers=peers, kinematic=kinematic,
        pedestrians=pedestrians_section(inputs, verdicts, figures),
        looks=looks_section(inputs, verdicts) if paper else None,
        robustness=robustness if paper else None, fair_fight=fair_fight if paper else None,
        validity=validity_section(inputs, verdicts) if paper else None,
        ablation=ablation_section(inputs, verdicts, figures) if paper else None,
        sweeps=tuple(sweep_section(s, figures) for s in inputs.sweeps),
        performance=performance_section(inputs, figures),
        given=runs_given_section(inputs, skipped),
        commonroad=commonroad_section(inputs),
        study_sections=study_sections(inputs),
        methods=methods_section(verdicts.claims if paper else None,
                                {m: r.config for m, r in inputs.lateral.by_method.items()}
                                if inputs.lateral is not None else {}, command))


def study_sections(inputs: ReportInputs) -> tuple[tuple[Any, Any], ...]:
    """The sections studies from outside the package bring (their registry entry's
    ``section``), each with the study's result (None when its folder holds none)."""
    from pipeline.store.study_registry import StudySection, load_studies

    return tuple((study, inputs.studies.get(study.name)) for study in load_studies()
                 if isinstance(study.section, StudySection))


def answer_context(inputs: ReportInputs, verdicts: Verdicts, robustness) -> AnswerContext:
    """What the answer reads besides the sections: the judge of record's verdicts, the
    registered readings under which an outcome changes (from a multiverse at its default
    budget; one below it writes nothing here) and the linear model's share of steps beyond
    its bound per judged method."""
    from pipeline.config import INTERPRETATION_REGISTER

    flips = None
    # a multiverse below its default budget never writes the answer (its own section shows it)
    if inputs.multiverse is not None and robustness is not None and robustness.headline:
        keys = {k.strip() for entry in INTERPRETATION_REGISTER
                for k in entry.config_key.split(",") if not k.strip().startswith("(")}
        flips = inputs.multiverse.reading_flips(keys)
    return AnswerContext(verdicts.nmpc, flips, "",
                         beyond_bound_shares(verdicts.family, verdicts.claims))
