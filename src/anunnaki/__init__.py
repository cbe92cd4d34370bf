"""Anunnaki: keep learning-enabled systems trustworthy while they run.

The core (this package without extras) holds the model-driven heart of the framework:

* :mod:`anunnaki.goals` — KAOS goal models with RELAX-ed requirements, platform bindings,
  utility expressions, and their evaluation as a logic tree (incremental, three-valued);
* :mod:`anunnaki.tactics` — adaptation tactics (the paper's XML form, and YAML);
* :mod:`anunnaki.trace` — the one JSONL trace format of timestamped messages;
* :mod:`anunnaki.check` — static checks behind ``anunnaki check``.

Heavy parts (bus, vision, dashboard) live behind extras and are never imported here.
"""

from anunnaki.errors import AnunnakiError, ExpressionError, ModelFileError

__version__ = "0.1.0"

__all__ = ["AnunnakiError", "ExpressionError", "ModelFileError", "__version__"]
