"""Enki: a robustified model per domain, from the contexts where the model fails (paper §3.3).

``anunnaki robustify MODEL --data DATA --phenomenon P --domain NAME`` runs the chain
(:func:`robustify`, docs/robustify.md): Enlil's search of P's parameter space against MODEL
(or a given archive) → a diverse training set of its contexts, weighted toward categories 1
and 2 while covering the whole space (:func:`select_contexts`, :class:`SelectionRule`) → a
fine-tuned copy of MODEL on train frames perturbed by them, mixed with clean frames
(:func:`finetune`; MODEL's file is only read) → the new model measured, assessed by Enlil and
given its behavior oracle → optionally registered (:func:`anunnaki.lec.register_model`).
Every stage is recorded in a work folder; a rerun continues after Ctrl-C or ``kill -9``.

The fine-tune takes its training contexts from a :class:`ContextSource`, so that a
comparison runs every arm with the same images, epochs, optimiser steps and seed
(:class:`Budget`)::

    from anunnaki.enki import ArchiveContexts, Budget, UniformContexts, finetune

    enki = finetune("rover-default.safetensors", train, val,
                    ArchiveContexts("hsl", selection.params), budget=Budget(epochs=8), seed=1)
    rand = finetune("rover-default.safetensors", train, val,
                    UniformContexts("hsl"), budget=Budget(epochs=8), seed=1)

:class:`CorruptionMix` is the third source: each frame a random phenomenon of the library at
a random strength. :class:`MixedContexts` draws each frame's source from several (one model
for several domains: benchmarks/switching.py). The recipe's parts (docs/robustify.md#recipe):
:class:`ArchiveMix` (the archive as a distribution: jittered elites mixed with uniform
contexts), :class:`WorstOfK` (the candidate with the highest loss under the network being
trained), ``finetune(..., consistency=λ)`` and ``Budget(ema=DECAY)``; by name through
:data:`CONTEXT_SOURCES` and :func:`make_source` (``robustify --source``). Needs the
``vision`` and ``enlil`` extras.
"""

from anunnaki.enki._chain import RobustifyConfig, archive_sha256, new_model_id, robustify
from anunnaki.enki._errors import EnkiError
from anunnaki.enki._finetune import Budget, finetune
from anunnaki.enki._select import (
    LEARNABLE_F1,
    Selection,
    SelectionRule,
    select_contexts,
    unlearnable_rows,
)
from anunnaki.enki._sources import (
    CONTEXT_SOURCES,
    ArchiveContexts,
    ArchiveMix,
    ContextSource,
    CorruptionMix,
    MixedContexts,
    SourceSpec,
    UniformContexts,
    WorstOfK,
    make_source,
)

__all__ = [
    "CONTEXT_SOURCES",
    "LEARNABLE_F1",
    "ArchiveContexts",
    "ArchiveMix",
    "Budget",
    "ContextSource",
    "CorruptionMix",
    "EnkiError",
    "MixedContexts",
    "RobustifyConfig",
    "Selection",
    "SelectionRule",
    "SourceSpec",
    "UniformContexts",
    "WorstOfK",
    "archive_sha256",
    "finetune",
    "make_source",
    "new_model_id",
    "robustify",
    "select_contexts",
    "unlearnable_rows",
]
