"""The cyclic garbage collector around a command's bring-up (issue #30 item 4).

A command's bring-up (the sub-commands' modules, torch, the models, the parsed files) makes
objects that live as long as the process. Collected while they are made, they are traversed
again and again: importing torch alone triggers dozens of full collections. And once the
run is going, every full collection traverses them all once more, as does the last one when
the interpreter exits.

So :func:`main` pauses the collector while the command line is parsed; a command that brings
more up (``anunnaki run``: the nodes, the managed system and its networks) keeps it paused
until it is up, then calls :func:`settle`: what exists is frozen (``gc.freeze``: the
collector leaves it alone from then on) and collection resumes for what the run makes.
Nothing a program computes depends on when the collector runs; only the time it costs.

:func:`end` undoes it: collection on, and, when ``main`` was called as a function (tests,
an embedding program), the frozen objects handed back to the collector. The process's own
command line keeps them frozen: it exits next, and its last collection would only traverse
what the exit frees anyway.
"""

from __future__ import annotations

import gc

__all__ = ["end", "pause", "settle"]

_state = {"paused": False, "frozen": False}


def pause() -> None:
    """Stop collecting (bring-up); a no-op when the collector is already off."""
    if gc.isenabled():
        gc.disable()
        _state["paused"] = True


def settle() -> None:
    """Bring-up done: freeze what exists and collect again (a no-op without a pause)."""
    if _state["paused"]:
        gc.freeze()
        _state["frozen"] = True
        _state["paused"] = False
        gc.enable()


def end(*, unfreeze: bool) -> None:
    """Collect again, as before :func:`pause`; ``unfreeze``: hand back what was frozen."""
    if _state["paused"]:
        _state["paused"] = False
        gc.enable()
    if unfreeze and _state["frozen"]:
        _state["frozen"] = False
        gc.unfreeze()
