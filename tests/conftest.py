"""Shared test configuration.

Hypothesis runs without its per-example deadline: a deadline is a timed assertion, and on
this project's shared 2-core machines a loaded moment made property tests fail that had
nothing wrong (measurements live in benchmarks/, not in tests).
"""

from hypothesis import settings

settings.register_profile("anunnaki", deadline=None)
settings.load_profile("anunnaki")
