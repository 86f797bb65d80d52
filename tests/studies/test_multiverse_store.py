"""Hostile class: the multiverse's folder trusted by name.

The multiverse resumed a family whose member file had been cut (the family's manifest still
matched) and rewrote ``space.json`` on a rerun of a complete study. Now a family is resumed only
when every member file matches its member's manifest (a cut member is simulated again, the
others kept), a rerun whose result is unchanged rewrites nothing (``space.json`` keeps the
first run's bookkeeping), and a second study on the folder is refused in one line.
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pytest

from pipeline.errors import FolderBusyError
from pipeline.store.lock import folder_lock
from pipeline.studies.multiverse import load_space, run_multiverse
from pipeline.studies.results.multiverse import SPACE

#: a tiny space: one simulation dimension, one metric reading (its re-scoring reads every
#: member's trajectory) and one statistic, on families of four
TINY = """name: tiny
family_size: 4
family_seed: 0
n_specifications: 4
sample_seed: 0
simulation_pool: 1
backend: daqp
n_resamples: 99
min_pairs: 2
dimensions:
  - {key: planner.beta, stage: simulation, applies_to: [improved], values: [0.25, 1.0]}
  - {key: metrics.reaction_obstacle, stage: analysis, values: [threatening, first_visible]}
"""


def _files(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*")
            if p.is_file() and p.name != ".lock"}


def test_a_cut_member_is_simulated_again_and_a_complete_rerun_rewrites_nothing(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    space = load_space(path)
    out = tmp_path / "mv"
    lines: list[str] = []
    first = run_multiverse(space, out, ["scenario.family.n_jobs=1"], n_jobs=1,
                           log=lines.append)
    assert first.info.overrides == ("scenario.family.n_jobs=1",)
    specifications = (out / "specifications.csv").read_bytes()

    # a rerun of the complete study: read back, not one file written
    before = _files(out)
    lines.clear()
    again = run_multiverse(space, out, ["scenario.family.n_jobs=1"], n_jobs=1,
                           log=lines.append)
    assert _files(out) == before
    assert any("the result is unchanged; its files are kept as written" in line
               for line in lines), lines
    assert again.info.overrides == first.info.overrides
    assert '"overrides": [\n    "scenario.family.n_jobs=1"\n  ]' in (out / SPACE).read_text()

    # one member's trajectory cut after the study was written
    family = next((out / "runs" / "improved").iterdir())
    member = family / "member_0001"
    trajectory = member / "trajectory.csv"
    whole = trajectory.read_bytes()
    trajectory.write_bytes(whole[:len(whole) // 3])
    kept = {p: p.stat().st_mtime_ns for p in (family / "member_0000").iterdir()}
    lines.clear()
    run_multiverse(space, out, ["scenario.family.n_jobs=1"], n_jobs=1, log=lines.append)
    assert trajectory.read_bytes() == whole  # simulated again, the same run
    assert {p: p.stat().st_mtime_ns for p in kept} == kept  # the other members kept
    assert (out / "specifications.csv").read_bytes() == specifications
    assert any("1 family runs to do" in line for line in lines), lines

    # a second study on the same folder: one line, nothing written
    with folder_lock(out, "multiverse tiny"):
        before = _files(out)
        with pytest.raises(FolderBusyError) as info:
            run_multiverse(space, out, ["scenario.family.n_jobs=1"], n_jobs=1,
                           log=lines.append)
        assert str(info.value).startswith(
            f"{out} is in use by another study (multiverse tiny, pid {os.getpid()})")
        assert _files(out) == before
    assert len(pd.read_csv(out / "specifications.csv"))
