"""The camera chain: the LEC node, the oracle node and a live scorer on one camera topic.

Every managed-system kind that has a camera (``sim``, ``ros1``, ``ros2``, a third party's
robot) wires it here, and only here::

    camera ─Image─▶ LecNode (the registry's active model) ─▶ /lec/detector/detections
       ├──────────▶ OracleNode (oracle) ─Assessment─▶ /utu/oracle/output   (Utu's agent A4)
       ├──────────▶ OracleNode (scorer) ─Assessment─▶ /sim/oracle/scorer   (no agent reads it)
       └──────────▶ OracleNode (shadow) ─Assessment─▶ /utu/oracle/shadow   (e.g. agent A7)

The shadow is one model's oracle assessing every frame whichever model is active (options
``domain: default`` or ``model: ID`` say which): while a robust model runs, the default
model's own oracle tells whether the default would cope now, so the way back to it need not
wait for the scene to *look* clear for a fixed time (docs/whole-loop.md).

The oracle and the scorer are options as a launch file gives them: ``name`` (a plugin of
the oracle slot) and the oracle's own options (e.g. ``window``). An oracle that takes
something from the assessed detector's model registry declares it with the optional hook
:class:`TakesModels`, a class method, found with ``isinstance`` and never by the oracle's
name: the ground-truth assessor takes the models' clean F1, Enlil's learned oracle the
registry itself. What an oracle observes (ground truth, detections, context) is the oracle
node's business, by the oracle's own hooks (:mod:`anunnaki.oracles`).

The detector and the oracles need the ``vision`` extra; they are imported when a chain is
built, so a kind without a camera costs nothing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from anunnaki import topics
from anunnaki._closing import Closing
from anunnaki.errors import ModelFileError

__all__ = [
    "CameraChain",
    "TakesModels",
    "check_camera_chain",
]


@runtime_checkable
class TakesModels(Protocol):
    """Optional, on an oracle's class: the options it takes from the assessed models.

    The camera chain calls it with the detector's model registry (an
    :class:`anunnaki.lec.ModelRegistry`) when the chain runs a detector; the options it
    returns fill in what the launch file leaves out (the file's own options win).
    """

    @classmethod
    def options_from_models(cls, models: Any) -> dict[str, Any]:
        """Options for the constructor, e.g. ``{"clean_f1": models.clean_f1}``."""
        ...


def _oracle_name(options: Mapping[str, Any], default: str | None, element: str) -> str:
    name = options.get("name", default)
    if not isinstance(name, str):
        raise ModelFileError(
            "the oracle has no name",
            element=f"{element}.name",
            hint="give its name, e.g. {name: ground_truth, window: 30}",
        )
    return name


def check_camera_chain(
    *,
    models: str | None,
    oracle: Mapping[str, Any] | None,
    scorer: Mapping[str, Any] | None = None,
    default_oracle: str | None = None,
    where: str = "managed",
    shadow: Mapping[str, Any] | None = None,
) -> None:
    """Bring-up checks (B5): load the registry, check the oracles' names.

    Errors are :class:`~anunnaki.errors.ModelFileError` naming the element under ``where``
    (e.g. ``managed.oracle.name``), so the launch file's line can be given.
    """
    registry = None
    if models is not None:
        from anunnaki.lec import load_registry

        registry = load_registry(models)
    if shadow is not None:
        _shadow_model(shadow, registry, f"{where}.shadow")
    for key, options in (("oracle", oracle), ("scorer", scorer), ("shadow", shadow)):
        if options is None:
            continue
        from anunnaki.oracles import ORACLES

        name = _oracle_name(options, default_oracle, f"{where}.{key}")
        if not ORACLES.offers(name):  # imports no plugin: Enlil's would import torch
            raise ModelFileError(
                f"unknown oracle {name!r}",
                element=f"{where}.{key}.name",
                hint=f"known oracles: {', '.join(ORACLES.names())}",
            )


def _shadow_model(options: Mapping[str, Any], registry: Any, element: str) -> str:
    """The model id a shadow oracle assesses: its ``model``, or its ``domain``'s model."""
    model, domain = options.get("model"), options.get("domain")
    if registry is None:
        raise ModelFileError(
            "a shadow oracle needs the detector's models",
            element=element,
            hint="give 'models:' (the registry) beside 'shadow:'",
        )
    if (model is None) == (domain is None):
        raise ModelFileError(
            "say which model the shadow oracle assesses",
            element=element,
            hint="give either 'domain' (e.g. domain: default) or 'model' (a model id), not both",
        )
    from anunnaki.lec import UnknownModelError

    try:
        spec = registry.resolve(model_id=model, domain=domain)
    except UnknownModelError as exc:
        raise ModelFileError(
            str(exc), element=f"{element}.{'model' if model is not None else 'domain'}"
        ) from None
    return str(spec.id)


class CameraChain(Closing):
    """The nodes on one camera topic: the detector, its oracle and a live scorer.

    Args:
        bus: The bus the managed system and Utu are on.
        camera: The camera topic (``Image``).
        models: The detector's model registry (a file or a loaded ``ModelRegistry``);
            ``None`` runs no detector.
        oracle: The oracle node's options (``name`` and the oracle's own); ``None``: none.
        scorer: A second oracle's options, run beside the first as its live scorer; it
            publishes on ``topics.SCORER`` as node ``/scorer_<name>``; ``None``: none.
        shadow: A shadow oracle's options: ``name``, the oracle's own, and ``domain`` or
            ``model``, the model it assesses on every frame whichever is active; it
            publishes on ``topics.SHADOW_ORACLE`` as node ``/shadow_<name>``; ``None``: none.
        classes: Class names, for ground truth that gives labels as indices.
        default_oracle: The oracle's name when its options give none (``None``: required).

    Attributes:
        registry: The loaded model registry (``None`` without a detector).
        lec: The LEC node (``None`` without a detector).
        oracle: The oracle node, or ``None``.
        scorer: The scorer's oracle node, or ``None``.
        shadow: The shadow oracle's node, or ``None``.
        detections_topic: Where the detector's detections go.

    """

    def __init__(
        self,
        bus: Any,
        *,
        camera: str,
        models: str | Path | Any = None,
        oracle: Mapping[str, Any] | None = None,
        scorer: Mapping[str, Any] | None = None,
        classes: Sequence[str] | None = None,
        default_oracle: str | None = None,
        shadow: Mapping[str, Any] | None = None,
    ) -> None:
        self.bus = bus
        self.camera = camera
        self._nodes: list[Any] = []
        self.registry: Any = None
        self.lec: Any = None
        self.oracle: Any = None
        self.scorer: Any = None
        self.shadow: Any = None
        self.detections_topic = topics.DETECTIONS
        try:
            if models is not None:
                from anunnaki.lec import LecNode, ModelRegistry, load_registry

                self.registry = (
                    models if isinstance(models, ModelRegistry) else load_registry(models)
                )
                self.lec = self._own(LecNode(bus, self.registry, camera=camera))
                self.detections_topic = self.lec.detections_topic
            self.oracle = self._oracle(oracle, classes, default_oracle)
            self.scorer = self._oracle(scorer, classes, default_oracle, output=topics.SCORER)
            if shadow is not None:
                opts = {k: v for k, v in shadow.items() if k != "domain"}
                opts["model"] = _shadow_model(shadow, self.registry, "shadow")
                self.shadow = self._oracle(
                    opts, classes, default_oracle, output=topics.SHADOW_ORACLE, role="shadow"
                )
        except BaseException:
            self.close()
            raise

    def _own(self, node: Any) -> Any:
        self._nodes.append(node)
        return node

    def _oracle(
        self,
        options: Mapping[str, Any] | None,
        classes: Sequence[str] | None,
        default: str | None,
        *,
        output: str | None = None,
        role: str = "scorer",
    ) -> Any:
        """An oracle node from its options, or ``None``."""
        if options is None:
            return None
        from anunnaki.oracles import ORACLES, OracleNode

        opts = dict(options)
        name = _oracle_name(opts, default, "oracle")
        opts.pop("name", None)
        factory = ORACLES.factory(name)
        if self.registry is not None and isinstance(factory, TakesModels):
            for key, value in factory.options_from_models(self.registry).items():
                opts.setdefault(key, value)
        if output is not None:
            opts.setdefault("output", output)
            opts.setdefault("node", f"/{role}_{name}")
        node = OracleNode(
            self.bus,
            name,
            camera=self.camera,
            detections=self.detections_topic,
            classes=classes,
            **opts,
        )
        return self._own(node)

    def describe(self) -> str:
        """One line for the launch's output: detector, oracle and scorer."""
        lec = self.lec
        text = "no detector; " if lec is None else f"detector {lec.active.id} on {self.camera}; "
        text += f"oracle {self.oracle.oracle.name}" if self.oracle is not None else "no oracle"
        if self.scorer is not None:
            text += f", scored live by {self.scorer.oracle.name}"
        if self.shadow is not None:
            text += f", shadowed by {self.shadow.oracle.name} for {self.shadow.model_id}"
        return text

    def close(self) -> None:
        """Close the scorer, the oracle and the LEC node (idempotent)."""
        while self._nodes:
            self._nodes.pop().close()
