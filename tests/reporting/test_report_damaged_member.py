"""A report that survives one bad member (issue 62, item 4): a damaged, missing or swapped
``horizon.npz`` or a cut trajectory in a member the pedestrian section draws costs that member
(listed on the page with its folder and reason), never the page (it once ended the report in a
traceback with no index.html); a damaged explorer data file is written again by the next
report (it was kept because its runs had not changed)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

SMALL = ["scenario=pedestrians", "scenario.family.size=6", "scenario.family.n_jobs=1"]


@pytest.fixture(scope="module")
def pristine(make_config, tmp_path_factory) -> tuple[Path, Path]:
    """The paper scenario and a 6-member pedestrian family of baseline and improved, and the
    report of them untouched."""
    from pipeline.reporting.page import build_report
    from pipeline.studies.experiment import run_experiment, run_family

    root = tmp_path_factory.mktemp("damaged") / "outputs"
    for method in ("baseline", "improved"):
        run_experiment(make_config([f"method={method}"]), root / "paper" / method)
        run_family(make_config([f"method={method}"] + SMALL), root / "pedestrians" / method,
                   progress=False, member_cache=None)
    build_report(root, root.parent / "report", "pytest", figure_jobs=1)
    return root, root.parent / "report"


def _damage(member: Path, how: str) -> None:
    if how == "garbage":
        (member / "horizon.npz").write_bytes(b"not a zip file")
    elif how == "missing":
        (member / "horizon.npz").unlink()
    elif how == "cut":
        lines = (member / "trajectory.csv").read_text().splitlines()
        (member / "trajectory.csv").write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    elif how == "swapped":
        other = member.parent / ("member_0001" if member.name != "member_0001" else "member_0002")
        shutil.copy(other / "horizon.npz", member / "horizon.npz")


def _figure_member(html: str) -> int | None:
    found = re.search(r"Member (\d+) of the pedestrian family", html)
    return int(found.group(1)) if found else None


def test_a_damaged_figure_member_costs_that_member_not_the_page(pristine, tmp_path):
    from pipeline.reporting.page import build_report

    root, report = pristine
    chosen = _figure_member((report / "index.html").read_text())
    assert chosen is not None
    for how in ("garbage", "missing", "cut", "swapped"):
        copy = tmp_path / how / "outputs"
        shutil.copytree(root, copy)
        _damage(copy / "pedestrians" / "improved" / f"member_{chosen:04d}", how)
        out = tmp_path / how / "report"
        build_report(copy, out, "pytest", figure_jobs=1)
        html = (out / "index.html").read_text()
        assert 'id="pedestrians"' in html and 'id="pedestrians-damaged"' in html, how
        assert f"member {chosen}: <code>{copy / 'pedestrians' / 'improved'}" in html, how
        assert _figure_member(html) not in (None, chosen), how  # the next readable member


def test_every_member_damaged_leaves_the_page_and_lists_each(pristine, tmp_path):
    from pipeline.reporting.page import build_report

    root, _ = pristine
    copy = tmp_path / "outputs"
    shutil.copytree(root, copy)
    modes = ("garbage", "missing", "cut", "garbage", "missing", "cut")
    for i, how in enumerate(modes):
        _damage(copy / "pedestrians" / "improved" / f"member_{i:04d}", how)
    build_report(copy, tmp_path / "report", "pytest", figure_jobs=1)
    html = (tmp_path / "report" / "index.html").read_text()
    assert 'id="pedestrians"' in html and _figure_member(html) is None
    listed = re.findall(r"<li>member (\d+): <code>", html.split('id="pedestrians-damaged"')[1]
                        .split("</ul>")[0])
    assert sorted(map(int, listed)) == list(range(6))


def test_a_damaged_explorer_data_file_is_written_again(pristine, tmp_path):
    from pipeline.reporting.page import build_report

    root, report = pristine
    out = tmp_path / "report"
    shutil.copytree(report, out)
    data = out / "explorer_data" / "pedestrians" / "0.js"
    good = data.read_bytes()
    data.write_bytes(good[: len(good) // 2])
    build_report(root, out, "pytest", figure_jobs=1)
    assert data.read_bytes() == good
