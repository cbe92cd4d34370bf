"""Enki's selection rule: a diverse training set of contexts from an Enlil archive.

The archive holds every context the search evaluated, with its behavior category. A
training set made of the compromised contexts alone would teach the model one corner of the
parameter space and cost it elsewhere; the contexts where nothing happens (category 0) are
cheap to learn but teach little. The rule (docs/robustify.md):

1. **Quotas.** Each category ``c`` gets ``n × w_c × N_c / Σ_k w_k × N_k`` of the *n* places
   (largest remainders), ``N_c`` its contexts in the archive and ``w_c`` its weight
   (default ``1, 3, 3``: a degraded or compromised context is three times as likely to be
   chosen as an unaffected one). A category with fewer contexts than its quota gives the
   rest to the others in the same proportions; an archive with at most *n* contexts is
   taken whole.
2. **Diversity and coverage.** Categories are filled 2, 1, then 0, each by farthest-point
   sampling in the normalised space ``[0, 1]^d``: the next context is the one farthest from
   every context chosen so far (of any category). The first is the archive's largest drop.
   So the hard contexts spread over the whole region where the model fails, and the
   category-0 places go to the parts of the space the hard ones leave empty.

0. **The learnability cap**, before the quotas. A context where *every* model measured on it
   scores an F1 below ``learnable`` (0.05: a black frame, a drop over the whole view) teaches
   nothing but to fire on noise, so it is left out. One model at zero is a hard context, not
   an unlearnable one (the dark hsl context where the default model scores 0 and a model
   trained on random contexts 0.78, docs/enki.md), so the cap needs a second opinion: the F1
   of at least one other model at the same rows (``others``, e.g. the registry's models, or
   the arms of a comparison), besides the archive's own. Without one the cap leaves the
   archive whole, and the selection says so (``cap``).

Deterministic: no random draw (ties go to the lower evaluation index).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from anunnaki.enki._errors import EnkiError
from anunnaki.enlil import Archive

__all__ = ["LEARNABLE_F1", "Selection", "SelectionRule", "select_contexts", "unlearnable_rows"]

#: The learnability floor: a context where every model measured scores an F1 below this is
#: unlearnable (a black frame), and left out of the training contexts.
LEARNABLE_F1 = 0.05


@dataclass(frozen=True)
class SelectionRule:
    """The selection's parameters (``anunnaki robustify --contexts N --weights W0 W1 W2``).

    Attributes:
        contexts: Contexts in the training set (at most the archive's size).
        weights: Weights of categories 0, 1 and 2 (relative; non-negative, one positive).
        learnable: The learnability cap: a context where every model measured on it has an
            F1 below this is left out (module docstring, step 0). 0 turns the cap off.

    """

    contexts: int = 64
    weights: tuple[float, float, float] = (1.0, 3.0, 3.0)
    learnable: float = LEARNABLE_F1

    def __post_init__(self) -> None:
        if self.contexts < 1:
            raise EnkiError(f"--contexts must be at least 1, got {self.contexts}")
        if len(self.weights) != 3 or min(self.weights) < 0 or max(self.weights) <= 0:
            raise EnkiError(
                f"--weights {list(self.weights)}: give three non-negative weights, for "
                "categories 0, 1 and 2, at least one of them positive (e.g. 1 3 3)"
            )
        if not 0.0 <= self.learnable < 1.0:
            raise EnkiError(
                f"the learnability floor must be an F1 in [0, 1), got {self.learnable} "
                f"(default {LEARNABLE_F1}; 0 turns the cap off)"
            )


@dataclass(frozen=True)
class Selection:
    """The chosen contexts.

    Attributes:
        phenomenon: The archive's phenomenon.
        param_names: Parameter names (column order of :attr:`params`).
        rows: ``[n]`` the chosen rows of the archive, in the order chosen.
        params: ``[n, d]`` their normalised contexts.
        categories: ``[n]`` their categories.
        drops: ``[n]`` their measured relative F1 drops.
        unlearnable: Archive rows left out by the learnability cap.
        cap: How the cap was applied: ``"applied"`` (with *models* opinions), ``"off"``
            (floor 0) or ``"one model"`` (no second opinion: nothing left out).
        models: Models whose F1 the cap read (the archive's and the others).

    """

    phenomenon: str
    param_names: tuple[str, ...]
    rows: npt.NDArray[np.int64]
    params: npt.NDArray[np.float64]
    categories: npt.NDArray[np.int64]
    drops: npt.NDArray[np.float64]
    unlearnable: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    cap: str = "one model"
    models: int = 1

    def counts(self) -> list[int]:
        """Chosen contexts per category 0, 1, 2."""
        return [int((self.categories == c).sum()) for c in range(3)]

    def as_dict(self) -> dict[str, Any]:
        """JSON-safe form (the work folder's ``selection.json``)."""
        return {
            "phenomenon": self.phenomenon,
            "param_names": list(self.param_names),
            "rows": self.rows.tolist(),
            "params": self.params.tolist(),
            "categories": self.categories.tolist(),
            "drops": self.drops.tolist(),
            "unlearnable": self.unlearnable.tolist(),
            "cap": self.cap,
            "models": self.models,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Selection:
        """Inverse of :meth:`as_dict`."""
        return cls(
            str(data["phenomenon"]),
            tuple(str(n) for n in data["param_names"]),
            np.asarray(data["rows"], np.int64),
            np.asarray(data["params"], np.float64).reshape(-1, len(data["param_names"])),
            np.asarray(data["categories"], np.int64),
            np.asarray(data["drops"], np.float64),
            np.asarray(data.get("unlearnable", []), np.int64),
            str(data.get("cap", "one model")),
            int(data.get("models", 1)),
        )


def _quotas(counts: list[int], weights: tuple[float, float, float], n: int) -> list[int]:
    """Places per category: proportional to weight × count, capped by count (see module)."""
    quota = [0, 0, 0]
    left = n
    open_ = [c for c in range(3) if counts[c] > 0 and weights[c] > 0]
    while left > 0 and open_:
        mass = [weights[c] * (counts[c] - quota[c]) for c in open_]
        total = sum(mass)
        share = [left * m / total for m in mass]
        give = [min(int(s), counts[c] - quota[c]) for s, c in zip(share, open_, strict=True)]
        rest = left - sum(give)
        order = sorted(range(len(open_)), key=lambda i: (-(share[i] - int(share[i])), open_[i]))
        for i in order:
            if rest == 0:
                break
            if give[i] < counts[open_[i]] - quota[open_[i]]:
                give[i] += 1
                rest -= 1
        for i, c in enumerate(open_):
            quota[c] += give[i]
        left = n - sum(quota)
        open_ = [c for c in open_ if quota[c] < counts[c]]
    return quota


def unlearnable_rows(
    archive: Archive, others: Sequence[npt.ArrayLike] = (), *, floor: float = LEARNABLE_F1
) -> npt.NDArray[np.int64]:
    """Rows of *archive* where its model and every one of *others* score an F1 below *floor*.

    Args:
        archive: The archive (its ``f1`` is its model's).
        others: Other models' F1 at the archive's rows, one ``[N]`` array each; ``nan``
            where a model was not measured (a row is then judged by the models that were).
        floor: The learnability floor.

    Raises:
        EnkiError: An array of *others* does not have one F1 per archive row.

    """
    n = len(archive)
    stack = [np.asarray(archive.f1, np.float64)]
    for k, other in enumerate(others):
        f1 = np.asarray(other, np.float64).reshape(-1)
        if f1.shape != (n,):
            raise EnkiError(
                f"the F1 of other model {k} has {f1.size} values for an archive of {n} "
                "contexts; give one per archive row (nan where it was not measured)"
            )
        stack.append(f1)
    below = np.where(np.isnan(stack), True, np.asarray(stack) < floor)
    return np.flatnonzero(below.all(axis=0)).astype(np.int64)


def select_contexts(
    archive: Archive,
    rule: SelectionRule | None = None,
    *,
    others: Sequence[npt.ArrayLike] = (),
) -> Selection:
    """Choose the training contexts from *archive* by the module's rule.

    Args:
        archive: Enlil's archive of the model to robustify.
        rule: Number of contexts, category weights and the learnability floor.
        others: Other models' F1 at the archive's rows (``[N]`` each, ``nan`` where not
            measured): the second opinion the learnability cap needs.

    Raises:
        EnkiError: The archive is empty, every context it holds has weight 0, or the cap
            leaves nothing.

    """
    rule = rule or SelectionRule()
    n_rows = len(archive)
    if n_rows == 0:
        raise EnkiError(
            f"the archive about {archive.phenomenon} holds no contexts; run the search "
            "with a budget (anunnaki assess --budget N) or let robustify run it"
        )
    cats = np.asarray(archive.categories, np.int64)
    unlearnable = np.zeros(0, np.int64)
    cap = "off" if rule.learnable == 0.0 else "one model" if not others else "applied"
    if cap == "applied":
        unlearnable = unlearnable_rows(archive, others, floor=rule.learnable)
        if len(unlearnable) == n_rows:
            raise EnkiError(
                f"every context of the archive about {archive.phenomenon} scores F1 below "
                f"{rule.learnable} for all {1 + len(others)} models: nothing is learnable; "
                "lower the floor (SelectionRule.learnable) or search a milder range"
            )
        cats = cats.copy()
        cats[unlearnable] = -1  # in no category: never picked
    counts = [int((cats == c).sum()) for c in range(3)]
    quota = _quotas(counts, rule.weights, min(rule.contexts, n_rows))
    if sum(quota) == 0:
        raise EnkiError(
            f"--weights {list(rule.weights)} give every context of the archive (categories "
            f"0/1/2: {'/'.join(map(str, counts))}) weight 0; raise a weight"
        )
    points = np.asarray(archive.params, np.float64)
    chosen: list[int] = []
    nearest = np.full(n_rows, np.inf)
    for c in (2, 1, 0):
        pool = np.flatnonzero(cats == c)
        for _ in range(quota[c]):
            if not chosen:
                pick = int(pool[np.argmax(archive.drop[pool])])
            else:
                free = pool[~np.isin(pool, chosen)]
                pick = int(free[np.argmax(nearest[free])])
            chosen.append(pick)
            dist = np.sqrt(((points - points[pick]) ** 2).sum(axis=1))
            nearest = np.minimum(nearest, dist)
    rows = np.asarray(chosen, np.int64)
    return Selection(
        archive.phenomenon,
        tuple(archive.param_names),
        rows,
        points[rows],
        cats[rows],
        np.asarray(archive.drop, np.float64)[rows],
        unlearnable,
        cap,
        1 + len(others),
    )
