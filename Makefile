# One place for paths and commands. `make help` lists the targets.
PYTHON_BOOT ?= $(shell command -v python3.11 || command -v python3)
VENV        := .venv
PY          := $(VENV)/bin/python
# the one command (apf-mpc: `apf-mpc --help` lists every study, `apf-mpc <study> --help` its
# arguments), run from the venv's Python
APF         := $(PY) -m pipeline.cli
STAMP       := $(VENV)/.installed
RUNS        ?= outputs
FAMILY_SIZE ?= 200
KINEMATIC_FAMILY_SIZE ?= 50
# the methods the paper names run on the ledgers' first PEERS_FAMILY_SIZE (lateral) and
# KINEMATIC_PEERS_FAMILY_SIZE (Appendix-A track) scenarios in make reproduce (member i is the
# same scenario in any family of the same seed), to keep it within its three minutes; make
# peers runs them on all FAMILY_SIZE and KINEMATIC_FAMILY_SIZE
PEERS_FAMILY_SIZE ?= 50
KINEMATIC_PEERS_FAMILY_SIZE ?= 25
# their families' workers: one (the parent simulates) beside make reproduce's other seven
# experiments, where a pool of its own buys nothing and costs its start-up (measured: 43 against
# 56 CPU-s for both); make peers runs them on both cores
PEERS_JOBS ?= 1
# the other families of make reproduce's eight experiments: one worker each (the parent simulates)
# for the same reason; measured on a fresh clone, make experiment without the member cache took
# 139 s and 259 CPU-s against 151 s and 292 CPU-s with two workers each (the members' files
# byte-identical either way); `make run-family FAMILY_JOBS=2` runs one alone on both cores
FAMILY_JOBS ?= 1
# make pedestrians: the recorded-pedestrian family (ETH/UCY), not part of make reproduce
PEDESTRIANS_FAMILY_SIZE ?= 200
# the variants of make pedestrians (conf/experiment/pedestrians_<variant>.yaml) and their size
PEDESTRIANS_VARIANTS ?= car aimed reactive lateral
PEDESTRIANS_VARIANTS_FAMILY_SIZE ?= 30
# make euro-ncap: tests per method (the protocol's grid of 5 cases x 11 speeds, twice)
EURO_NCAP_FAMILY_SIZE ?= 110
REPORT      ?= reports/latest
PYTEST_ARGS ?=
PYTEST_JOBS ?= auto
INSTALLER   ?= uv
# WARM=no: make install without its warm step (the bytecode and numba caches; the install test,
# which checks the packages alone, while tests/integration/test_warm.py checks the warm step)
WARM        ?= yes

SWEEP       ?= obstacle_speed
MULTIVERSE  ?= default
TUNE        ?= default
# where make tune's families run: local (this machine), dask-local:N, dask://HOST:PORT, dask-slurm:N
WORKERS     ?= local
# the lateral-track peers make tune-peers tunes against improved, and the Appendix-A track's
# (dwa exists on that track only; its method preset is dwa_kinematic)
TUNE_PEERS  ?= mpc_dcbf cbf_filter vo
TUNE_KINEMATIC_PEERS ?= dwa
# the scenario the README's explorer screenshot shows (<experiment>/<member>)
SCREENSHOT_MEMBER ?= family/0
# a tuning on the Appendix-A track (tune.track kinematic): Clarabel for every family (the
# kinematic MPC's QP has no DAQP form) and a hypervolume box that holds that track's values
# (measured on make reproduce's kinematic_family and kinematic_peers: family means reaction
# 0.1-1.7 s, jerk 0.3-37 m/s^3 with improved at 6.6 and the peers at 0.3-1.8, recovery
# 0.3-3.2 s; the lateral box [0.5, 3] of jerk would leave improved's untuned setting outside)
KINEMATIC_TUNE_SETS := --set track=kinematic --set backend=clarabel_direct \
  --set heldout_backend=clarabel_direct --set "hypervolume_bounds=[[0.0,2.0],[0.0,12.0],[0.0,5.0]]"
export SLURM_CI_DIR ?= /tmp/slurm-ci
# one member cache for every study (pipeline/store/member_cache.py): a family member simulated by
# one study is restored, not simulated again, by any other with the same settings and code;
# MEMBER_CACHE=off turns it off (make test always runs without it)
MEMBER_CACHE ?= $(RUNS)/member_cache
export PIPELINE_MEMBER_CACHE = $(if $(filter off,$(MEMBER_CACHE)),off,$(abspath $(MEMBER_CACHE)))
LAUNCHER    ?= sequential
# the command the report stamps under provenance: the make command that actually ran, with its
# command-line variables (make tune TUNE=quick); exported, so that a sub-make's report (make
# tune's $(MAKE) report) stamps the command typed, not "make report"
export REPORT_COMMAND ?= make $(strip $(MAKECMDGOALS) $(MAKEOVERRIDES))

.PHONY: help install lint clip reproduce experiment frames test-integration run-paper run-kinematic run-kinematic-readings run-family run-kinematic-family run-frames run-apf-alone run-peers run-kinematic-peers run-paper-scenario peers speed-check nmpc-family report screenshot sweep verify ablation multiverse pedestrians euro-ncap tune tune-unpruned tune-peers nmpc-check test test-machine test-slurm test-all bench install-commonroad commonroad cache-size clean-cache clean

help:  ## list the targets
	@grep -E '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-12s %s\n", $$1, $$2}'

# uv (from the package registry, pinned in constraints.txt) installs the same pins in a fraction
# of pip's time; pip is the fallback whenever uv cannot be installed or fails (INSTALLER=pip
# forces it). The uv path creates the venv without pip (0.1 s instead of ensurepip's 2.7 s),
# fetches uv with the interpreter's own pip into the venv's .uv-boot folder, and lets uv install
# the project, pip and uv into the venv: first from uv's cache alone (--offline: 1 s where every
# pinned package is cached; this machine's package proxy answers every revalidation as modified,
# so an online resolution takes 2-7 s), else from the registry. Neither path compiles all of
# site-packages twice: pip compiles everything it installs (always), uv nothing; then
# pipeline.warm writes the bytecode of exactly the modules the commands import (where
# PYTHONDONTWRITEBYTECODE is set, Python would otherwise compile them again in every process:
# 5 s of optuna alone) and, on the other core, puts the loop's numba kernels in numba's cache
# (otherwise a first make reproduce's eight experiments and their workers each compile them at
# once). Measured on 2 cores, package caches warm: about 10 s against pip's 37 s
# (make bench: install_over_pip)
UV_BOOT := $(VENV)/.uv-boot/bin/uv
UV_INSTALL := --quiet --python $(PY) -c constraints.txt -e ".[test]" pip uv
# pip's fallback installs without byte-compiling every package (--no-compile, as uv does: half
# its time, 49 -> 23 s measured); the project's own modules are compiled below, the packages'
# as the warm-up imports them
$(STAMP): pyproject.toml constraints.txt
	@if [ "$(INSTALLER)" = uv ] && $(PYTHON_BOOT) -m venv --without-pip $(VENV) \
	    && $(PYTHON_BOOT) -m pip install --quiet --upgrade --target $(VENV)/.uv-boot -c constraints.txt uv \
	    && { $(UV_BOOT) pip install --offline $(UV_INSTALL) 2>/dev/null || $(UV_BOOT) pip install $(UV_INSTALL); }; then \
	  echo "installed with uv"; \
	else \
	  echo "installing with pip"; \
	  $(PYTHON_BOOT) -m venv $(VENV) && \
	  $(PY) -m pip install --quiet --upgrade pip && \
	  $(PY) -m pip install --quiet --no-compile -c constraints.txt -e ".[test]"; \
	fi
	$(PY) -m compileall -q pipeline hydra_plugins examples > /dev/null
	@if [ "$(WARM)" = yes ]; then \
	  $(PY) -m pipeline.warm --no-kernels & bytecode=$$!; \
	  $(PY) -m pipeline.warm --kernels-only; kernels=$$?; wait $$bytecode && exit $$kernels; \
	fi
	touch $(STAMP)

install: $(STAMP)  ## create .venv and install the project with pinned versions

experiment: $(STAMP)  ## run every method on the paper scenario and on the scenario family
	@# outputs/frames too: the fixed frame's families (make frames) are made again after it,
	@# never shown beside a family of other code or settings
	rm -rf $(RUNS)/paper $(RUNS)/kinematic $(RUNS)/kinematic_readings $(RUNS)/kinematic_family $(RUNS)/family $(RUNS)/frames $(RUNS)/apf_alone $(RUNS)/peers $(RUNS)/kinematic_peers  # rebuilt; members come back from the member cache only for the same code and settings
	@# the eight experiments in six jobs (the paper scenario's three share one process), three
	@# at a time, the longest first: each family's parent has serial stretches (Hydra's job
	@# set-up, the compilation, the tables) in which the others use the cores (measured: 162-166 s
	@# against 173-178 s one family after the other). Three, not all six: on the 2-core machine
	@# of 2026-12-07 the six jobs of make experiment took 134 s and 143 s three at a time, 133 s
	@# and 139 s two at a time, 152 s and 147 s all six at once (about 10 % more CPU-s: six
	@# processes thrash two cores' caches). Each one's output is printed whole when it ends
	@# (-O). The earlier frame's 600 members (make frames, about 60 CPU-s) are not among them.
	@echo "eight experiments in six jobs, three at a time (the paper scenario's three in one process); each one's output follows when it ends"
	$(MAKE) --no-print-directory -j3 -O run-family run-peers run-kinematic-family run-kinematic-peers run-apf-alone run-paper-scenario

frames: $(STAMP)  ## after make reproduce: the lateral MPC in its earlier frame (the state against the start-goal line) on the same 200 scenarios, for the report's "Does the MPC's model hold?" (about 1 min), then the report
	rm -rf $(RUNS)/frames
	$(MAKE) --no-print-directory run-frames FAMILY_JOBS=2
	$(MAKE) report

# the experiments of `make experiment` (run side by side from there)
run-paper run-kinematic run-kinematic-readings: run-%: $(STAMP)
	$(APF) run experiment=$(subst -,_,$*) hydra.sweep.dir=$(RUNS)/$(subst -,_,$*)

# the three experiments on the paper's one scenario in one process (apf-mpc run's --next: one
# start-up instead of three, about 6 CPU-s each)
run-paper-scenario: $(STAMP)
	$(APF) run experiment=paper hydra.sweep.dir=$(RUNS)/paper --next experiment=kinematic hydra.sweep.dir=$(RUNS)/kinematic --next experiment=kinematic_readings hydra.sweep.dir=$(RUNS)/kinematic_readings

run-family: $(STAMP)
	$(APF) run experiment=family hydra.sweep.dir=$(RUNS)/family scenario.family.size=$(FAMILY_SIZE) scenario.family.n_jobs=$(FAMILY_JOBS)

run-frames: $(STAMP)
	$(APF) run experiment=frames hydra.sweep.dir=$(RUNS)/frames scenario.family.size=$(FAMILY_SIZE) scenario.family.n_jobs=$(FAMILY_JOBS)

run-apf-alone: $(STAMP)
	$(APF) run experiment=apf_alone hydra.sweep.dir=$(RUNS)/apf_alone scenario.family.size=$(FAMILY_SIZE) scenario.family.n_jobs=$(FAMILY_JOBS)

run-peers: $(STAMP)
	$(APF) run experiment=peers hydra.sweep.dir=$(RUNS)/peers scenario.family.size=$(PEERS_FAMILY_SIZE) scenario.family.n_jobs=$(PEERS_JOBS)

run-kinematic-peers: $(STAMP)
	$(APF) run experiment=kinematic_peers hydra.sweep.dir=$(RUNS)/kinematic_peers scenario.family.size=$(KINEMATIC_PEERS_FAMILY_SIZE) scenario.family.n_jobs=$(PEERS_JOBS)

run-kinematic-family: $(STAMP)
	$(APF) run experiment=kinematic_family hydra.sweep.dir=$(RUNS)/kinematic_family scenario.family.size=$(KINEMATIC_FAMILY_SIZE) scenario.family.n_jobs=$(FAMILY_JOBS)

report: $(STAMP)  ## rebuild the HTML report from existing run folders (no simulation)
	$(APF) report $(RUNS) --out $(REPORT) --command "$(REPORT_COMMAND)"

screenshot: $(STAMP)  ## the README's screenshots (docs/report_screenshot*.png: 1280 and 390 px, and the explorer) from make reproduce's own report
	$(APF) screenshot $(REPORT)/index.html docs/report_screenshot.png \
	  --narrow docs/report_screenshot_390.png --explorer docs/explorer_screenshot.png --member $(SCREENSHOT_MEMBER)

# the member a clip draws (make clip MEMBER=family/113: <experiment>/<index>, as the explorer names it)
MEMBER ?= family/0
clip: $(STAMP)  ## one member as an animated GIF for slides: make clip MEMBER=family/113 -> $(REPORT)/clips/family_113.gif (the explorer links to it)
	$(APF) clip "$(MEMBER)" --outputs "$(RUNS)" --out "$(REPORT)/clips/$(subst /,_,$(MEMBER)).gif"

reproduce: experiment report  ## set up, run the experiment and write reports/latest/index.html (its last lines: the verdicts in words)

sweep: $(STAMP)  ## run a sweep preset (SWEEP=sensitivity|horizon|obstacle_speed, LAUNCHER=sequential|local_cores|basic)
	$(APF) run sweep=$(SWEEP) hydra/launcher=$(LAUNCHER)
	$(APF) report $(RUNS) --sweep $(RUNS)/sweeps/$(SWEEP) --out $(REPORT) --command "$(REPORT_COMMAND)"

ablation: $(STAMP)  ## which revision does what: ablations + interpretation variants on the family
	rm -rf $(RUNS)/ablation $(RUNS)/interpretations
	$(APF) ablation --out $(RUNS)/ablation scenario.family.size=$(FAMILY_SIZE)
	$(APF) run experiment=interpretations hydra.sweep.dir=$(RUNS)/interpretations
	$(MAKE) report

pedestrians: $(STAMP)  ## improved and baseline among recorded pedestrians (ETH/UCY, docs/pedestrians.md): a sidewalk robot that can stop, and the variants (car, aimed crossings, reactive walkers; about 3 min), then the report
	rm -rf $(RUNS)/pedestrians $(RUNS)/pedestrians_variants
	@# the family, then the variants one after the other in the same process (apf-mpc run's
	@# --next: one start-up, one set of kernels and workers; the same files, byte for byte, as
	@# five processes, 33 against 53 s at 12 members each, measured 2026-12-06). Side by side
	@# (make -j5 -O) they took as long or longer: the families are CPU-bound on two cores
	$(APF) run experiment=pedestrians hydra.sweep.dir=$(RUNS)/pedestrians scenario.family.size=$(PEDESTRIANS_FAMILY_SIZE) \
	  $(foreach variant,$(PEDESTRIANS_VARIANTS),--next experiment=pedestrians_$(variant) hydra.sweep.dir=$(RUNS)/pedestrians_variants/$(variant) scenario.family.size=$(PEDESTRIANS_VARIANTS_FAMILY_SIZE))
	$(MAKE) report

euro-ncap: $(STAMP)  ## the methods on Euro NCAP's AEB/LSS VRU crossings (a child from between parked cars, adults, a cyclist; both tracks and braking; docs/euro_ncap.md), then the report
	$(APF) euro-ncap --family-size $(EURO_NCAP_FAMILY_SIZE) --out $(RUNS)/euro_ncap
	$(MAKE) report

multiverse: $(STAMP)  ## how robust is each verdict: the multiverse (MULTIVERSE=default|quick), then the report
	$(APF) multiverse --space $(MULTIVERSE) --out $(RUNS)/multiverse
	$(MAKE) report

tune: $(STAMP)  ## a fair fight: both methods tuned with one budget, judged on held-out scenarios (TUNE=default|quick; WORKERS=dask-local:N|dask://HOST:PORT|dask-slurm:N for a Dask cluster), then the report
	$(APF) tune --space $(TUNE) --workers $(WORKERS) --out $(RUNS)/tune
	$(MAKE) report

tune-unpruned: $(STAMP)  ## the pruning check: the default tune with every trial on its whole training family (outputs/tune_unpruned; make bench compares it with make tune's)
	$(APF) tune --space $(TUNE) --set 'rungs=[]' --set name=$(TUNE)_unpruned --out $(RUNS)/tune_unpruned

# each peer in its own tune against improved: the same preset (budget, replicates, convergence rule,
# pruning, held-out family) as make tune; no matched control (it is the baseline's); the feasibility
# threshold the untuned baseline's collisions, as in make tune, so improved's trials are make tune's
tune-peers: $(STAMP)  ## the fair fight against each lateral peer (TUNE_PEERS) and each Appendix-A one (TUNE_KINEMATIC_PEERS), tuned as make tune tunes improved and the baseline (outputs/tune_peers/<peer>), then the report
	set -e; for peer in $(TUNE_PEERS); do \
	  $(APF) tune --space $(TUNE) --workers $(WORKERS) --set "methods=[improved,$$peer]" \
	    --set "matched_control=''" --set safety_reference=baseline \
	    --set name=$(TUNE)_vs_$$peer --out $(RUNS)/tune_peers/$$peer; \
	done; \
	for peer in $(TUNE_KINEMATIC_PEERS); do \
	  $(APF) tune --space $(TUNE) --workers $(WORKERS) --set "methods=[improved,$${peer}_kinematic]" \
	    --set "matched_control=''" --set safety_reference=baseline $(KINEMATIC_TUNE_SETS) \
	    --set name=$(TUNE)_vs_$${peer}_kinematic --out $(RUNS)/tune_peers/$${peer}_kinematic; \
	done
	$(MAKE) report

peers: $(STAMP)  ## the methods the paper names on both tracks' whole families (make reproduce: their first 50 / 25 scenarios), then the report
	rm -rf $(RUNS)/peers $(RUNS)/kinematic_peers
	$(MAKE) --no-print-directory -j2 -O run-peers run-kinematic-peers PEERS_FAMILY_SIZE=$(FAMILY_SIZE) KINEMATIC_PEERS_FAMILY_SIZE=$(KINEMATIC_FAMILY_SIZE) PEERS_JOBS=2
	$(MAKE) report

nmpc-family: $(STAMP)  ## the judge of record: the ledger's methods on the scenario family under the nonlinear MPC (CasADi + IPOPT, about 3 min), then the report
	rm -rf $(RUNS)/nmpc_family
	$(APF) nmpc-family --out $(RUNS)/nmpc_family scenario.family.size=$(FAMILY_SIZE)
	$(MAKE) report

nmpc-check: $(STAMP)  ## each track's linear MPC against the nonlinear MPC (CasADi) on the paper scenario and 50 family members per method, then the report
	$(APF) nmpc-check --out $(RUNS)/nmpc_check
	$(MAKE) report

speed-check: $(STAMP)  ## is slower ever less safe? both methods at 1.5 and 3 m/s and with velocity planning, then the report
	$(APF) speed-check --out $(RUNS)/speed
	$(MAKE) report

# the benchmark harness lives in the repository (benchmarks/, a study registered from outside the
# package: $PIPELINE_STUDIES names its folder); the report reads its typed result from reports/bench
bench: $(STAMP)  ## benchmark the controller step vs the Clarabel floor and the peers -> reports/bench/
	PIPELINE_STUDIES=benchmarks PYTHONPATH=. $(APF) bench --out reports/bench
	$(PY) -m benchmarks.bench_aggregate 10000

verify: reproduce  ## rerun `make reproduce` and compare with reports/reference/ (tolerances in pipeline/studies/verify.py)
	$(APF) verify $(RUNS) reports/reference

test: $(STAMP)  ## lint and type-check (make lint, run as a test) and every stage's tests on every core (PYTEST_JOBS=auto; excludes the integration tier, make test-integration, and tests marked slow, slurm or machine)
	@# one test file per worker at a time (--dist loadfile), so a file's shared runs are made once;
	@# in the order tests/conftest.py gives them, the longest first (xdist would otherwise reorder
	@# the files by their number of tests and leave a long file of few tests for the end).
	@# make lint is a test (tests/commands/test_lint.py, started first): it runs beside the
	@# others on one worker (mypy alone took 25 s of one core on a fresh clone before the first
	@# test started), and a lint failure is one of pytest's failures, named in its summary
	PIPELINE_MEMBER_CACHE=off $(PY) -m pytest -m "$(TEST_MARKERS)" -n $(PYTEST_JOBS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS)

# make test's selection: every test but the integration tier (tests/integration/: whole studies,
# the browser, processes signalled, the wheel; make test-integration), the slow ones, the SLURM
# ones (make test-slurm) and the machine's (make test-machine). With the integration tier make
# test took 853-942 s on this session's machine (2026-12-07), 611 s without it (with the Hydra
# launchers' tests, test_sweeps.py, which start processes and now stand in the tier); CI runs
# every tier
TEST_MARKERS = not slow and not slurm and not machine and not integration
INTEGRATION_MARKERS = integration and not slow and not slurm and not machine

test-integration: $(STAMP)  ## the integration tier (tests/integration/: whole studies, the tune, the multiverse, the report in a browser, processes signalled, the wheel; CI runs it after make test)
	PIPELINE_MEMBER_CACHE=off $(PY) -m pytest -m "$(INTEGRATION_MARKERS)" -n $(PYTEST_JOBS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS)

test-machine: $(STAMP)  ## the tests of the machine around the package: make install into fresh venvs (uv and pip), its warm step, a local Dask cluster (CI runs it after make test)
	PIPELINE_MEMBER_CACHE=off $(PY) -m pytest -m "machine and not slurm" -n $(PYTEST_JOBS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS)

lint: $(STAMP)  ## ruff (pyflakes, bugbear, isort, pyupgrade, simplify, complexity) and mypy, as configured in pyproject.toml
	$(PY) -m ruff check pipeline tests hydra_plugins examples benchmarks
	$(PY) -m mypy

test-slurm: $(STAMP)  ## start a single-node SLURM cluster (.ci/slurm-cluster), run the SLURM tests, stop it
	.ci/slurm-cluster start
	PIPELINE_MEMBER_CACHE=off SLURM_CONF=$(SLURM_CI_DIR)/slurm.conf $(PY) -m pytest -m slurm -p no:cacheprovider $(PYTEST_ARGS); \
	  status=$$?; .ci/slurm-cluster stop; exit $$status

test-all: $(STAMP)  ## run every test, slow ones included (SLURM ones: make test-slurm)
	$(PY) -m pytest -m "not slurm" $(PYTEST_ARGS)

# scenario=commonroad (docs/commonroad.md): the optional extra into .venv (Polygon3 builds from
# source: a C compiler; .ci/run installs build-essential), and both methods on one file
install-commonroad: $(STAMP)  ## add the optional CommonRoad extra (commonroad-io, drivability checker, vehicle models) to .venv
	@if [ -x $(VENV)/bin/uv ]; then \
	  { $(VENV)/bin/uv pip install --offline --quiet --python $(PY) -c constraints.txt -e ".[test,commonroad]" 2>/dev/null \
	    || $(VENV)/bin/uv pip install --quiet --python $(PY) -c constraints.txt -e ".[test,commonroad]"; }; \
	else \
	  $(PY) -m pip install --quiet --no-compile -c constraints.txt -e ".[test,commonroad]"; \
	fi
	@# the extra's modules (and the project's that import it) compiled as make install's are
	$(PY) -m pipeline.warm --no-kernels

COMMONROAD ?=
commonroad: $(STAMP)  ## improved and baseline on a CommonRoad scenario: make commonroad COMMONROAD=path/to/scenario.xml (needs make install-commonroad)
	@test -n "$(COMMONROAD)" || { echo "error: set COMMONROAD=path/to/scenario.xml" >&2; exit 2; }
	@path="$$(realpath -m -- "$(COMMONROAD)")"; \
	$(APF) commonroad "$$path" --methods improved,baseline --out $(RUNS)/commonroad

cache-size: $(STAMP)  ## what the member cache holds (members, files, MB)
	$(APF) cache size

clean-cache: $(STAMP)  ## empty the member cache (every study then simulates its members again)
	$(APF) cache clean

clean:  ## remove generated output (keeps .venv)
	rm -rf outputs multirun $(REPORT)
