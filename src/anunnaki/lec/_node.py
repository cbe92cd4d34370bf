"""The LEC node: runs the active model on every camera frame and hot-swaps it (``/lm_manager``).

One node serves one learning-enabled component (the paper's object detector, lec name
``detector``). It is the paper's learning model manager (§3.3, §4.1.4) and the LEC itself in
one process, because a swap must be atomic with respect to the frames the model sees::

    /rover/camera/image ──Image──▶ LecNode ──Detections──▶ /lec/detector/detections
                                      │  ▲
           /lm_manager/active ◀──{lec, model, domain}   /lm_manager/swap {lec, model | domain}

Why the swap works the way it does
    * **Preloaded off the frame path.** A swap request is served on the service's own thread:
      the registry resolves the model, checks the file's sha256 and loads it there, while the
      frame thread keeps running the old model. A slow load never stalls or drops frames.
    * **Switched atomically between two frames.** The frame thread reads the active model
      once per frame, just before inference; the swap replaces it under the same lock. A
      frame is therefore entirely old-model or entirely new-model, frames are processed in
      arrival order by one thread, and once the first new-model detection is out no
      old-model one follows (the switch is monotone). A slow frame never blocks a swap.
    * **Refused swaps change nothing.** An unknown model or domain, a missing file, a sha256
      that differs from the registry's, or a file the loader refuses is answered with
      ``ServiceReply(ok=False, error)`` and the old model keeps running.
    * **Reply when switched.** ``ServiceReply(ok=True, body={model, domain, load_ms, …})``
      is sent once the new model is the active one (the next frame uses it), so Utu's
      ``swap_model`` action succeeds only for a swap that happened.

Models registered while it runs
    ``/lm_manager/reload`` (an operator service: the request carries the operator token, as
    Utu's do) re-reads the registry file, checks every model's and oracle's sha256 and loads
    every new model once, then swaps pick from the new registry; a bad registry is refused
    with the error and the old one kept. The model in use must stay listed, unchanged: a
    reload never drops it (:meth:`LecNode.reload`, docs/model-manager.md).

The active model is announced on ``/lm_manager/active`` on every change and once a
``active_period`` (1 s) otherwise, so Utu's agent for the model manager (A6 in the UAV model)
never goes stale: on a thread of its own, or, on a bus delivered by a deterministic executor
(a simulated run), at each ``active_period`` of the simulation's ``/clock``. Inactive models
that were loaded stay in a small cache (``cache``), so swapping back to the default model is
instant.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import numpy.typing as npt

from anunnaki import topics
from anunnaki.bus import Bus, Node, Publisher, Sample
from anunnaki.errors import AnunnakiError, MissingExtraError, ModelFileError
from anunnaki.lec._detector import Detector
from anunnaki.lec._registry import ModelRegistry, ModelRegistryError, ModelSpec
from anunnaki.lec._registry_reload import replace, reread
from anunnaki.messages import Detections, Image, ServiceReply, body_of
from anunnaki.tokens import (
    OPERATOR_TOKEN_ENV,
    default_token_file,
    service_operator_token,
    token_matches,
)

__all__ = [
    "LecNode",
    "LecNodeStats",
    "ReloadResult",
    "SwapResult",
    "decode_image",
    "detections_topic",
]

log = logging.getLogger("anunnaki.lec")


def detections_topic(lec: str) -> str:
    """The topic an LEC's detections are published on: ``/lec/<lec>/detections``."""
    return f"/lec/{lec}/detections"


def decode_image(message: Image) -> npt.NDArray[np.uint8]:
    """Decode an :class:`~anunnaki.messages.Image` into ``(H, W, 3)`` RGB uint8 (``to_array``).

    Raises:
        ValueError: The bytes do not decode.
        MissingExtraError: OpenCV is not installed.

    """
    return cast("npt.NDArray[np.uint8]", message.to_array())


@dataclass(frozen=True)
class SwapResult:
    """The outcome of a swap.

    Attributes:
        ok: Whether the requested model is now the active one.
        lec: The LEC's name.
        model: The active model's id after the request (the old one if refused).
        domain: The active model's domain after the request.
        previous: The model that was active before.
        load_ms: Time to resolve, verify and load the new model (0 when it was cached or
            already active).
        changed: Whether the active model changed.
        error: Why the swap was refused.

    """

    ok: bool
    lec: str
    model: str
    domain: str
    previous: str
    load_ms: float = 0.0
    changed: bool = False
    error: str | None = None

    def reply(self) -> ServiceReply:
        """The service reply.

        ``ServiceReply(ok=True, body={lec, model, domain, previous, load_ms, changed})`` when
        switched (or already active); ``ServiceReply(ok=False, error, body={lec, active})``
        when refused, which a requester receives as a
        :class:`~anunnaki.bus.ServiceError` and Utu's executor as a failed action.
        """
        if not self.ok:
            return ServiceReply(
                ok=False,
                error=self.error or "refused",
                body={"lec": self.lec, "active": self.model},
            )
        return ServiceReply(
            ok=True,
            body={
                "lec": self.lec,
                "model": self.model,
                "domain": self.domain,
                "previous": self.previous,
                "load_ms": round(self.load_ms, 3),
                "changed": self.changed,
            },
        )


@dataclass(frozen=True)
class LecNodeStats:
    """Counters of a running :class:`LecNode`.

    Attributes:
        frames: Frames received.
        detections: Detection messages published (one per frame that decoded and ran).
        failed: Frames that did not decode or whose inference raised (logged, skipped).
        swaps: Swaps that changed the active model.
        refused: Swap requests refused.
        reloads: Registry reloads applied.
        reloads_refused: Registry reloads refused (unauthorised ones included).

    """

    frames: int
    detections: int
    failed: int
    swaps: int
    refused: int
    reloads: int = 0
    reloads_refused: int = 0


@dataclass(frozen=True)
class ReloadResult:
    """The outcome of a registry reload (:meth:`LecNode.reload`).

    Attributes:
        ok: Whether the new registry is now the one swaps pick from.
        lec: The LEC's name.
        registry: The registry file in force after the request (the old one if refused).
        active: The model in use (a reload never changes it).
        models: The ids the registry in force lists.
        added: Ids the reload added.
        changed: Ids whose entry changed.
        removed: Ids it no longer lists.
        caller: Who asked.
        status: ``reloaded``, ``refused`` or ``unauthorised``.
        error: Why it was refused.

    """

    ok: bool
    lec: str
    registry: str | None
    active: str
    models: tuple[str, ...] = ()
    added: tuple[str, ...] = ()
    changed: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    caller: str = "api"
    status: str = "reloaded"
    error: str | None = None

    def reply(self) -> ServiceReply:
        """The service reply.

        ``ServiceReply(ok=True, body={lec, registry, active, models, added, changed,
        removed, caller})`` when reloaded; ``ServiceReply(ok=False, error, body={lec,
        registry, active, status})`` when refused (a requester receives a
        :class:`~anunnaki.bus.ServiceError`).
        """
        if not self.ok:
            return ServiceReply(
                ok=False,
                error=self.error or "refused",
                body={
                    "lec": self.lec,
                    "registry": self.registry,
                    "active": self.active,
                    "status": self.status,
                },
            )
        return ServiceReply(
            ok=True,
            body={
                "lec": self.lec,
                "registry": self.registry,
                "active": self.active,
                "models": list(self.models),
                "added": list(self.added),
                "changed": list(self.changed),
                "removed": list(self.removed),
                "caller": self.caller,
            },
        )


class _Active(NamedTuple):
    spec: ModelSpec
    detector: Detector


def _labels(detector: Detector, labels: Any) -> list[str]:
    classes = tuple(getattr(detector, "classes", ()) or ())
    out = []
    for raw in np.asarray(labels).reshape(-1).tolist():
        index = int(raw)
        out.append(classes[index] if 0 <= index < len(classes) else str(index))
    return out


class LecNode(Node):
    """Runs an LEC's active model on a camera topic and swaps models on request.

    A :class:`~anunnaki.bus.Node`: the kit owns its lifecycle (declare, liveliness token,
    spin, close); the work runs on the bus's delivery threads.

    Args:
        bus: The bus to work on.
        registry: The LEC's models.
        lec: The LEC's name (default: the registry's ``lec``, usually ``detector``).
        camera: The camera topic (``Image`` frames), e.g. ``/uav/camera/image``.
        detections: Where to publish detections (default ``/lec/<lec>/detections``).
        active_topic: Where to announce the active model.
        swap_service: The swap service's name.
        node: The liveliness token held while the node runs.
        initial: The model id to start with (default: the registry's default model).
        active_period: Seconds between announcements of an unchanged active model
            (``None``: only on changes and by :meth:`publish_active`).
        frame_queue: Frames that may wait while one is processed; beyond it the oldest are
            dropped and counted by the bus (``bus.stats().dropped``).
        cache: How many inactive loaded models to keep in memory (0: none).
        reload_service: The registry reload service's name (an operator service).
        reload_dirs: Folders a reload may read a registry from, besides the folder of the
            registry file the node started with.
        operator_token: The token a reload request must carry; default
            ``$ANUNNAKI_OPERATOR_TOKEN``, else the user's own token file
            (:func:`anunnaki.tokens.user_operator_token`: written first if missing), as for
            Utu's operator services, so the reload service is never open by accident.

    The initial model is loaded in the constructor; a bad one raises at once (guideline B5),
    before anything is declared on the bus.

    Raises:
        ModelRegistryError: The initial model is unknown, its file corrupt or its hash wrong.
        ModelFileError: The operator token is too weak, or the user's token file unreadable.

    """

    def __init__(
        self,
        bus: Bus,
        registry: ModelRegistry,
        *,
        lec: str | None = None,
        camera: str = "/rover/camera/image",
        detections: str | None = None,
        active_topic: str = topics.ACTIVE_MODEL,
        swap_service: str = topics.SWAP,
        node: str = topics.LM_MANAGER,
        initial: str | None = None,
        active_period: float | None = 1.0,
        frame_queue: int = 64,
        cache: int = 2,
        reload_service: str = topics.RELOAD_MODELS,
        reload_dirs: Sequence[str | Path] = (),
        operator_token: str | None = None,
    ) -> None:
        if active_period is not None and not active_period > 0:
            raise ValueError(f"active_period must be > 0 seconds or None, got {active_period}")
        if cache < 0:
            raise ValueError(f"cache must be >= 0, got {cache}")
        self.bus = bus
        self.registry = registry
        self.lec = lec or registry.lec
        self.camera = camera
        self.detections_topic = detections or detections_topic(self.lec)
        self.active_topic = active_topic
        self.swap_service = swap_service
        self.reload_service = reload_service
        self.node = node
        started = Path(registry.source) if registry.source is not None else None
        roots = [started.resolve().parent] if started is not None and started.is_file() else []
        roots += [Path(d).resolve() for d in reload_dirs]
        #: The folders a reload may read a registry from (symlinks resolved).
        self.reload_roots: list[Path] = list(dict.fromkeys(roots))
        self._operator_token = service_operator_token("the model manager", given=operator_token)
        self._cache_size = cache
        self._cache: OrderedDict[str, Detector] = OrderedDict()
        self._lock = threading.Lock()
        self._swap_lock = threading.Lock()
        self._stop = threading.Event()
        self._frames = self._published = self._failed = self._swaps = self._refused = 0
        self._reloads = self._reloads_refused = self._unauthorised = 0
        spec = registry.resolve(initial) if initial is not None else registry.default
        self._active = _Active(spec, registry.load(spec))
        self._frame_queue = frame_queue
        super().__init__(bus, token=node, ready=None)
        try:
            self.publish_active()
        except BaseException:
            self.close()
            raise
        self._heartbeat: threading.Thread | None = None
        self._beat_at: float | None = None  # on an executor: the sim time of the last beat
        if active_period is not None and getattr(bus, "executor", None) is not None:
            # One thread of delivery (a simulated run): the beat keeps the run's own time,
            # the simulation's /clock, as an rclpy timer on sim time does; never a wall thread.
            self._period = active_period
            self.own(bus.subscribe(topics.CLOCK, self._on_clock, queue=4))
        elif active_period is not None:
            self._heartbeat = threading.Thread(
                target=self._beat, args=(active_period,), name=f"lec-active:{self.lec}",
                daemon=True,
            )  # fmt: skip
            self._heartbeat.start()

    def declare(self) -> None:
        """The detections publisher, the swap service and the camera subscription."""
        self._detections: Publisher = self.own(self.bus.publisher(self.detections_topic))
        self.own(self.bus.service(self.swap_service, self._on_swap))
        self.own(self.bus.service(self.reload_service, self._on_reload))
        self.own(
            self.bus.subscribe(self.camera, self._on_frame, queue=self._frame_queue, expect=Image)
        )

    def __repr__(self) -> str:
        return f"LecNode(lec={self.lec!r}, active={self.active.id!r}, camera={self.camera!r})"

    # -- state -------------------------------------------------------------------------------
    @property
    def active(self) -> ModelSpec:
        """The active model's registry entry."""
        with self._lock:
            return self._active.spec

    def stats(self) -> LecNodeStats:
        """The node's counters."""
        with self._lock:
            return LecNodeStats(
                self._frames,
                self._published,
                self._failed,
                self._swaps,
                self._refused,
                self._reloads,
                self._reloads_refused,
            )

    def active_message(self) -> dict[str, str]:
        """The announcement: ``{lec, model, domain}``."""
        spec = self.active
        return {"lec": self.lec, "model": spec.id, "domain": spec.domain}

    def publish_active(self) -> None:
        """Announce the active model on the active topic now."""
        try:
            self.bus.publish(self.active_topic, self.active_message())
        except AnunnakiError as exc:  # the bus closed under us: nothing to announce to
            log.debug("lec %s: could not announce the active model: %s", self.lec, exc)

    def _on_clock(self, sample: Sample) -> None:
        t = getattr(sample.message, "time", None)
        if not isinstance(t, int | float):
            return
        if self._beat_at is None or t < self._beat_at:
            self._beat_at = float(t)
        elif t - self._beat_at >= self._period - 1e-9:
            self._beat_at = float(t)
            self.publish_active()

    def _beat(self, period: float) -> None:
        while not self._stop.wait(period):
            self.publish_active()

    # -- the frame path ----------------------------------------------------------------------
    def _on_frame(self, sample: Sample) -> None:
        message = sample.message
        assert isinstance(message, Image)  # the subscriber expects Image
        with self._lock:
            self._frames += 1
        try:
            image = decode_image(message)
        except (ValueError, MissingExtraError) as exc:
            self._count_failure("%s (on %s)", exc, sample.topic)
            return
        with self._lock:  # the one read of the active model for this frame
            active = self._active
        start = time.perf_counter()
        try:
            results = active.detector.detect([image])
            result = results[0]
            latency_ms = (time.perf_counter() - start) * 1000.0
            out = Detections(
                frame_seq=message.seq,
                model_id=active.spec.id,
                domain=active.spec.domain,
                width=int(image.shape[1]),
                height=int(image.shape[0]),
                boxes=np.asarray(result.boxes, dtype=np.float64).reshape(-1, 4).tolist(),
                labels=_labels(active.detector, result.labels),
                scores=np.asarray(result.scores, dtype=np.float64).reshape(-1).tolist(),
                latency_ms=round(latency_ms, 3),
            )
        except Exception as exc:  # one bad frame or model output never kills the node
            self._count_failure(
                "frame %d: model %s raised %s: %s",
                message.seq,
                active.spec.id,
                type(exc).__name__,
                exc,
            )
            return
        try:
            self._detections.put(out)
        except AnunnakiError as exc:
            self._count_failure("frame %d: could not publish: %s", message.seq, exc)
            return
        with self._lock:
            self._published += 1

    def _count_failure(self, fmt: str, *args: Any) -> None:
        with self._lock:
            self._failed += 1
        log.warning("lec %s: " + fmt, self.lec, *args)

    # -- swapping ----------------------------------------------------------------------------
    def swap(
        self, model: str | None = None, *, domain: str | None = None, lec: str | None = None
    ) -> SwapResult:
        """Swap to a model (by id) or to a domain's model; returns once switched or refused.

        Blocks the caller while the new model loads; the frame thread keeps running the old
        model meanwhile. Swaps are serialised.
        """
        with self._swap_lock:
            current = self.active
            if lec is not None and lec != self.lec:
                return self._refuse(
                    current, f"this model manager serves lec {self.lec!r}, not {lec!r}"
                )
            if model is None and domain is None:
                return self._refuse(current, "say what to swap to: 'model' or 'domain'")
            try:
                spec = self.registry.resolve(model, domain)
            except ModelRegistryError as exc:
                return self._refuse(current, str(exc))
            if spec.id == current.id:
                return SwapResult(True, self.lec, spec.id, spec.domain, current.id)
            start = time.perf_counter()
            detector = self._cache.pop(spec.id, None)
            if detector is None:
                try:
                    detector = self.registry.load(spec)
                except AnunnakiError as exc:
                    return self._refuse(current, str(exc))
                except Exception as exc:  # a loader bug must not take the node down
                    return self._refuse(current, f"{type(exc).__name__}: {exc}")
            load_ms = (time.perf_counter() - start) * 1000.0
            with self._lock:
                old = self._active
                self._active = _Active(spec, detector)
                self._swaps += 1
            if self._cache_size:
                self._cache[old.spec.id] = old.detector
                while len(self._cache) > self._cache_size:
                    self._cache.popitem(last=False)
            log.info(
                "lec %s: swapped %s -> %s (%s) in %.1f ms",
                self.lec,
                old.spec.id,
                spec.id,
                spec.domain,
                load_ms,
            )
            self.publish_active()
            return SwapResult(
                True, self.lec, spec.id, spec.domain, old.spec.id, load_ms, changed=True
            )

    def _refuse(self, current: ModelSpec, error: str) -> SwapResult:
        with self._lock:
            self._refused += 1
        log.warning("lec %s: swap refused, %s keeps running: %s", self.lec, current.id, error)
        return SwapResult(False, self.lec, current.id, current.domain, current.id, error=error)

    def _on_swap(self, request: Any) -> ServiceReply:
        body = body_of(request)
        fields: dict[str, str | None] = {}
        for key in ("lec", "model", "domain"):
            value = body.get(key)
            if value is not None and not isinstance(value, str):
                return self._refuse(
                    self.active, f"'{key}' must be a string, got {type(value).__name__}"
                ).reply()
            fields[key] = value
        return self.swap(fields["model"], domain=fields["domain"], lec=fields["lec"]).reply()

    # -- reloading the registry --------------------------------------------------------------
    def reload(self, registry: str | Path | None = None, *, caller: str = "api") -> ReloadResult:
        """Re-read the registry file (or ``registry``) and swap from the new one from now on.

        The file must lie in :attr:`reload_roots`; it is read and checked as at a start
        (``_registry_reload.reread``: every model's and oracle's sha256, every new model
        loaded once) while frames keep running; the model in use must stay listed with the
        same files. Accepted, the registry object is updated in place (whoever holds it
        sees the new models), cached models whose entry changed are dropped, the reload is
        logged and the active model announced again. Refused, nothing changes. Serialised
        with swaps.
        """
        with self._swap_lock:
            current = self.active
            path = Path(registry) if registry is not None else None
            if path is None:
                if self.registry.source is None or not Path(self.registry.source).is_file():
                    return self._refuse_reload(
                        current,
                        caller,
                        "this model manager's registry was not read from a file; name the "
                        "registry file to read ('registry' in the request)",
                    )
                path = Path(self.registry.source)
            real = path.resolve()
            if not any(real.is_relative_to(root) for root in self.reload_roots):
                return self._refuse_reload(
                    current,
                    caller,
                    str(
                        ModelFileError(
                            "refused: the registry is outside the folders a reload may read",
                            path=path,
                            hint="put it next to the registry the model manager started with, "
                            "or list its folder in reload_dirs (now: "
                            f"{', '.join(map(str, self.reload_roots)) or 'none'})",
                        )
                    ),
                )
            try:
                change = reread(self.registry, path, keep=current.id)
            except AnunnakiError as exc:
                return self._refuse_reload(current, caller, str(exc))
            except Exception as exc:  # a loader bug must not take the node down
                return self._refuse_reload(current, caller, f"{type(exc).__name__}: {exc}")
            with self._lock:
                replace(self.registry, change)
                spec = self.registry.get(current.id)
                self._active = _Active(spec, self._active.detector)
                self._reloads += 1
            for model_id in (*change.changed, *change.removed):
                self._cache.pop(model_id, None)
            log.info(
                "lec %s: registry reloaded from %s by %s (added %s; changed %s; removed %s); "
                "%s keeps running",
                self.lec,
                change.source,
                caller,
                ", ".join(change.added) or "none",
                ", ".join(change.changed) or "none",
                ", ".join(change.removed) or "none",
                spec.id,
            )
            self.publish_active()
            return ReloadResult(
                True,
                self.lec,
                change.source,
                spec.id,
                tuple(self.registry.ids()),
                change.added,
                change.changed,
                change.removed,
                caller,
            )

    def _refuse_reload(
        self, current: ModelSpec, caller: str, error: str, status: str = "refused"
    ) -> ReloadResult:
        unauthorised = status == "unauthorised"
        with self._lock:
            self._reloads_refused += 1
            # Like Utu: the first request without the token is logged, the rest counted.
            quiet = unauthorised and self._unauthorised > 0
            self._unauthorised += unauthorised
        (log.debug if quiet else log.warning)(
            "lec %s: registry reload by %s refused, the registry %s is kept: %s",
            self.lec,
            caller,
            self.registry.source,
            error,
        )
        return ReloadResult(
            False,
            self.lec,
            self.registry.source,
            current.id,
            tuple(self.registry.ids()),
            caller=caller,
            status=status,
            error=error,
        )

    def _on_reload(self, request: Any) -> ServiceReply:
        body = body_of(request)
        caller = body.get("caller", "bus")
        if not isinstance(caller, str):
            caller = "bus"
        current = self.active
        if not token_matches(body.get("token"), self._operator_token):
            return self._refuse_reload(
                current,
                caller,
                "unauthorised: reload needs the operator token ('token' in the request; "
                f"clients read it from ${OPERATOR_TOKEN_ENV}, else from the user's "
                f"{default_token_file()})",
                status="unauthorised",
            ).reply()
        registry = body.get("registry")
        if registry is not None and not isinstance(registry, str):
            return self._refuse_reload(
                current,
                caller,
                f"'registry' must be a path (a string), got {type(registry).__name__}",
            ).reply()
        return self.reload(registry, caller=caller).reply()

    # -- life --------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop announcing, release the camera, the service and the token (idempotent).

        A frame in flight finishes first.
        """
        self._stop.set()
        super().close()

    def release(self) -> None:
        """Join the announcer and drop the cached models."""
        heartbeat = getattr(self, "_heartbeat", None)
        if heartbeat is not None and heartbeat is not threading.current_thread():
            heartbeat.join(timeout=2.0)
        self._cache.clear()
