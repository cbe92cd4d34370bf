# The two commands of the README:
#   make demo   set up a fresh machine and run the main job
#   make test   set up and run the tests (what CI runs)
.PHONY: demo test lint setup bench

PY := .venv/bin/python
ROVER := examples/rover

setup:
	@scripts/setup.sh

# The simulated rover with its detector, the learned (enlil) oracles and Utu, through an HSL
# shift, a raindrop on the lens, fog, and fog with poor light (about 65 s): Utu swaps in the
# Enki models by domain and, when no model is trusted, hands the rover to a human and e-mails
# the operator (a local SMTP sink on port 8025, started and stopped by the run, prints the
# mail). The live dashboard (URL printed; it stays up 60 s after the run); a per-phase table
# at the end, the run as data and drawn in runs/demo.json and runs/demo.png.
demo: setup
	$(PY) -m anunnaki.cli.main check $(ROVER)/goals-lm.yaml $(ROVER)/binding-enlil.yaml $(ROVER)/tactics-lm.yaml
	$(PY) -m anunnaki.cli.main run $(ROVER)/demo.yaml --mail-sink 8025 --dashboard --dashboard-linger 60 \
		--report runs/demo.json --plot runs/demo.png

test: setup
	$(PY) -m ruff check src tests benchmarks examples
	$(PY) -m ruff format --check src tests benchmarks examples
	$(PY) -m mypy
	.venv/bin/lint-imports
	$(PY) -m pytest -q -n 2 --dist loadfile --durations=30

bench: setup
	$(PY) benchmarks/goals.py
	$(PY) benchmarks/reaction.py
	$(PY) benchmarks/phenomena.py
	$(PY) benchmarks/sim.py
	$(PY) benchmarks/lec.py
	$(PY) benchmarks/swap.py
	$(PY) benchmarks/loop.py
	$(PY) benchmarks/dashboard.py

# The paper's §4 figures beside ours (the shipped models and oracles on our rendered data,
# rendered into data/ if absent) and the managers' table of benchmarks/case_studies.py:
# regenerates docs/results-paper.md and docs/images/results-paper-*.png (18 min at load 22;
# measurements cached in runs/paper/, so a rerun measures only what changed).
.PHONY: results
results: setup
	nice -n 10 $(PY) benchmarks/paper.py

# The simulated UAV's delivery mission (paper Fig. 18) with its detector, the learned enlil
# oracle as A4 and Utu (about 75 s): take-off, waypoints, fog near the target (swap to
# uav-fog), link and GPS faults, the battery draining (O2: return home); the live dashboard
# (URL printed; it stays up 60 s after the run) and a per-phase table at the end, the run as
# data and drawn in runs/demo-uav.json and runs/demo-uav.png. docs/uav.md says what happens.
UAV := examples/uav
.PHONY: demo-uav
demo-uav: setup
	$(PY) -m anunnaki.cli.main check $(UAV)/sim.yaml
	$(PY) -m anunnaki.cli.main run $(UAV)/sim.yaml --dashboard --dashboard-linger 60 \
		--report runs/demo-uav.json --plot runs/demo-uav.png

# Every picture README.md and docs/ show, remade from the current demos (the dashboards of
# make demo / make demo-uav stopped at a chosen simulated instant, in headless Chromium; the
# runs' plots) and from the committed measurements (4 CPU-minutes): docs/images/pictures.yaml
# says what makes each. results-paper-*.png are made by make results only.
.PHONY: pictures
pictures: setup
	@scripts/setup-browser.sh
	$(PY) scripts/pictures.py
