"""Enlil: search a phenomenon's parameter space for where a model degrades (paper §3.2, §4.1.2).

One evaluation (:func:`evaluate_context`) measures the model's F1 on a fixed batch
(:func:`fixed_batch`) under one context, a point of the phenomenon's parameter space
normalised to ``[0, 1]^d`` (:func:`to_phenomenon_vector`, :func:`normalise`), and maps the
relative drop to a behavior category (:func:`anunnaki.oracles.category_for_drop`).
Searches store every evaluation in a Parquet archive (:class:`ArchiveWriter`,
:func:`read_archive`). pyarrow, pyribs, scipy and Dask are the ``enlil`` extra and are
imported only when used. See docs/enlil.md.
"""

from anunnaki.enlil._archive import Archive, ArchiveMeta, ArchiveWriter, read_archive
from anunnaki.enlil._context import (
    ContextResult,
    EnlilError,
    evaluate_context,
    fixed_batch,
    normalise,
    relative_drop,
    resolve_phenomenon,
    to_phenomenon_vector,
)
from anunnaki.enlil._oracle_choice import (
    DEFAULT_ORACLE_ARCHITECTURE,
    MODEL_ARCHITECTURES,
    PHENOMENON_ARCHITECTURES,
    oracle_architecture,
)
from anunnaki.enlil._oracle_eval import (
    BASELINES,
    BaselineFit,
    HeldOut,
    Predictions,
    Retest,
    baseline_predictions,
    box_stability,
    evaluate_oracles,
    fit_baseline,
    fit_baselines,
    held_out_frames,
    interior_mask,
    label_ceiling,
    of_ceiling,
    oracle_predictions,
    retest_contexts,
    score_predictions,
)

# The behavior oracle (issue 13, items 3 to 6): network, training, evaluation, run time.
from anunnaki.enlil._oracle_lookup import ContextLookup, LookupSpec
from anunnaki.enlil._oracle_metrics import cohen_kappa, spearman
from anunnaki.enlil._oracle_net import (
    ORACLE_ARCHITECTURES,
    DropSpec,
    OracleCard,
    OracleModel,
    OraclePrediction,
    load_oracle,
)
from anunnaki.enlil._oracle_plugin import EnlilOracle
from anunnaki.enlil._oracle_train import (
    ContextSet,
    OracleTrainConfig,
    contexts_from_archive,
    merge_context_sets,
    random_contexts,
    seed_spread,
    train_oracle,
    train_oracle_seeds,
)
from anunnaki.enlil._plot import plot_archive
from anunnaki.enlil._run import (
    Job,
    SearchOutcome,
    executor_map,
    occupied_cells,
    run_search,
    summarise,
)
from anunnaki.enlil._search import SEARCHES, EnlilSearch, RandomSearch, Search, SobolSearch
from anunnaki.enlil._sweep import ContextDraw, ContextSpec, draw_contexts, parse_contexts

__all__ = [
    "BASELINES",
    "DEFAULT_ORACLE_ARCHITECTURE",
    "MODEL_ARCHITECTURES",
    "ORACLE_ARCHITECTURES",
    "PHENOMENON_ARCHITECTURES",
    "SEARCHES",
    "Archive",
    "ArchiveMeta",
    "ArchiveWriter",
    "BaselineFit",
    "ContextDraw",
    "ContextLookup",
    "ContextResult",
    "ContextSet",
    "ContextSpec",
    "DropSpec",
    "EnlilError",
    "EnlilOracle",
    "EnlilSearch",
    "HeldOut",
    "Job",
    "LookupSpec",
    "OracleCard",
    "OracleModel",
    "OraclePrediction",
    "OracleTrainConfig",
    "Predictions",
    "RandomSearch",
    "Retest",
    "Search",
    "SearchOutcome",
    "SobolSearch",
    "baseline_predictions",
    "box_stability",
    "cohen_kappa",
    "contexts_from_archive",
    "draw_contexts",
    "evaluate_context",
    "evaluate_oracles",
    "executor_map",
    "fit_baseline",
    "fit_baselines",
    "fixed_batch",
    "held_out_frames",
    "interior_mask",
    "label_ceiling",
    "load_oracle",
    "merge_context_sets",
    "normalise",
    "occupied_cells",
    "of_ceiling",
    "oracle_architecture",
    "oracle_predictions",
    "parse_contexts",
    "plot_archive",
    "random_contexts",
    "read_archive",
    "relative_drop",
    "resolve_phenomenon",
    "retest_contexts",
    "run_search",
    "score_predictions",
    "seed_spread",
    "spearman",
    "summarise",
    "to_phenomenon_vector",
    "train_oracle",
    "train_oracle_seeds",
]
