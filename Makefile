# The two commands of the README:
#   make demo   set up a fresh machine and run the main job
#   make test   set up and run the tests (what CI runs)
.PHONY: demo test lint setup bench

PY := .venv/bin/python
ROVER := examples/rover

setup:
	@scripts/setup.sh

demo: setup
	$(PY) -m anunnaki.cli.main check $(ROVER)/goals.yaml $(ROVER)/binding.yaml $(ROVER)/tactics.xml
	$(PY) -m anunnaki.cli.main run $(ROVER)/utu.yaml --speed 5

test: setup
	$(PY) -m ruff check src tests benchmarks examples
	$(PY) -m ruff format --check src tests benchmarks examples
	$(PY) -m mypy
	$(PY) -m pytest -q

bench: setup
	$(PY) benchmarks/goals.py
	$(PY) benchmarks/reaction.py
