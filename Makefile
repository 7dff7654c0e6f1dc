# One entry point for set-up, checks, the demo and benchmarks. Everything installs into .venv.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out

.PHONY: test test-quick browser lint typecheck pytest pytest-quick compiled demo serve bench clean

$(PY):
	$(PYTHON) -m venv $(VENV)

# pip compiles what it installs on one core; compileall does it on every core (half the time
# here), leaving out the MAVLink dialects nobody loads, the packages' own tests, the parts of
# Ray nothing here starts and the installers (they compile what they import when they run).
NOT_COMPILED := /pymavlink/dialects/v[12]0/(?!ardupilotmega|common|minimal|__init__)|/tests?/|/ray/(rllib|data|serve|tune|train)/|/site-packages/(pip|setuptools|fontTools)/
$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --no-compile -e '.[dev]'
	$(PY) -m compileall -q -j 0 -x '$(NOT_COMPILED)' $$($(PY) -c 'import sysconfig; print(sysconfig.get_path("purelib"))') > /dev/null
	touch $(STAMP)

# The type check runs beside the tests: they leave a core idle part of the time.
test: $(STAMP) browser lint
	$(MAKE) --no-print-directory -j2 typecheck pytest

# The browser tests drive Debian's Chromium (installed here when missing: CI runs as root).
CHROMIUM ?= /usr/bin/chromium
browser:
	@test -x $(CHROMIUM) || { \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium; \
	  else echo "make: $(CHROMIUM) is missing: sudo apt-get install chromium" >&2; exit 1; fi; }

lint: $(STAMP)
	$(VENV)/bin/ruff check planner gcs sitl_stub tests bench
	$(VENV)/bin/ruff format --check planner gcs sitl_stub tests bench

typecheck: $(STAMP)
	$(VENV)/bin/mypy

# On every core and one more (pytest-xdist): a flight waits on its simulator's pace part of
# the time, so one worker per core leaves a fifth of the CPU idle. The long tests (marked
# slow, the whole flights among them) are handed out first, in turn to each worker; a module
# whose fixture flies once (xdist_group) stays on one worker. The 30 slowest tests are listed
# at the end.
TEST_WORKERS ?= $(shell echo $$(( $$(nproc) + 1 )))
PYTEST := $(VENV)/bin/pytest -q -n $(TEST_WORKERS) --dist loadgroup

pytest: $(STAMP) compiled
	$(PYTEST) --durations=30

# Everything but the whole flights and the other long tests (marked slow), mypy beside it.
test-quick: $(STAMP) browser lint
	$(MAKE) --no-print-directory -j2 typecheck pytest-quick

pytest-quick: $(STAMP) compiled
	$(PYTEST) -m "not slow"

# The project's own modules compiled on every core before the tests: each process the tests
# start (a simulator, a service, a command) reads them compiled instead of compiling them
# again (as it must where PYTHONDONTWRITEBYTECODE is set), the better part of a second each.
compiled: $(STAMP)
	$(PY) -m compileall -q -j 0 planner gcs sitl_stub tests bench > /dev/null

demo: $(STAMP)
	mkdir -p $(OUT)
	$(PY) -m planner plan scenarios/paper_three_uav.yaml --seed 1 --out $(OUT)/plan.json
	$(PY) -m planner plot $(OUT)/plan.json --out $(OUT)/paths.png
	$(PY) -m planner schedule scenarios/paper_three_uav.yaml --popup --seed 1 --out $(OUT)/schedule.json --plot $(OUT)/speeds.png
	$(PY) -m planner export $(OUT)/schedule.json --vehicle UAV3 --format qgc --out $(OUT)/UAV3.plan
	$(PY) -m planner export $(OUT)/schedule.json --vehicle UAV3 --format wpl --out $(OUT)/UAV3.waypoints
	$(PY) -m gcs demo --report $(OUT)/demo-report
	@echo "demo: plan in $(OUT)/plan.json, plot in $(OUT)/paths.png, schedule in $(OUT)/schedule.json, speeds in $(OUT)/speeds.png"
	@echo "demo: the paper flight through the service (REST API and stream) against stub vehicles: $(OUT)/demo-report/flight.json; report: $(OUT)/demo-report/index.html"

# The coordinator service until interrupted (TCGCS_* settings; an admin token in tcgcs-data/admin.token).
serve: $(STAMP)
	$(PY) -m gcs serve

bench: $(STAMP)
	$(PY) bench/bench_planner.py
	$(PY) bench/bench_sitl_stub.py
	$(PY) bench/bench_gcs_mission.py
	$(PY) bench/bench_gcs_mission_loss.py
	$(PY) bench/bench_gcs_ingest.py
	$(PY) bench/bench_framing.py
	$(PY) bench/bench_geometry.py
	$(PY) bench/bench_swarm.py --vehicles 100 --speedup 20
	$(PY) bench/bench_jobs.py
	$(PY) bench/bench_isolation.py
	$(PY) bench/bench_failover.py

clean:
	rm -rf $(VENV) $(OUT) .mypy_cache .ruff_cache .pytest_cache .hypothesis
	find planner gcs sitl_stub tests bench -name __pycache__ -prune -exec rm -rf {} +
