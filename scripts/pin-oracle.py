"""Name a model's oracle in its registry: ``pin-oracle.py REGISTRY MODEL_ID ORACLE.safetensors``.

Writes (or replaces) the entry's ``oracle: {file, sha256}`` line in place, keeping the file's
comments and layout, then loads the registry to check the result (the oracle file must sit
in the registry's folder). Used by scripts/train-oracles.sh.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path


def pin(registry: Path, model_id: str, oracle: Path) -> str:
    """Rewrite *registry* so that *model_id* names *oracle*; returns the new line."""
    from anunnaki.lec import load_registry, sha256_file

    if oracle.resolve().parent != registry.resolve().parent:
        raise SystemExit(f"{oracle}: an oracle must sit in its registry's folder ({registry})")
    lines = registry.read_text(encoding="utf-8").splitlines()
    start = next(
        (i for i, t in enumerate(lines) if re.fullmatch(rf"\s*- id: {re.escape(model_id)}\s*", t)),
        None,
    )
    if start is None:
        raise SystemExit(f"{registry}: no entry '- id: {model_id}' (one line, block style)")
    indent = " " * (len(lines[start]) - len(lines[start].lstrip()) + 2)
    end = start + 1
    while end < len(lines) and lines[end].startswith(indent):
        end += 1
    line = f"{indent}oracle: {{file: {oracle.name}, sha256: {sha256_file(oracle)}}}"
    block = [t for t in lines[start + 1 : end] if not t.lstrip().startswith("oracle:")]
    lines[start + 1 : end] = [*block, line]
    registry.write_text("\n".join(lines) + "\n", encoding="utf-8")
    spec = load_registry(registry).get(model_id)  # the result loads, the oracle is found
    if spec.oracle is None:
        raise SystemExit(f"{registry}: {model_id} names no oracle after the edit")
    return line.strip()


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    print(pin(Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])))
