"""How scene objects look in pybullet: model files, quick-loading URDF copies, textures.

The pybullet_data models a scene uses (humanoid, quadruped, vehicles, distractors), their
scale per metre of a placement's size, the lite copies of heavy URDFs (see
:func:`_lite_urdf`), the humanoid's clothing links and the ground texture. Kept apart from
:class:`~anunnaki.sim.Scene` because it is about assets on disk, not about a world.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from anunnaki.sim._layout import Platform

# Model files (pybullet_data), their scale per metre of "size", and the z-rotation that
# stands them up / faces them along +x.
_HUMANOID = "humanoid/humanoid.urdf"  # DeepMimic humanoid: y-up, 1.58 m tall at scale 0.25
_HUMANOID_SCALE_PER_M = 0.25 / 1.58
_DEER = "laikago/laikago_toes_zup_lores.urdf"  # low-poly quadruped, 0.71 m long at scale 1
_DEER_SCALE_PER_M = 1.0 / 0.71
# Model scale per metre of size, from each model's bounding box at scale 1.
_VEHICLES = (("racecar/racecar.urdf", 1.0 / 0.458), ("husky/husky.urdf", 1.0 / 1.009))
# One model per kind of anunnaki.sim._layout.DISTRACTOR_KINDS (a Scene refuses a kind without).
_DISTRACTORS = {
    "cube": ("cube.urdf", 1.0),
    "sphere": ("sphere2.urdf", 1.0),
    "duck": ("duck_vhacd.urdf", 1.0 / 0.091),
    "ball": ("soccerball.urdf", 1.0),
    "mug": ("objects/mug.urdf", 1.0 / 0.128),
    "teddy": ("teddy_vhacd.urdf", 1.0 / 0.101),
}


def _strip_material(src: Path, directory: Path) -> str:
    """Copy an OBJ file without its material (and texture) lines; return the copy's path."""
    target = directory / f"{src.parent.name}_{src.name}"
    if not target.exists():
        lines = src.read_text().splitlines(keepends=True)
        target.write_text("".join(ln for ln in lines if not ln.startswith(("mtllib", "usemtl"))))
    return str(target)


_PRIMITIVE = re.compile(r"<(box|cylinder|sphere)\b[^>]*/>")
# Meshes of thousands of triangles that the lite copies replace (wheels) or drop (hinges).
_HEAVY_MESHES = frozenset(
    {
        "wheel.stl",
        "left_front_wheel.obj",
        "right_front_wheel.obj",
        "left_rear_wheel.obj",
        "right_rear_wheel.obj",
        "left_steering_hinge.STL",
        "right_steering_hinge.STL",
        "user_rail.stl",
    }
)
# Heavy meshes without a primitive collision shape, shown as a primitive: (origin, geometry).
_STAND_INS = {
    "top_plate.stl": ('<origin rpy="0 0 0" xyz="0 0 0.21"/>', '<box size="0.812 0.414 0.03"/>'),
}


def _lite_urdf(model: str, directory: Path) -> str:
    """Write a quick-loading, quick-rendering copy of a pybullet_data URDF; return its path.

    pybullet's tiny renderer pays for every triangle of every body in view or not (the
    husky's four 7,000-triangle wheels cost 20 ms a frame even behind the camera), and the
    loader decodes a texture once per link (0.2 s for the laikago). The copy

    * shows a heavy mesh's primitive collision shape instead (wheels become the cylinders
      they already collide as) and drops it when there is none (steering hinges);
    * loads OBJ meshes without their material and texture (objects are tinted anyway);
    * for the quadruped, collides with the low-poly meshes it shows instead of STL hulls.

    Measured here: husky 6x faster to render, laikago 10x faster to load, same silhouettes.
    """
    import pybullet_data

    src = Path(pybullet_data.getDataPath()) / model
    out = directory / (model.replace("/", "_"))
    if out.exists():
        return str(out)

    def link(match: re.Match[str]) -> str:
        block = match.group(0)
        visual = re.search(r"<visual>.*?</visual>", block, re.S)
        collision = re.search(r"<collision>.*?</collision>", block, re.S)
        if visual is None:
            return block
        mesh = re.search(r'<mesh filename="([^"]*)"([^>]*)/>', visual.group(0))
        if mesh is None:
            return block
        path = src.parent / mesh.group(1)
        vis = visual.group(0)
        if path.name in _STAND_INS:
            origin_xml, geometry_xml = _STAND_INS[path.name]
            new_vis = re.sub(r"<origin[^>]*/>", origin_xml, vis, count=1)
            return block.replace(vis, re.sub(r"<mesh[^>]*/>", geometry_xml, new_vis))
        if path.name in _HEAVY_MESHES:
            prim = _PRIMITIVE.search(collision.group(0)) if collision else None
            if prim is None or collision is None:
                return block.replace(vis, "")
            origin = re.search(r"<origin[^>]*/>", collision.group(0))
            new_vis = re.sub(r"<origin[^>]*/>", origin.group(0) if origin else "", vis, count=1)
            new_vis = re.sub(r"<mesh[^>]*/>", prim.group(0), new_vis)
            return block.replace(vis, new_vis)
        shown = _strip_material(path, directory) if path.suffix == ".obj" else str(path)
        block = block.replace(
            vis, vis.replace(f'filename="{mesh.group(1)}"', f'filename="{shown}"')
        )
        if collision is not None and model.startswith("laikago/"):
            coll = collision.group(0)
            block = block.replace(coll, re.sub(r'filename="[^"]*"', f'filename="{shown}"', coll))
        return block

    text = re.sub(r"<link .*?</link>", link, src.read_text(), flags=re.S)

    def absolute(match: re.Match[str]) -> str:
        name = match.group(1)
        return match.group(0) if name.startswith("/") else f'filename="{src.parent / name}"'

    out.write_text(re.sub(r'filename="([^"]*)"', absolute, text))
    return str(out)


_HUMANOID_LINKS = {
    "trousers": (0, 9, 10, 12, 13),
    "shirt": (1, 3, 6),
    "skin": (2, 4, 5, 7, 8),
    "shoes": (11, 14),
}


def _ground_texture(rng: np.random.Generator, platform: Platform, size: int = 128) -> np.ndarray:
    """A tileable grass/soil texture ``[size, size, 3] uint8`` (periodic Fourier noise)."""
    out = np.empty((size, size, 3), dtype=np.float64)
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.fftfreq(size)[None, :]
    radius = np.sqrt(fx**2 + fy**2)
    radius[0, 0] = 1.0
    spectrum = 1.0 / radius**1.4
    spectrum[0, 0] = 0.0
    noise = np.real(np.fft.ifft2(spectrum * np.exp(2j * np.pi * rng.random((size, size)))))
    noise = (noise - noise.mean()) / (noise.std() + 1e-9)
    fine = rng.normal(0.0, 1.0, (size, size))
    if platform == "rover":
        base = np.array([0.36, 0.45, 0.22]) * rng.uniform(0.85, 1.15)
        soil = np.array([0.45, 0.38, 0.28])
    else:
        base = np.array([0.33, 0.44, 0.24]) * rng.uniform(0.85, 1.15)
        soil = np.array([0.5, 0.46, 0.38])
    mix = 1.0 / (1.0 + np.exp(-1.5 * (noise - 0.6)))  # patches of soil
    for c in range(3):
        out[:, :, c] = base[c] * (1 - mix) + soil[c] * mix + 0.035 * fine + 0.03 * noise
    return (np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
