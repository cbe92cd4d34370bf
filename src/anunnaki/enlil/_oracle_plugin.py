"""The ``enlil`` oracle plugin: learned behavior oracles at run time, one per model.

Registered in the oracle slot (``anunnaki.oracles``) as ``enlil``; an
:class:`~anunnaki.oracles.OracleNode` runs it as agent A4. Oracles are per model: the node
hands ``assess`` the active model id (the LEC node announces it on ``/lm_manager/active``),
and the plugin uses that model's oracle, named in the model registry::

    models:
      - id: rover-default
        file: rover-default.safetensors
        sha256: 5b47…
        oracle: {file: rover-default.oracle.safetensors, sha256: 0c1d…}

After a swap the new model's oracle is used (all are loaded when the plugin is built, each
sha256 checked); for a model no oracle covers nothing is invented: ``assess`` returns
``None`` (nothing is published) and the plugin logs it once per model.

A frame's context lookup is a few small BLAS calls (one query against the stored
contexts). OpenBLAS's idle workers spin for a while after each threaded call, so at a camera
rate they kept a core busy between frames: measured in the whole loop, the UAV's oracle
process took 23–34 ms of CPU per frame with numpy's and SciPy's default two BLAS threads
and 8–9 with one (docs/whole-loop.md). ``assess`` therefore runs on one BLAS thread
(``blas_threads``), through threadpoolctl, and restores the process's setting after. So does
loading an oracle, whose context lookup factors a kernel matrix of at most a few hundred
contexts per phenomenon: with two BLAS threads and the other core busy the rover's nine fits
took 5.8 s in all, on one thread 0.5 s (``anunnaki run examples/rover/demo.yaml``, load 2).
"""

from __future__ import annotations

import contextlib
import logging
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from anunnaki._blas import blas_limit
from anunnaki.enlil._oracle_net import CLEAR, OracleModel, load_oracle
from anunnaki.lec import ModelRegistry
from anunnaki.messages import Assessment
from anunnaki.oracles import Frame, OracleError

__all__ = ["EnlilOracle"]

log = logging.getLogger("anunnaki.enlil")


class EnlilOracle:
    """Assess each camera frame with the active model's learned oracle.

    Args:
        models: A model registry (a file, ``anunnaki: models/1``, or a loaded
            :class:`~anunnaki.lec.ModelRegistry`) whose entries name their oracle
            (``oracle: {file, sha256}``).
        oracles: Oracle files by model id, instead of (or on top of) the registry's; or
            loaded :class:`~anunnaki.enlil.OracleModel` objects.
        window: Average the calibrated probabilities over the last *window* frames of the
            same model (1: every frame on its own).
        preload: Load every named oracle now (a bad file is reported when the node is
            built, and no frame waits for a file to be read and prepared); ``False``: each
            on the first frame of its model.
        blas_threads: The BLAS threads (numpy's and SciPy's) ``assess`` runs on; ``None``
            leaves them as the process has them. The figures are the same (to rounding).

    Raises:
        OracleError: Neither *models* nor *oracles* given, or *window* < 1.

    """

    name = "enlil"

    def __init__(
        self,
        models: str | Path | ModelRegistry | None = None,
        *,
        oracles: Mapping[str, str | Path | OracleModel] | None = None,
        window: int = 1,
        preload: bool = True,
        blas_threads: int | None = 1,
    ) -> None:
        if models is None and not oracles:
            raise OracleError(
                "the enlil oracle needs models=REGISTRY.yaml (entries with 'oracle:') or "
                "oracles={model_id: FILE}"
            )
        if not isinstance(window, int) or window < 1:
            raise OracleError(f"enlil: window must be a whole number >= 1, got {window!r}")
        if blas_threads is not None and (not isinstance(blas_threads, int) or blas_threads < 1):
            raise OracleError(f"enlil: blas_threads must be >= 1 or None, got {blas_threads!r}")
        self.window = window
        self.blas_threads = blas_threads
        self._sources: dict[str, tuple[Path, str | None] | OracleModel] = {}
        if models is not None:
            from anunnaki.lec import load_registry

            registry = models if isinstance(models, ModelRegistry) else load_registry(models)
            for spec in registry:
                if spec.oracle is not None:
                    self._sources[spec.id] = (spec.oracle.file, spec.oracle.sha256)
        for model_id, item in (oracles or {}).items():
            self._sources[model_id] = item if isinstance(item, OracleModel) else (Path(item), None)
        self._loaded: dict[str, OracleModel | None] = {}
        self._history: deque[np.ndarray] = deque(maxlen=window)
        self._last_model: str | None = None
        if preload:
            for model_id in self.covered:
                self.oracle_for(model_id)

    @classmethod
    def options_from_models(cls, models: ModelRegistry) -> dict[str, Any]:
        """Use the assessed detector's registry, whose entries name their oracles (hook)."""
        return {"models": models}

    def __repr__(self) -> str:
        return f"EnlilOracle(models={sorted(self._sources)}, window={self.window})"

    @property
    def covered(self) -> list[str]:
        """The model ids an oracle is known for."""
        return sorted(self._sources)

    def oracle_for(self, model_id: str) -> OracleModel | None:
        """The oracle of *model_id* (loaded on first use), or ``None`` (logged once)."""
        if model_id in self._loaded:
            return self._loaded[model_id]
        source = self._sources.get(model_id)
        oracle: OracleModel | None = None
        if source is None:
            log.warning(
                "enlil: no behavior oracle covers model %r (covered: %s); nothing is published "
                "for it",
                model_id,
                ", ".join(self.covered) or "none",
            )
        elif isinstance(source, OracleModel):
            oracle = source
        else:
            with self._blas_limit():  # its context lookup's fit: small matrices, one thread
                oracle = load_oracle(source[0], sha256=source[1])
            log.info("enlil: loaded the oracle of model %r from %s", model_id, source[0])
        if oracle is not None and oracle.model_id != model_id:
            log.warning(
                "enlil: the oracle named for model %r was trained for %r; using it anyway",
                model_id,
                oracle.model_id,
            )
        self._loaded[model_id] = oracle
        return oracle

    def assess(self, frame: Frame, *, seq: int, model_id: str) -> Assessment | None:
        """The active model's category, confidence and perceived context for *frame*."""
        oracle = self.oracle_for(model_id)
        if oracle is None:
            return None
        if model_id != self._last_model:
            self._history.clear()
            self._last_model = model_id
        with self._blas_limit():
            return self._assess(oracle, frame, seq=seq, model_id=model_id)

    def _blas_limit(self) -> contextlib.AbstractContextManager[Any]:
        """At most ``blas_threads`` BLAS threads in the block (a no-op with ``None``)."""
        return blas_limit(self.blas_threads, extra="oracle", with_scipy=True)

    def _assess(self, oracle: OracleModel, frame: Frame, *, seq: int, model_id: str) -> Assessment:
        out = oracle.outputs([frame])
        cat, params, phen = out.category, out.params, out.phenomenon
        drop = oracle.predicted_drop(out.drop)
        row = oracle.category_probabilities(cat, params, phen)[0]
        # the predicted drop rides along as a fourth column (nan without a drop head)
        self._history.append(np.append(row, np.nan if drop is None else drop[0]))
        mean = np.mean(np.stack(self._history), axis=0)
        probs = mean[:3]
        category = int(np.argmax(probs))
        context = _context(oracle, params[0], phen[0], category)
        context["probs"] = [round(float(p), 4) for p in probs]
        return Assessment(
            category=category,
            confidence=float(np.clip(probs[category], 0.0, 1.0)),
            context=context,
            model_id=model_id,
            assessor=self.name,
            frame_seq=seq,
            drop=round(float(mean[3]), 4) if np.isfinite(mean[3]) else None,
        )


def _context(oracle: OracleModel, params: np.ndarray, phen: np.ndarray, category: int) -> Any:
    if oracle.card.phenomenon_head:
        which = int(np.argmax(phen))
    else:
        which = 1 if category > 0 or float(np.max(params)) > 0.15 else 0
    if which == 0:
        return {"phenomenon": CLEAR, "params": {}}
    spec = oracle.card.phenomena[which - 1]
    values = {n: round(float(params[j]), 4) for j, n in enumerate(spec.param_names)}
    return {"phenomenon": spec.name, "params": values, "normalised": True}
