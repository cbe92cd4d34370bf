"""Render the synthetic scene under every phenomenon at a few strengths (docs figure).

    .venv/bin/python docs/make_phenomena_figure.py     # writes docs/images/phenomena.png

One row per phenomenon (built-ins and a composition), one column per strength
(``strength_params(s)``, seed 0). Tiled with numpy and written by OpenCV, which the
``vision`` extra already brings, so the figure needs no plotting library.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from anunnaki.phenomena import PHENOMENA, synthetic_scene

STRENGTHS = (0.0, 0.25, 0.5, 0.75, 1.0)
EXTRA = ("fog+raindrop",)
DEFAULT_OUTPUT = Path(__file__).parent / "images" / "phenomena.png"
TILE_H, TILE_W = 120, 160
LABEL_W, HEADER_H, GAP = 120, 24, 4
BACKGROUND = 255


def render(names: list[str], strengths: tuple[float, ...] = STRENGTHS) -> np.ndarray:
    """Return the figure as an RGB ``uint8`` array."""
    import cv2

    scene = synthetic_scene(TILE_H, TILE_W)
    height = HEADER_H + len(names) * (TILE_H + GAP)
    width = LABEL_W + len(strengths) * (TILE_W + GAP)
    figure = np.full((height, width, 3), BACKGROUND, np.uint8)
    font, black = cv2.FONT_HERSHEY_SIMPLEX, (0, 0, 0)
    for column, strength in enumerate(strengths):
        x = LABEL_W + column * (TILE_W + GAP)
        cv2.putText(figure, f"s = {strength:g}", (x + 50, 16), font, 0.45, black, 1, cv2.LINE_AA)
    for row, name in enumerate(names):
        phenomenon = PHENOMENA.create(name)
        y = HEADER_H + row * (TILE_H + GAP)
        cv2.putText(figure, name, (4, y + TILE_H // 2), font, 0.45, black, 1, cv2.LINE_AA)
        for column, strength in enumerate(strengths):
            x = LABEL_W + column * (TILE_W + GAP)
            tile = phenomenon.apply(scene, phenomenon.strength_params(strength), seed=0)
            figure[y : y + TILE_H, x : x + TILE_W] = tile
    return figure


def main(argv: list[str] | None = None) -> Path:
    """Render the figure and write it as PNG; return the path written."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    import cv2

    figure = render([*PHENOMENA.names(), *EXTRA])
    args.output.parent.mkdir(parents=True, exist_ok=True)
    bgr = cv2.cvtColor(figure, cv2.COLOR_RGB2BGR)
    if not cv2.imwrite(str(args.output), bgr, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise SystemExit(f"could not write {args.output}")
    print(f"wrote {args.output} ({figure.shape[1]}x{figure.shape[0]})")
    return args.output


if __name__ == "__main__":
    main()
