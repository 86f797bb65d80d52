"""Studies register themselves (issue 57): one YAML per study (``conf/study/<name>.yaml``, or
``study/<name>.yaml`` under a folder of ``$PIPELINE_STUDIES``) gives its subcommand of
``apf-mpc``, its output folders (the layout), its typed result (the report's loader) and its
report section (the one section list). A study planted from a temporary folder (a module on
``PYTHONPATH``, its YAML and its section's template; no package edit) is found in ``apf-mpc
--help``, writes into its folder of the layout and shows in the report's HTML."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pipeline.errors import ConfigError
from pipeline.store.layout import OutputsLayout
from pipeline.store.study_registry import ENV, load_studies

ROOT = Path(__file__).resolve().parents[2]

STUDY_MODULE = '''
"""Counts gates: writes gates.json into --out (a planted study)."""
import json
from pathlib import Path

from pipeline.commands import output_folder, run_command


def add_arguments(parser):
    parser.add_argument("--out", type=output_folder, required=True)
    parser.add_argument("--gates", type=int, default=3, help="how many gates")


def run(args):
    return run_command(lambda: _run(args))


def _run(args):
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "gates.json").write_text(json.dumps({"gates": args.gates}))
    print(f"{args.gates} gates written to {args.out}")
    return 0


class GateResult:
    def __init__(self, gates):
        self.gates = gates

    @staticmethod
    def present(folder):
        return (Path(folder) / "gates.json").is_file()

    @classmethod
    def load(cls, folder):
        return cls(json.loads((Path(folder) / "gates.json").read_text())["gates"])
'''

STUDY_YAML = """
name: gate-count
help: counts the gates (a planted study)
command: gate_study
folders: [gate_count]
result: gate_study:GateResult
section:
  key: gate_count
  title: Gate count
  template: gate_count.html.j2
  after: commonroad
"""

TEMPLATE = """{% if gate_count %}
<h2 id="gate-count">Gate count</h2>
<p>gates counted: <span id="gate-count-value">{{ gate_count.gates }}</span></p>
{% endif %}
"""


@pytest.fixture()
def planted(tmp_path):
    """A study outside the package: its module, its YAML and its template; the environment
    that registers it."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "gate_study.py").write_text(STUDY_MODULE)
    conf = tmp_path / "my_conf" / "study"
    conf.mkdir(parents=True)
    (conf / "gate_count.yaml").write_text(STUDY_YAML)
    (conf / "gate_count.html.j2").write_text(TEMPLATE)
    env = {**os.environ, ENV: str(tmp_path / "my_conf"), "PIPELINE_MEMBER_CACHE": "off",
           "PYTHONPATH": os.pathsep.join([str(tmp_path / "mods"), str(ROOT)])}
    return tmp_path, env


def apf_mpc(args: list[str], env: dict, cwd: Path) -> subprocess.CompletedProcess:
    """``apf-mpc ARGS`` (the console script's function, as installed)."""
    return subprocess.run([sys.executable, "-c", "import sys; from pipeline.cli import main; "
                           "sys.exit(main())", *args], env=env, cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def test_a_planted_study_is_a_subcommand_a_folder_and_a_report_section(planted, monkeypatch):
    """From the temporary folder alone: ``apf-mpc --help`` lists it with its line, ``apf-mpc
    gate-count --help`` shows its own argument, the layout has its folder (not among the
    claims' runs), it writes there, and the report shows its section with the number it
    wrote (7, not the default 3), in the contents after the built-in sections it follows and
    before the register."""
    tmp, env = planted
    shown = apf_mpc(["--help"], env, tmp)
    assert shown.returncode == 0, shown.stderr
    assert re.search(r"^  gate-count +counts the gates \(a planted study\)$", shown.stdout, re.M)
    assert re.search(r"^  tune +", shown.stdout, re.M)  # the package's own still there
    own = apf_mpc(["gate-count", "--help"], env, tmp)
    assert own.returncode == 0 and "--gates GATES" in own.stdout and "usage: apf-mpc gate-count" \
        in own.stdout

    monkeypatch.setenv(ENV, str(tmp / "my_conf"))
    runs = tmp / "runs"
    layout = OutputsLayout.load(runs)
    assert layout.folder("gate_count") == runs / "gate_count"
    assert "gate_count" in layout.not_main_runs and "gate_count" not in layout.canonical

    wrote = apf_mpc(["gate-count", "--out", str(layout.folder("gate_count")), "--gates", "7"],
                    env, tmp)
    assert wrote.returncode == 0, wrote.stderr
    assert (runs / "gate_count" / "gates.json").is_file()
    paper = apf_mpc(["run", "method=baseline", f"hydra.run.dir={runs / 'paper' / 'baseline'}"],
                    env, tmp)
    assert paper.returncode == 0, paper.stderr
    report = apf_mpc(["report", str(runs), "--out", str(tmp / "report"), "--figure-jobs", "1"],
                     env, tmp)
    assert report.returncode == 0, report.stderr
    html = (tmp / "report" / "index.html").read_text()
    assert '<span id="gate-count-value">7</span>' in html
    contents = re.findall(r'<li><a href="(?:appendix\.html)?#([a-z0-9-]+)">',
                          html.split("</nav>")[0])
    assert "gate-count" in contents
    assert contents.index("definitions") < contents.index("gate-count") < \
        contents.index("register")
    # its section on the report's page; the register on the appendix page beside it
    assert 'id="gate-count"' in html and 'id="register"' not in html
    assert 'id="register"' in (tmp / "report" / "appendix.html").read_text()


def test_a_planted_study_without_its_result_shows_no_section(planted, monkeypatch):
    """The same study whose folder holds nothing: no entry in the contents, no section (the
    page reads the study's result, not the registry alone)."""
    from pipeline.reporting.contents import page_parts
    from pipeline.store.study_registry import StudySection

    tmp, _ = planted
    monkeypatch.setenv(ENV, str(tmp / "my_conf"))
    study = next(s for s in load_studies() if s.name == "gate-count")
    assert isinstance(study.section, StudySection)
    page = {"paper": None, "sweeps": (), "given": _Given(), "gate_count": None}
    _, contents, body, _, _ = page_parts(page, (study,))
    assert "gate-count" not in [a for a, _ in contents]
    page["gate_count"] = object()
    _, contents, body, _, _ = page_parts(page, (study,))
    assert ("gate-count", "Gate count") in contents
    assert "study/gate_count.html.j2" in body


class _Given:
    notes, other_runs, skipped = (), (), ()


def test_every_built_in_study_runs_through_the_one_command():
    """Each registered study's subcommand builds its parser (``apf-mpc <study> --help``: exit
    0, its usage line), and every ``$(APF) <study>`` of the Makefile names a registered one."""
    from pipeline.cli import main

    names = [s.name for s in load_studies()]
    assert {"run", "report", "tune", "multiverse", "nmpc-check", "speed-check", "aggregate",
            "score", "verify", "screenshot", "cache", "commonroad", "pedestrians",
            "nmpc-family", "ablation"} <= set(names)
    for name in names:
        if name == "run":
            continue  # Hydra's own --help (its subprocess case: test_the_aliases...)
        with pytest.raises(SystemExit) as done:
            main([name, "--help"])
        assert done.value.code == 0
    makefile = (ROOT / "Makefile").read_text()
    used = set(re.findall(r"\$\(APF\) ([a-z][a-z-]*)", makefile))
    assert used <= set(names) | {"bench"}, used - set(names)
    assert "bench" in {s.name for s in load_studies((ROOT / "benchmarks",))}


def test_the_aliases_and_the_one_command_agree(tmp_path):
    """``python -m pipeline.tune --help`` is ``apf-mpc tune --help``; ``apf-mpc`` alone prints
    the list and exits 2, an unknown study is one line naming the allowed ones."""
    env = {**os.environ, "PIPELINE_MEMBER_CACHE": "off"}
    alias = subprocess.run([sys.executable, "-m", "pipeline.tune", "--help"], env=env,
                           capture_output=True, text=True, cwd=tmp_path)
    one = apf_mpc(["tune", "--help"], env, tmp_path)
    assert alias.returncode == one.returncode == 0 and alias.stdout == one.stdout
    assert one.stdout.startswith("usage: apf-mpc tune")
    bare = apf_mpc([], env, tmp_path)
    assert bare.returncode == 2 and "studies:" in bare.stdout
    unknown = apf_mpc(["nonsense"], env, tmp_path)
    assert unknown.returncode == 2
    assert unknown.stderr.strip().splitlines()[-1].startswith("apf-mpc: error: unknown study")
    assert "tune" in unknown.stderr


@pytest.mark.parametrize("text, key", [
    ("name: tune\ncommand: gate_study\n", "name"),                 # a name taken
    ("name: other\ncommand: gate_study\nnonsense: 1\n", "nonsense"),
    ("name: other\n", "command"),                                  # neither command nor experiment
    ("name: other\ncommand: gate_study\nfolders: [tune]\n", "folders"),   # the tune's folder
    ("name: other\ncommand: gate_study\nfolders: [a]\nclaims_folders: [b]\n", "claims_folders"),
    ("name: Bad Name\ncommand: gate_study\n", "name"),
])
def test_a_bad_registry_entry_is_one_line_naming_its_key(tmp_path, monkeypatch, text, key):
    """An entry that cannot be one: ConfigError naming the file and the key; ``apf-mpc`` exits
    2 with that one line."""
    (tmp_path / "study").mkdir()
    (tmp_path / "study" / "bad.yaml").write_text(textwrap.dedent(text))
    monkeypatch.setenv(ENV, str(tmp_path))
    with pytest.raises(ConfigError) as error:
        load_studies()
    assert error.value.key.endswith(f": {key}")
    from pipeline.cli import main

    assert main(["--help"]) == 2


def test_an_entry_rewritten_with_the_same_size_and_time_is_read_again(tmp_path, monkeypatch):
    """The registry keeps each file's parse per process by its text: an entry rewritten with
    the same size and modification time (rsync -t, two writes within one clock tick) is read
    as it is now, and a section's template removed since is refused again."""
    study = tmp_path / "study"
    study.mkdir()
    entry = study / "gates.yaml"
    monkeypatch.setenv(ENV, str(tmp_path))

    def names() -> set[str]:
        return {s.name for s in load_studies()}

    entry.write_text("name: gatesaaa\ncommand: gate_study\n")
    stamp = entry.stat().st_mtime_ns
    assert "gatesaaa" in names()
    entry.write_text("name: gatesbbb\ncommand: gate_study\n")
    os.utime(entry, ns=(stamp, stamp))
    assert "gatesbbb" in names() and "gatesaaa" not in names()
    (study / "t.html.j2").write_text("<p>gates</p>\n")
    entry.write_text("name: gatesccc\ncommand: gate_study\nsection:\n  key: gates\n"
                     "  title: Gates\n  template: t.html.j2\n  after: answer\n")
    assert "gatesccc" in names()
    (study / "t.html.j2").unlink()
    with pytest.raises(ConfigError, match="template"):
        load_studies()
