"""PNG plots of an archive (the ``plot`` extra): contexts by category, per-category counts."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from anunnaki.enlil._archive import Archive
from anunnaki.errors import MissingExtraError

_COLOURS = {0: "#2a9d8f", 1: "#e9c46a", 2: "#e76f51"}


def plot_archive(archive: Archive, out: Path, *, others: Sequence[Archive] = ()) -> list[Path]:
    """Write ``contexts.png`` (first two parameters, coloured by category) and ``counts.png``.

    *others* (e.g. the random and Sobol archives of the same budget) are drawn beside it,
    like the paper's Fig. 12 and 17.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("matplotlib", "plot") from exc
    out.mkdir(parents=True, exist_ok=True)
    archives = [archive, *others]
    fig, axes = plt.subplots(1, len(archives), figsize=(4.5 * len(archives), 4), squeeze=False)
    for ax, arch in zip(axes[0], archives, strict=True):
        x = arch.params[:, 0]
        y = arch.params[:, 1] if arch.params.shape[1] > 1 else np.zeros(len(arch))
        for c in (0, 2, 1):
            sel = arch.categories == c
            ax.scatter(x[sel], y[sel], s=8, c=_COLOURS[c], label=f"category {c}")
        ax.set_xlabel(arch.param_names[0])
        ax.set_ylabel(arch.param_names[1] if len(arch.param_names) > 1 else "")
        ax.set_title(f"{arch.meta.search}: {len(arch)} contexts")
        ax.legend(fontsize=7)
    contexts = out / "contexts.png"
    fig.tight_layout()
    fig.savefig(contexts, dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 3.5))
    width = 0.8 / len(archives)
    for k, arch in enumerate(archives):
        counts = [int((arch.categories == c).sum()) for c in (0, 1, 2)]
        ax.bar(np.arange(3) + k * width, counts, width, label=arch.meta.search)
    ax.set_xticks(np.arange(3) + 0.4 - width / 2, ["0", "1", "2"])
    ax.set_xlabel("category")
    ax.set_ylabel("contexts")
    ax.legend()
    counts_png = out / "counts.png"
    fig.tight_layout()
    fig.savefig(counts_png, dpi=100)
    plt.close(fig)
    return [contexts, counts_png]
