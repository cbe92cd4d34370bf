r"""Names that become parts of paths: one rule, checked in one place.

A model id, a domain, the name of a search or a run ends up as a file or folder name:
``anunnaki robustify`` writes ``OUT/ID.safetensors``, ``anunnaki assess`` writes
``assess/ID-P-SEARCH-sSEED/``. A name holding ``/``, ``\``, ``..``, a NUL or an absolute
path would put a file outside the folder it was meant for (``--domain 'fog/../x y'`` once
wrote ``OUT/rover-fog/../x y.safetensors``), so every such name is checked against
:data:`NAME_RULE` where it enters — a command-line option, a field of a YAML file, an argument
of a library function — and every file written under a name is checked to land inside its
folder (:func:`inside`). The rule is pathlib's and Django's ``get_valid_filename``'s habit,
stated once (docs/model-manager.md, "Names").

A domain is a name with one more constraint (:data:`DOMAIN_RULE`): goal models compare it
with a phenomenon's name (``rain+brightness`` ↔ ``rain_brightness``), so it is an identifier.
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path

from anunnaki.errors import AnunnakiError

__all__ = [
    "DOMAIN_RULE",
    "NAME_RULE",
    "NameRuleError",
    "check_domain",
    "check_name",
    "close_file",
    "inside",
]

#: The rule every name that becomes part of a path follows (as error messages state it).
NAME_RULE = (
    "a name is 1 to 128 characters: letters, digits, '_', '-' and '.', the first a letter, a "
    "digit or '_' (so no '/', '\\', spaces, NUL, leading '.' or '..', and no absolute path)"
)
#: A domain: a name that is also an identifier (goal models compare it with phenomena).
DOMAIN_RULE = (
    "a domain must be an identifier: 1 to 64 letters, digits and '_', the first not a digit "
    "(e.g. fog, low_light)"
)

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,127}")
_DOMAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")


class NameRuleError(AnunnakiError, ValueError):
    """A name breaks the rule, or a file would be written outside its folder.

    The rule is :data:`NAME_RULE` (a domain's :data:`DOMAIN_RULE`). A ``ValueError`` too, so
    a pydantic validator reports it on its field.
    """


def _suggest(value: str, allowed: str, limit: int) -> str:
    """*value* with every run of characters outside *allowed* turned into one ``_``."""
    text = re.sub(f"[^{allowed}]+", "_", value).strip("_.-")[:limit]
    return text


def _fail(value: object, what: str, rule: str, example: str, fix: str | None) -> NameRuleError:
    shown = repr(value) if isinstance(value, str) else f"{type(value).__name__} {value!r}"
    if fix is None:
        fix = f"e.g. {example!r}" if example else "e.g. 'rover-fog'"
        fix = f"give a name that follows it, {fix}"
    return NameRuleError(f"{what} {shown} is not allowed: {rule}; {fix}")


def check_name(value: object, *, what: str, fix: str | None = None) -> str:
    """Return *value* if it follows :data:`NAME_RULE`, else raise :class:`NameRuleError`.

    Args:
        value: The name (a model id, a run's, a search's …).
        what: What it is, as the user gave it: ``--id``, ``model id``, ``registry entry
            models[2].id``; the message starts with it.
        fix: What to do instead (default: a name that follows the rule, derived from
            *value*).

    """
    if isinstance(value, str) and _NAME.fullmatch(value):
        return value
    example = _suggest(value, "A-Za-z0-9_.-", 128) if isinstance(value, str) else ""
    raise _fail(value, what, NAME_RULE, example, fix)


def check_domain(value: object, *, what: str = "domain", fix: str | None = None) -> str:
    """Return *value* if it is a domain (:data:`DOMAIN_RULE`), else raise :class:`NameRuleError`.

    Every domain is also a name (:func:`check_name`).
    """
    if isinstance(value, str) and _DOMAIN.fullmatch(value):
        return value
    example = _suggest(value, "A-Za-z0-9_", 64) if isinstance(value, str) else ""
    if example[:1].isdigit():
        example = "_" + example[:63]
    raise _fail(value, what, DOMAIN_RULE, example, fix)


def inside(folder: str | Path, path: str | Path, *, what: str) -> Path:
    """*path* if, symlinks resolved, it lies inside *folder*; else raise :class:`NameRuleError`.

    Call it before writing a file whose name was built from a name: the last line of
    defence behind :func:`check_name`.

    Args:
        folder: The folder every write of the command belongs in (its ``--out``).
        path: The file about to be written (relative paths are taken from the current
            folder, as ``open`` takes them).
        what: What the file is, for the message.

    """
    root = Path(os.path.realpath(folder))
    real = Path(os.path.realpath(path))
    if real != root and not real.is_relative_to(root):
        raise NameRuleError(
            f"{what} {str(path)!r} would be written outside its folder {str(root)!r} (it "
            f"resolves to {str(real)!r}); names follow this rule: {NAME_RULE}"
        )
    return Path(path)


def close_file(path: str | Path) -> Path | None:
    """The file next to *path* whose name is closest to its name (a misspelt file), or ``None``.

    Only files with *path*'s suffix count (``rover-defualt.safetensors`` →
    ``rover-default.safetensors``, not its ``.json``).
    """
    p = Path(path)
    try:
        names = sorted(f.name for f in p.parent.iterdir() if f.suffix == p.suffix and f.is_file())
    except OSError:
        return None
    close = difflib.get_close_matches(p.name, names, n=1, cutoff=0.75)
    return p.parent / close[0] if close else None
