"""The ``patch_cnn`` oracle architecture finds a raindrop anywhere on the lens (issue 22, item 3).

Synthetic frames: a chequerboard (random cell size, phase and colours) with or without one
raindrop of the project's ``raindrop`` phenomenon. The network is trained briefly on drops
in the left half of the frame only and must find drops in every part of the frame it has
never seen one in (the right half, the corners), and leave clean frames alone: pooling over
patches (max, attention) keeps a drop's evidence wherever it is.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

import torch

from anunnaki.enlil import ORACLE_ARCHITECTURES, EnlilError
from anunnaki.phenomena import PHENOMENA

SIZE = 64


def _board(rng: np.random.Generator) -> np.ndarray:
    cell = int(rng.integers(3, 6))
    ox, oy = (int(v) for v in rng.integers(0, cell, 2))
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    board = (((yy + oy) // cell + (xx + ox) // cell) % 2).astype(bool)
    light, dark = rng.integers(150, 256, 3), rng.integers(0, 100, 3)
    return np.where(board[..., None], light, dark).astype(np.uint8)


def _frames(centres: list[tuple[float, float] | None], seed: int) -> tuple[np.ndarray, np.ndarray]:
    rain = PHENOMENA.create("raindrop")
    rng = np.random.default_rng(seed)
    images, labels = [], []
    for i, centre in enumerate(centres):
        image = _board(rng)
        if centre is not None:
            params = {"x": centre[0], "y": centre[1], "radius": 0.1, "feather": 0.25}
            image = rain.apply(image, params, seed=i)
        images.append(image)
        labels.append(int(centre is not None))
    x = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).float() / 255.0
    return x, np.asarray(labels)


def _train(net, x, y) -> None:  # type: ignore[no-untyped-def]
    gen = torch.Generator().manual_seed(0)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    target = torch.from_numpy(y)
    net.train()
    for _ in range(8):
        for idx in torch.randperm(len(x), generator=gen).split(32):
            loss = torch.nn.functional.cross_entropy(net(x[idx])[0][:, :2], target[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
    net.eval()


def test_a_raindrop_anywhere_on_the_lens_is_found() -> None:
    torch.manual_seed(0)
    rng = np.random.default_rng(1)
    # training drops only in the left half of the frame
    train = [
        (float(rng.uniform(0.1, 0.45)), float(rng.uniform(0.1, 0.9))) if rng.random() < 0.5
        else None
        for _ in range(256)
    ]  # fmt: skip
    x, y = _frames(train, seed=2)
    net = ORACLE_ARCHITECTURES.factory("patch_cnn")(1, 2)
    _train(net, x, y)
    # held out: every cell of a 4 x 4 grid (12 of 16 in the half never trained on), clean too
    grid = [(gx, gy) for gx in (0.12, 0.38, 0.62, 0.88) for gy in (0.12, 0.38, 0.62, 0.88)]
    held: list[tuple[float, float] | None] = [*grid, *grid, *([None] * 32)]
    xt, yt = _frames(held, seed=3)
    with torch.no_grad():
        found = net(xt)[0][:, :2].argmax(dim=1).numpy()
    right = [i for i, c in enumerate(held) if c is not None and c[0] > 0.5]
    assert found[yt == 1].mean() >= 0.9, found[yt == 1]
    assert found[right].mean() >= 0.9, [held[i] for i in right if not found[i]]
    assert found[yt == 0].mean() <= 0.1


def test_patch_cnn_outputs_and_options() -> None:
    torch.manual_seed(0)
    x = torch.rand(2, 3, 128, 128)
    for pool in ("max", "attention", "max+attention"):
        net = ORACLE_ARCHITECTURES.factory("patch_cnn")(4, 3, pool=pool, drop_head=True).eval()
        cat, params, phen, drop = net(x)
        assert cat.shape == (2, 3) and params.shape == (2, 4) and phen.shape == (2, 3)
        assert drop.shape == (2,)
    with pytest.raises(EnlilError, match="pool 'mean'"):
        ORACLE_ARCHITECTURES.factory("patch_cnn")(1, 1, pool="mean")
