"""Which oracle network a model's oracle gets: the per-phenomenon choice, written once.

The choice was measured (docs/enlil.md, "Issue 22"): per phenomenon, the architecture whose
figures are above the other's beyond the spread of three seeds; a phenomenon with no
measured preference (a tie, or not measured) names none. One oracle covers all of its
model's phenomena, so the phenomena that name an architecture decide it (they must agree)
and the others follow them; a model whose phenomena name none gets the cheaper
:data:`DEFAULT_ORACLE_ARCHITECTURE`. ``scripts/train-oracles.sh`` (through ``anunnaki oracle
architecture``) and ``anunnaki robustify``'s oracle step both ask :func:`oracle_architecture`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from types import MappingProxyType

from anunnaki.enlil._context import EnlilError

__all__ = ["DEFAULT_ORACLE_ARCHITECTURE", "PHENOMENON_ARCHITECTURES", "oracle_architecture"]

#: The network of an oracle whose phenomena name none (the cheaper one).
DEFAULT_ORACLE_ARCHITECTURE = "small_cnn"

#: The measured choice per phenomenon (docs/enlil.md, "Issue 22"); a phenomenon not named
#: here has no preference.
PHENOMENON_ARCHITECTURES: Mapping[str, str] = MappingProxyType({"hsl": "patch_cnn"})


def _parts(phenomena: Iterable[str]) -> list[str]:
    """The phenomena, compositions (``rain+brightness``) split into their parts, in order."""
    out: list[str] = []
    for name in phenomena:
        for raw in name.split("+"):
            part = raw.strip()
            if part and part not in out:
                out.append(part)
    return out


def oracle_architecture(
    phenomena: Iterable[str],
    *,
    choices: Mapping[str, str | None] | None = None,
    default: str = DEFAULT_ORACLE_ARCHITECTURE,
) -> str:
    """The network of one oracle covering *phenomena*.

    Args:
        phenomena: The phenomena the oracle covers; a composition (``raindrop+raindrop``,
            ``rain+brightness``) counts each of its parts.
        choices: Overrides of :data:`PHENOMENON_ARCHITECTURES` per phenomenon; an empty
            name (or ``None``) drops that phenomenon's choice.
        default: The network when no phenomenon names one.

    Returns:
        The architecture's name (an :data:`anunnaki.enlil.ORACLE_ARCHITECTURES` name).

    Raises:
        EnlilError: Two phenomena name different architectures (one oracle covers both),
            naming them and the fix.

    """
    table = dict(PHENOMENON_ARCHITECTURES)
    for name, arch in (choices or {}).items():
        if arch:
            table[name] = arch
        else:
            table.pop(name, None)
    chosen: tuple[str, str] | None = None
    for part in _parts(phenomena):
        arch = table.get(part)
        if arch is None:
            continue
        if chosen is not None and chosen[1] != arch:
            raise EnlilError(
                f"oracle architecture: phenomenon {chosen[0]} names {chosen[1]} and {part} "
                f"names {arch}, but one oracle covers both; name the network yourself "
                "(oracle train --architecture, robustify --oracle-architecture, or "
                "ARCH_<model> in scripts/train-oracles.sh)"
            )
        chosen = (part, arch)
    return chosen[1] if chosen is not None else default
