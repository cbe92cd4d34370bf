"""Write an Enki model's measured figures into its registry entry's description line.

    python scripts/describe-domain.py examples/models/rover.yaml rover-hsl

`anunnaki robustify --register` adds the entry with the clean F1 only; this replaces that
entry's `description:` line (and nothing else in the file) with the figures of the model's
sidecar (`metrics.enki`: clean F1 of both models on the test split, mean F1 of both on the
archive contexts not used in training) and of its oracle's sidecar (val accuracy, macro-F1).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

from anunnaki.lec import load_registry


def describe(model: dict[str, Any], oracle: dict[str, Any]) -> str:
    """One line of the sidecars' figures."""
    enki = model["training"]["enki"]
    metrics = model["metrics"]["enki"]
    clean, contexts = metrics["clean"], metrics["archive_contexts"]
    base = enki["from"]["model_id"]
    val = oracle["metrics"]["val"]
    unused = contexts["contexts"] - contexts["used_in_training"]
    return (
        f"Enki ({enki['phenomenon']}, seed {enki['seeds']['finetune']}): test F1 "
        f"{clean['new']:.3f} clean ({base} {clean['input']:.3f}); {contexts['new']['f1']:.3f} "
        f"on {contexts['contexts']} contexts of {base}'s search, {unused} not used in training "
        f"({base} {contexts['input']['f1']:.3f}); oracle val accuracy {val['accuracy']:.3f}, "
        f"macro-F1 {val['macro_f1']:.3f}."
    )


def main(registry_file: str, model_id: str) -> None:
    """Replace the description line of *model_id*'s entry in *registry_file*."""
    path = Path(registry_file)
    spec = load_registry(path).get(model_id)
    if spec.oracle is None:
        sys.exit(f"{path}: {model_id} has no oracle; robustify --register adds one")
    model = json.loads(spec.file.with_suffix(".json").read_text(encoding="utf-8"))
    oracle = json.loads(spec.oracle.file.with_suffix(".json").read_text(encoding="utf-8"))
    before = path.read_text(encoding="utf-8")
    lines = before.splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if line.rstrip() == f"  - id: {model_id}")
    for i in range(start + 1, len(lines)):
        if re.match(r"  - |\S", lines[i]):
            break
        if lines[i].startswith("    description:"):
            lines[i] = f"    description: {json.dumps(describe(model, oracle))}\n"
            path.write_text("".join(lines), encoding="utf-8")
            try:
                load_registry(path).verify(model_id)  # still valid, hashes checked
            except Exception:
                path.write_text(before, encoding="utf-8")
                raise
            return
    sys.exit(f"{path}: the entry of {model_id} has no description line")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
