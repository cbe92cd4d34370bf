"""One pybullet client, headless, and the camera maths shared by every scene.

Why a wrapper: pybullet keeps global state per *client*, and its module-level functions fall
back to a default client when ``physicsClientId`` is omitted. Every call here passes the
client id explicitly, so several worlds live side by side in one process (and in process
pools) without sharing anything. pybullet's URDF importer prints warnings straight to the C
``stdout``; loading is done with the file descriptors briefly silenced (:func:`quiet`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from anunnaki._closing import Closing
from anunnaki.errors import MissingExtraError

__all__ = ["Camera", "World", "pybullet", "quiet"]

_QUIET_LOCK = threading.Lock()


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Silence C-level stdout/stderr (pybullet's importer warnings) inside the block."""
    with _QUIET_LOCK:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        saved: list[tuple[int, int]] = []
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
        except OSError:  # pragma: no cover - no /dev/null: just be noisy
            yield
            return
        try:
            for fd in (1, 2):
                try:
                    saved.append((fd, os.dup(fd)))
                    os.dup2(devnull, fd)
                except OSError:  # pragma: no cover - fd not open (daemonised process)
                    continue
            yield
        finally:
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            os.close(devnull)


def _import_pybullet() -> Any:
    try:
        with quiet():  # the import prints "pybullet build time: ..."
            import pybullet as pb
            import pybullet_data  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError("pybullet", "vision") from exc
    return pb


class _Lazy:
    """The pybullet module, imported on first use (``import anunnaki.sim`` stays cheap)."""

    _module: Any = None

    def __getattr__(self, name: str) -> Any:
        if _Lazy._module is None:
            _Lazy._module = _import_pybullet()
        return getattr(_Lazy._module, name)


pybullet: Any = _Lazy()


@dataclass(frozen=True)
class Camera:
    """A pinhole camera pose and lens.

    Attributes:
        eye: Camera position, world metres ``(x, y, z)``; z is up.
        target: The point it looks at (world metres).
        fov: Vertical field of view in degrees.
        near: Near clipping distance (m).
        far: Far clipping distance (m).
        up: The world direction that is "up" in the image.

    """

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fov: float = 60.0
    near: float = 0.05
    far: float = 80.0
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def matrices(self, width: int, height: int) -> tuple[list[float], list[float]]:
        """Return pybullet's (view, projection) matrices, column-major 16-lists."""
        view = pybullet.computeViewMatrix(list(self.eye), list(self.target), list(self.up))
        proj = pybullet.computeProjectionMatrixFOV(self.fov, width / height, self.near, self.far)
        return list(view), list(proj)

    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """Project world points ``[N, 3]`` to pixel coordinates ``[N, 2]`` (x right, y down).

        Points behind the camera are clamped to the near plane, so they land far outside the
        image on their side: an object straddling the camera counts as cut by the frame.
        """
        view, proj = self.matrices(width, height)
        v = np.asarray(view, dtype=np.float64).reshape(4, 4, order="F")
        pr = np.asarray(proj, dtype=np.float64).reshape(4, 4, order="F")
        homo = np.concatenate([points, np.ones((len(points), 1))], axis=1)
        cam = homo @ v.T
        cam[:, 2] = np.minimum(cam[:, 2], -self.near)  # camera looks down -z
        clip = cam @ pr.T
        ndc = clip[:, :2] / clip[:, 3:4]
        x = (ndc[:, 0] + 1.0) * 0.5 * width
        y = (1.0 - ndc[:, 1]) * 0.5 * height
        return np.stack([x, y], axis=1)


@dataclass(frozen=True)
class Light:
    """Scene lighting for pybullet's tiny renderer.

    Attributes:
        direction: Direction *towards* the light (world).
        color: Light colour RGB in [0, 1].
        ambient: Ambient coefficient.
        diffuse: Diffuse coefficient.
        specular: Specular coefficient.

    """

    direction: tuple[float, float, float] = (0.4, 0.3, 1.0)
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ambient: float = 0.6
    diffuse: float = 0.4
    specular: float = 0.05


class World(Closing):
    """A headless pybullet client (``DIRECT``) with pybullet_data on its search path.

    Close it (or use ``with``): a client holds native memory until disconnected.

    Args:
        gravity: Gravity along z (m/s²).

    """

    def __init__(self, *, gravity: float = -9.81) -> None:
        pb = pybullet
        import pybullet_data

        self.client: int = int(pb.connect(pb.DIRECT))
        if self.client < 0:  # pragma: no cover - pybullet refuses only when out of memory
            raise RuntimeError("pybullet refused a DIRECT connection")
        pb.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=self.client)
        pb.setGravity(0.0, 0.0, gravity, physicsClientId=self.client)
        self._closed = False
        self._links: dict[int, int] = {}

    def load(
        self,
        urdf: str,
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
        *,
        scale: float = 1.0,
        fixed: bool = False,
        frozen: bool = False,
    ) -> int:
        """Load a URDF (relative to pybullet_data) quietly; return its body id.

        ``frozen`` puts the body to sleep for good: its joints are not simulated (it can
        still be posed with ``resetJointState`` and still collides). A fixed humanoid's
        15 free joints otherwise cost 0.25 ms of every physics step, and sag.
        """
        pb = pybullet
        with quiet():
            body = pb.loadURDF(
                urdf,
                list(position),
                list(orientation),
                globalScaling=scale,
                useFixedBase=fixed or frozen,
                flags=pb.URDF_ENABLE_SLEEPING if frozen else 0,
                physicsClientId=self.client,
            )
        if frozen:
            for state in (pb.ACTIVATION_STATE_SLEEP, pb.ACTIVATION_STATE_DISABLE_WAKEUP):
                pb.changeDynamics(body, -1, activationState=state, physicsClientId=self.client)
        return int(body)

    def num_links(self, body: int) -> int:
        """Number of links of ``body`` (joints; the base is link -1)."""
        n = self._links.get(body)
        if n is None:
            n = self._links[body] = int(pybullet.getNumJoints(body, physicsClientId=self.client))
        return n

    def aabb(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounding box ``(low[3], high[3])`` over all links of ``body``."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for link in range(-1, self.num_links(body)):
            a, b = pybullet.getAABB(body, link, physicsClientId=self.client)
            lo = np.minimum(lo, a)
            hi = np.maximum(hi, b)
        return lo, hi

    def set_pose(
        self,
        body: int,
        position: tuple[float, float, float] | np.ndarray,
        orientation: tuple[float, float, float, float] | np.ndarray,
    ) -> None:
        """Teleport ``body``'s base."""
        pybullet.resetBasePositionAndOrientation(
            body, list(position), list(orientation), physicsClientId=self.client
        )

    def color(self, body: int, link: int, rgba: tuple[float, float, float, float]) -> None:
        """Tint one link's visual shape."""
        pybullet.changeVisualShape(body, link, rgbaColor=list(rgba), physicsClientId=self.client)

    def render(
        self, camera: Camera, width: int, height: int, light: Light | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render RGB ``[H, W, 3] uint8`` and the segmentation mask ``[H, W] int32``.

        The mask holds ``body + ((link + 1) << 24)`` per pixel, -1 for the background
        (``ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX``); tiny renderer, no shadows.
        """
        light = light or Light()
        view, proj = camera.matrices(width, height)
        _, _, rgb, _, seg = pybullet.getCameraImage(
            width,
            height,
            view,
            proj,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            lightDirection=list(light.direction),
            lightColor=list(light.color),
            lightAmbientCoeff=light.ambient,
            lightDiffuseCoeff=light.diffuse,
            lightSpecularCoeff=light.specular,
            flags=pybullet.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX,
            physicsClientId=self.client,
        )
        image = np.asarray(rgb, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]
        mask = np.asarray(seg, dtype=np.int32).reshape(height, width)
        return np.ascontiguousarray(image), mask

    def close(self) -> None:
        """Disconnect the client (idempotent)."""
        if not self._closed:
            self._closed = True
            with contextlib.suppress(Exception):
                pybullet.disconnect(physicsClientId=self.client)
