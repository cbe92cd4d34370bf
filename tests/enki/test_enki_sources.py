"""The mixed context source: one model's training frames from several domains' sources."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from anunnaki.enki import ArchiveContexts, ContextSource, EnkiError, MixedContexts


class Tag(ContextSource):
    """Fills the image with one value, so a test sees which source perturbed a frame."""

    kind = "tag"

    def __init__(self, value: int) -> None:
        super().__init__(clean=0.9)  # never used: a mixed source calls perturb directly
        self.value = value

    def perturb(self, image: Any, rng: np.random.Generator) -> Any:
        return np.full_like(image, self.value)


def _image() -> Any:
    return np.full((8, 8, 3), 128, np.uint8)


def test_each_perturbed_frame_comes_from_one_source_by_weight() -> None:
    mixed = MixedContexts([Tag(1), Tag(2), Tag(3)], weights=[1, 1, 2], clean=0.25)
    rng = np.random.default_rng(0)
    seen = [int(mixed(_image(), rng)[0, 0, 0]) for _ in range(4000)]
    share = {v: seen.count(v) / len(seen) for v in (128, 1, 2, 3)}
    assert share[128] == pytest.approx(0.25, abs=0.03)  # the mixed source's own clean share
    assert share[1] == pytest.approx(0.75 / 4, abs=0.03)
    assert share[3] == pytest.approx(0.75 / 2, abs=0.03)  # weight 2: twice as often


def test_the_same_stream_gives_the_same_frames() -> None:
    sources = [ArchiveContexts("fog", [[0.9, 0.9]]), ArchiveContexts("hsl", [[0.5, 0.5, 0.05]])]
    a = MixedContexts(sources, clean=0.0)
    out1 = [a(_image(), np.random.default_rng(7)) for _ in range(3)]
    out2 = [a(_image(), np.random.default_rng(7)) for _ in range(3)]
    assert all(np.array_equal(x, y) for x, y in zip(out1, out2, strict=True))
    assert not np.array_equal(out1[0], _image())


def test_describe_lists_the_inner_sources() -> None:
    mixed = MixedContexts([ArchiveContexts("fog", [[0.2, 0.3], [0.4, 0.5]]), Tag(1)])
    d = mixed.describe()
    assert d["kind"] == "mixed" and d["clean"] == 0.3
    assert d["sources"][0] == {"kind": "archive", "clean": 0.3, "phenomenon": "fog",
                               "contexts": 2}  # fmt: skip
    assert d["weights"] == [0.5, 0.5]


@pytest.mark.parametrize(
    ("sources", "weights", "match"),
    [
        ([], None, "at least one source"),
        ([Tag(1)], [1, 2], "one non-negative weight per source"),
        ([Tag(1), Tag(2)], [0, 0], "at least one positive"),
        ([Tag(1), Tag(2)], [1, -1], "non-negative"),
    ],
)
def test_bad_mixes_are_refused(sources: Any, weights: Any, match: str) -> None:
    with pytest.raises(EnkiError, match=match):
        MixedContexts(sources, weights=weights)
