"""Which oracle network a model's oracle gets: the measured choice, written once.

The choice is measured (docs/enlil.md, "Issue 22 at the shipped scale: the network"). Per
model first: a model whose own oracle was measured with both networks (three seeds each) is
named in :data:`MODEL_ARCHITECTURES` with the network its figures chose. Then per
phenomenon: an architecture is named in :data:`PHENOMENON_ARCHITECTURES` when every one of
its seeds is above every seed of the other on a figure that decides (balanced macro-F1,
random-context accuracy, false alarms per 1,000 clean frames) and not below that way on
another; a phenomenon with no measured preference (a tie, or not measured) names none. One
oracle covers all of its model's phenomena, so the phenomena that name an architecture
decide it (they must agree) and the others follow them; a model whose phenomena name none
gets the cheaper :data:`DEFAULT_ORACLE_ARCHITECTURE`. ``scripts/train-oracles.sh`` (through
``anunnaki oracle architecture``) and ``anunnaki robustify``'s oracle step both ask
:func:`oracle_architecture`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from itertools import pairwise
from types import MappingProxyType

from anunnaki.enlil._context import EnlilError

__all__ = [
    "DEFAULT_ORACLE_ARCHITECTURE",
    "MODEL_ARCHITECTURES",
    "PHENOMENON_ARCHITECTURES",
    "oracle_architecture",
]

#: The network of an oracle whose phenomena name none (the cheaper one).
DEFAULT_ORACLE_ARCHITECTURE = "small_cnn"

#: The measured choice per phenomenon (docs/enlil.md, "Issue 22"); a phenomenon not named
#: here has no preference. Empty: at the shipped scale hsl, raindrop and fog tie on the
#: held-out figures (the reduced-scale measurement's hsl -> patch_cnn did not hold there).
PHENOMENON_ARCHITECTURES: Mapping[str, str] = MappingProxyType({})

#: The measured choice per model, before the phenomena's (docs/enlil.md, "Issue 22 at the
#: shipped scale: the network"): every one of rover-default's patch_cnn seeds raises fewer
#: false alarms on close pedestrians than every small_cnn seed (0-31.6 against 50.6-64.6 per
#: 1,000 clean frames; the held-out figures tie). rover-low_light: its shipped patch_cnn
#: oracle, kept until it is measured the same way.
MODEL_ARCHITECTURES: Mapping[str, str] = MappingProxyType(
    {"rover-default": "patch_cnn", "rover-low_light": "patch_cnn"}
)


def _parts(phenomena: Iterable[str]) -> list[str]:
    """The phenomena, compositions (``rain+brightness``) split into their parts, in order."""
    out: list[str] = []
    for name in phenomena:
        for raw in name.split("+"):
            part = raw.strip()
            if part and part not in out:
                out.append(part)
    return out


def _agree(named: list[tuple[str, str]]) -> str | None:
    """The one architecture the (phenomenon, architecture) pairs name, or ``None``."""
    for (p1, a1), (p2, a2) in pairwise(named):
        if a1 != a2:
            raise EnlilError(
                f"oracle architecture: phenomenon {p1} names {a1} and {p2} names {a2}, but "
                "one oracle covers both; name the network yourself (oracle train "
                "--architecture, robustify --oracle-architecture, or ARCH_<model> in "
                "scripts/train-oracles.sh)"
            )
    return named[0][1] if named else None


def oracle_architecture(
    phenomena: Iterable[str],
    *,
    model_id: str | None = None,
    choices: Mapping[str, str | None] | None = None,
    default: str = DEFAULT_ORACLE_ARCHITECTURE,
) -> str:
    """The network of one oracle covering *phenomena* (of model *model_id*).

    In this order: the *choices* given for the phenomena, the model's measured choice
    (:data:`MODEL_ARCHITECTURES`), the phenomena's (:data:`PHENOMENON_ARCHITECTURES`),
    *default*.

    Args:
        phenomena: The phenomena the oracle covers; a composition (``raindrop+raindrop``,
            ``rain+brightness``) counts each of its parts.
        model_id: The oracle's model, for :data:`MODEL_ARCHITECTURES`.
        choices: Networks named per phenomenon, before the measured tables (a composition's
            name names each of its parts); an empty name (or ``None``) drops that
            phenomenon's entry of :data:`PHENOMENON_ARCHITECTURES`.
        default: The network when nothing names one.

    Returns:
        The architecture's name (an :data:`anunnaki.enlil.ORACLE_ARCHITECTURES` name).

    Raises:
        EnlilError: Two phenomena name different architectures (one oracle covers both),
            naming them and the fix.

    """
    parts = _parts(phenomena)
    # a choice named for a composition (``rain+brightness``) is a choice for each of its parts
    named = [(part, arch) for name, arch in (choices or {}).items() for part in _parts([name])]
    given = {part: arch for part, arch in named if arch}
    chosen = _agree([(p, given[p]) for p in parts if p in given])
    if chosen is not None:
        return chosen
    if model_id is not None and model_id in MODEL_ARCHITECTURES:
        return MODEL_ARCHITECTURES[model_id]
    dropped = {part for part, arch in named if not arch}
    table = {k: v for k, v in PHENOMENON_ARCHITECTURES.items() if k not in dropped}
    return _agree([(p, table[p]) for p in parts if p in table]) or default
