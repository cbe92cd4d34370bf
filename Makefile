# The two commands of the README:
#   make demo   set up what the demo needs (no root) and run the main job
#   make test   set up everything the tests need (as root: Chromium, ROS 1; ROS 2 in .venv-ros2)
#               and run them (CI)
.PHONY: demo test lint setup setup-demo setup-test bench

PY := .venv/bin/python
ROVER := examples/rover

# scripts/setup.sh's profiles: demo = the extras the demos import (vision, dashboard, plot,
# mail, oracle); test = every extra (dev, bus, vision, dashboard, plot, enlil, ros, mail) and,
# as root, Debian's Chromium and ROS 1, and ROS 2 Jazzy in its own .venv-ros2 (no root,
# scripts/setup-ros2.sh). `setup` is the test profile (benchmarks, results).
setup-demo:
	@scripts/setup.sh demo

setup-test:
	@scripts/setup.sh test

setup: setup-test

# The simulated rover with its detector, the learned (enlil) oracles and Utu, through an HSL
# shift, a raindrop on the lens, fog, and fog with poor light (about 65 s): Utu swaps in the
# Enki models by domain and, when no model is trusted, hands the rover to a human and e-mails
# the operator (a local SMTP sink on port 8025, started and stopped by the run, prints the
# mail). The live dashboard (URL printed; it stays up 30 s after the run, saying so every
# 10 s; Ctrl-C leaves at once); a per-phase table at the end, the run as data and drawn in
# runs/demo.json and runs/demo.png.
demo: setup-demo
	$(PY) -m anunnaki.cli.main check $(ROVER)/goals-lm.yaml $(ROVER)/binding-enlil.yaml $(ROVER)/tactics-lm.yaml
	$(PY) -m anunnaki.cli.main run $(ROVER)/demo.yaml --mail-sink 8025 --dashboard --dashboard-linger 30 \
		--report runs/demo.json --plot runs/demo.png

test: setup-test
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
# measurements cached in runs/paper/, so a rerun measures only what changed); then the
# rover's and the UAV's assurance cases from the results as they now stand, into
# docs/assurance/rover and docs/assurance/uav (a second, reproducible: same inputs, same bytes).
.PHONY: results
results: setup
	nice -n 10 $(PY) benchmarks/paper.py
	$(PY) benchmarks/assurance.py --ship docs/assurance

# The simulated UAV's delivery mission (paper Fig. 18) with its detector, the learned enlil
# oracle as A4 and Utu (about 75 s): take-off, waypoints, fog near the target (swap to
# uav-fog), link and GPS faults, the battery draining (O2: return home); the live dashboard
# (URL printed; it stays up 30 s after the run, saying so every 10 s) and a per-phase table
# at the end, the run as data and drawn in runs/demo-uav.json and runs/demo-uav.png.
# docs/uav.md says what happens.
UAV := examples/uav
.PHONY: demo-uav
demo-uav: setup-demo
	$(PY) -m anunnaki.cli.main check $(UAV)/sim.yaml
	$(PY) -m anunnaki.cli.main run $(UAV)/sim.yaml --dashboard --dashboard-linger 30 \
		--report runs/demo-uav.json --plot runs/demo-uav.png

# Every picture README.md and docs/ show, remade from the current demos (the dashboards of
# make demo / make demo-uav stopped at a chosen simulated instant, in headless Chromium; the
# runs' plots) and from the committed measurements (4 CPU-minutes): docs/images/pictures.yaml
# says what makes each. results-paper-*.png are made by make results only.
.PHONY: pictures
pictures: setup
	@scripts/setup-browser.sh
	$(PY) scripts/pictures.py
