"""The work folder of ``anunnaki robustify --out DIR``: options, stage markers, resume.

``DIR/robustify.json`` holds the options that decide the results (model hash, data,
phenomenon, domain, budgets, selection rule, seeds). A run into a folder made with other
options stops and names the first that differs: old and new work are never mixed. Each
stage that completes writes ``DIR/stages/NAME.json`` (what it produced) atomically; a rerun
skips the stages that have one. The stages themselves resume inside: the searches from their
archive parts, the fine-tune from its per-epoch checkpoint.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from anunnaki.enki._errors import EnkiError

__all__ = ["WorkFolder"]

FORMAT = "anunnaki-robustify/1"


def write_json(path: Path, data: Any) -> None:
    """Write *data* as JSON to *path* atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".tmp-{path.name}")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)


class WorkFolder:
    """A robustify work folder (see the module docstring).

    Args:
        path: The folder (created when missing).
        options: The options that decide the results (JSON-safe).
        scoped: Options that belong to one stage and are checked there (see
            :meth:`stage`): an older folder whose ``robustify.json`` holds them is not
            refused for them; :attr:`recorded` keeps what it held.

    Raises:
        EnkiError: The folder holds work made with other options, or is a file.

    """

    def __init__(
        self, path: str | Path, options: dict[str, Any], *, scoped: tuple[str, ...] = ()
    ) -> None:
        self.path = Path(path)
        self.recorded: dict[str, Any] = {}
        if self.path.exists() and not self.path.is_dir():
            raise EnkiError(f"--out {self.path}: is a file; give a folder for the work")
        self.path.mkdir(parents=True, exist_ok=True)
        marker = self.path / "robustify.json"
        options = json.loads(json.dumps(options))  # tuples as lists, as read back
        if marker.is_file():
            old = json.loads(marker.read_text(encoding="utf-8"))
            if old.get("format") != FORMAT:
                raise EnkiError(f"{marker}: not a robustify work folder ({FORMAT})")
            self.recorded = old.get("options", {})
            self._check({k: v for k, v in self.recorded.items() if k not in scoped}, options)
        else:
            write_json(marker, {"format": FORMAT, "options": options})
        self.options = options

    def _check(self, old: dict[str, Any], new: dict[str, Any]) -> None:
        for key in sorted(set(old) | set(new)):
            if old.get(key) != new.get(key):
                raise EnkiError(
                    f"--out {self.path}: this work was made with {key} = {old.get(key)!r}, "
                    f"this run has {key} = {new.get(key)!r}; rerun with the same options to "
                    "continue it, or give another --out folder to start afresh"
                )

    def stage(self, name: str) -> dict[str, Any] | None:
        """What stage *name* produced, or ``None`` when it has not completed."""
        file = self.path / "stages" / f"{name}.json"
        if not file.is_file():
            return None
        data: dict[str, Any] = json.loads(file.read_text(encoding="utf-8"))
        return data

    def forget(self, prefix: str) -> list[str]:
        """Drop the records of the stages whose names start with *prefix* (to run them again)."""
        gone = []
        for file in sorted((self.path / "stages").glob(f"{prefix}*.json")):
            file.unlink()
            gone.append(file.stem)
        return gone

    def done(self, name: str, result: dict[str, Any]) -> dict[str, Any]:
        """Mark stage *name* complete with *result*; returns *result*."""
        write_json(self.path / "stages" / f"{name}.json", result)
        return result
