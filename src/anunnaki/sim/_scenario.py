"""Scenario files: what the world holds and which adverse conditions arrive when.

A scenario is data (``examples/rover/scenario.yaml``), validated by pydantic on load with
errors that name the file, the line and the field. Its time line is evaluated by
:class:`Timeline`, a pure function of simulation time, so the ground truth published on
``/sim/phenomena`` is exactly what was applied to the frame.

Phenomenon events ramp: from ``at`` the phenomenon is active and its parameters move
linearly, over ``ramp`` seconds, from where they were (the identity, or the parameters an
earlier event of the same phenomenon had reached at ``at``) to the event's target, given
either as a scalar ``strength`` (the phenomenon's :meth:`strength_params`) or as explicit
``params``. ``until`` ends it. Active phenomena apply in the order they first started.

Faults act beyond the camera: ``rate`` (a sensor publishes at another rate, e.g. the
ultrasonic's 10 → 4.8 → 3 Hz of goal G6), ``dropout`` (a sensor's topic falls silent for
``duration`` seconds) and ``battery_drain`` (extra drain in % per second, obstacle O2).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from anunnaki.errors import ModelFileError

__all__ = [
    "CameraConfig",
    "FaultEvent",
    "ObjectSpec",
    "PhenomenonEvent",
    "Scenario",
    "Timeline",
    "UavMission",
    "UltrasonicConfig",
    "Variation",
    "draw_scenario",
    "load_scenario",
    "parse_scenario",
]

Sensor = Literal["camera", "ultrasonic", "gps", "battery", "status", "link"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class CameraConfig(_Strict):
    """The camera: rate (Hz), image size (pixels), encoding on the bus."""

    rate: float = Field(10.0, gt=0.0, le=120.0)
    width: int = Field(128, ge=16, le=1920)
    height: int = Field(128, ge=16, le=1080)
    encoding: Literal["jpeg", "png"] = "jpeg"
    quality: int = Field(90, ge=10, le=100)


class UltrasonicConfig(_Strict):
    """The rover's ultrasonic range finder: rate (Hz), max range (m), mounting height (m)."""

    rate: float = Field(10.0, gt=0.0, le=100.0)
    max_range: float = Field(4.0, gt=0.1, le=20.0)


class ObjectSpec(_Strict):
    """An object placed in the world on top of the layout's (e.g. on the route).

    ``walk_to``/``speed``/``start``: a pedestrian or deer that walks, from ``start`` seconds,
    towards ``walk_to`` at ``speed`` m/s (a crossing).
    """

    kind: str
    x: float
    y: float
    yaw: float = 0.0
    size: float | None = Field(None, gt=0.0, le=20.0)
    walk_to: tuple[float, float] | None = None
    speed: float = Field(0.0, ge=0.0, le=5.0)
    start: float = Field(0.0, ge=0.0)

    @field_validator("kind")
    @classmethod
    def _kind(cls, v: str) -> str:
        kinds = ("pedestrian", "deer", "vehicle", "cube", "sphere", "duck", "ball", "mug", "teddy")
        if v not in kinds:
            raise ValueError(f"unknown object kind {v!r}; kinds: {', '.join(kinds)}")
        return v


class PhenomenonEvent(_Strict):
    """A phenomenon on the camera stream from ``at``, ramping over ``ramp`` seconds."""

    at: float = Field(ge=0.0)
    phenomenon: str
    strength: float | None = Field(None, ge=0.0, le=1.0)
    params: dict[str, float] | None = None
    ramp: float = Field(0.0, ge=0.0)
    until: float | None = None

    @model_validator(mode="after")
    def _check(self) -> PhenomenonEvent:
        from anunnaki.phenomena import PHENOMENA, PhenomenonError

        if (self.strength is None) == (self.params is None):
            raise ValueError("give exactly one of 'strength' (0..1) or 'params'")
        if self.until is not None and self.until <= self.at:
            raise ValueError(f"'until' ({self.until}) must be after 'at' ({self.at})")
        try:
            phenomenon = PHENOMENA.create(self.phenomenon)
        except Exception:
            names = ", ".join(PHENOMENA.names())
            raise ValueError(f"unknown phenomenon {self.phenomenon!r}; known: {names}") from None
        if self.params is not None:
            try:
                phenomenon.validate(self.params)
            except PhenomenonError as exc:
                raise ValueError(str(exc)) from None
        return self


class FaultEvent(_Strict):
    """A fault beyond the camera, from ``at``."""

    at: float = Field(ge=0.0)
    fault: Literal["rate", "dropout", "battery_drain"]
    sensor: Sensor | None = None
    rate: float | None = Field(None, ge=0.0)
    duration: float | None = Field(None, gt=0.0)

    @model_validator(mode="after")
    def _check(self) -> FaultEvent:
        if self.fault in ("rate", "dropout") and self.sensor is None:
            raise ValueError(f"a '{self.fault}' fault names its 'sensor'")
        if self.fault == "rate" and (self.rate is None or self.rate <= 0):
            raise ValueError("a 'rate' fault gives the new 'rate' in Hz (> 0)")
        if self.fault == "dropout" and self.duration is None:
            raise ValueError("a 'dropout' fault gives its 'duration' in seconds")
        if self.fault == "battery_drain" and self.rate is None:
            raise ValueError("a 'battery_drain' fault gives the extra drain 'rate' in %/s")
        return self


class UavMission(_Strict):
    """The UAV's delivery mission in local metres (x east, y north) around ``origin``."""

    home: tuple[float, float] = (0.0, 0.0)
    waypoints: list[tuple[float, float]] = Field(
        default_factory=lambda: [(-20.0, 10.0), (10.0, 25.0)]
    )
    delivery: tuple[float, float] = (25.0, -15.0)
    cruise_altitude: float = Field(30.0, gt=2.0, le=120.0)
    speed: float = Field(6.0, gt=0.0, le=25.0)
    climb_rate: float = Field(3.0, gt=0.0, le=10.0)
    origin: tuple[float, float] = (42.7251, -84.4791)  # lat, lon (degrees)
    start_altitude: float = Field(0.0, ge=0.0, le=120.0)
    battery: float = Field(100.0, gt=0.0, le=100.0)
    drain_hover: float = Field(0.12, ge=0.0)
    drain_per_speed: float = Field(0.02, ge=0.0)
    deliver_time: float = Field(3.0, ge=0.0)
    gps_rate: float = Field(10.0, gt=0.0, le=100.0)
    battery_rate: float = Field(1.0, gt=0.0, le=100.0)

    @field_validator("origin")
    @classmethod
    def _origin(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not (-90 <= v[0] <= 90 and -180 <= v[1] <= 180):
            raise ValueError("origin is (latitude, longitude) in degrees")
        return v


class Variation(_Strict):
    """How a scenario is drawn again per seed (``vary:``; :func:`draw_scenario`).

    Attributes:
        timing: Seconds: the phenomenon events that start at the same time (one phase) move
            together by a shift drawn uniformly in ``[-timing, timing]`` (``at`` and
            ``until`` alike), and each object's ``start`` moves by its own draw (not
            below 0).
        placement: Metres: each object's ``x`` (along the route) and its ``walk_to`` move
            by a shift drawn uniformly in ``[-placement, placement]``.
        strength: Each phenomenon event's target moves towards the identity by a fraction
            drawn uniformly in ``[0, strength]`` (0: as written; 0.3: as weak as 70 % of
            it); events that start together share the draw.
        fault_timing: Seconds: the faults of one sensor (``battery_drain``: of the battery)
            move together by a shift drawn uniformly in ``[-fault_timing, fault_timing]``
            (not below 0), so a rate fault and the later one that restores the rate keep
            their interval; a dropout keeps its ``duration``.
        drain: Each ``battery_drain`` fault's extra drain is scaled by a factor drawn
            uniformly in ``[1 - drain, 1 + drain]`` (one draw for all of them).

    """

    timing: float = Field(0.0, ge=0.0, le=30.0)
    placement: float = Field(0.0, ge=0.0, le=20.0)
    strength: float = Field(0.0, ge=0.0, le=1.0)
    fault_timing: float = Field(0.0, ge=0.0, le=30.0)
    drain: float = Field(0.0, ge=0.0, le=1.0)


class Scenario(_Strict):
    """A whole scenario file (``anunnaki: scenario/1``)."""

    anunnaki: Literal["scenario/1"] = "scenario/1"
    platform: Literal["rover", "uav"]
    name: str = ""
    description: str = ""
    layout: int = Field(0, ge=0)
    background: bool = True
    seed: int = Field(0, ge=0)
    duration: float = Field(60.0, gt=0.0)
    camera: CameraConfig = CameraConfig()
    ultrasonic: UltrasonicConfig = UltrasonicConfig()
    route: list[tuple[float, float]] = Field(default_factory=lambda: [(0.0, 0.0), (44.0, 0.0)])
    cruise_speed: float = Field(0.8, gt=0.0, le=3.0)
    mission: UavMission = UavMission()
    objects: list[ObjectSpec] = Field(default_factory=list)
    phenomena: list[PhenomenonEvent] = Field(default_factory=list)
    faults: list[FaultEvent] = Field(default_factory=list)
    vary: Variation | None = None

    @field_validator("route")
    @classmethod
    def _route(cls, v: list[tuple[float, float]]) -> list[tuple[float, float]]:
        if len(v) < 2:
            raise ValueError("a route has at least two points")
        return v

    @model_validator(mode="after")
    def _sensors(self) -> Scenario:
        allowed = {
            "rover": {"camera", "ultrasonic", "status"},
            "uav": {"camera", "gps", "battery", "status", "link"},
        }[self.platform]
        for fault in self.faults:
            if fault.sensor is not None and fault.sensor not in allowed:
                raise ValueError(
                    f"the {self.platform} has no sensor {fault.sensor!r}; "
                    f"sensors: {', '.join(sorted(allowed))}"
                )
        if not self.background and self.platform != "rover":
            raise ValueError(
                "background: false is for the rover (the UAV's layout is its whole scene)"
            )
        return self


def _weaker(event: PhenomenonEvent, fraction: float) -> dict[str, Any]:
    """``event``'s fields with its target moved ``fraction`` of the way to the identity."""
    from anunnaki.phenomena import PHENOMENA

    fields = event.model_dump(exclude_none=True)
    if event.strength is not None:
        fields["strength"] = event.strength * (1.0 - fraction)
        return fields
    assert event.params is not None
    ph = PHENOMENA.create(event.phenomenon)
    target, identity = ph.validate(event.params), ph.identity_params()
    params = {k: v + fraction * (identity[k] - v) for k, v in target.items()}
    fields["params"] = ph.validate(params)
    return fields


def draw_scenario(scenario: Scenario, seed: int) -> Scenario:
    """The scenario drawn again from ``seed`` as its ``vary:`` section says.

    Phase timing, object placement, condition strength, fault timing and battery drain are
    drawn with one generator seeded by ``seed`` (the same seed, the same scenario; the faults'
    draws come last, so a ``vary`` without fault fields draws the rest as it always did);
    the drawn scenario's ``seed`` is
    ``seed`` too, and it has no ``vary`` (drawing it again changes nothing). Without
    ``vary`` the scenario comes back with only its ``seed`` replaced.
    """
    import numpy as np

    v = scenario.vary
    if v is None:
        return scenario.model_copy(update={"seed": seed})
    rng = np.random.default_rng(seed)
    starts = sorted({e.at for e in scenario.phenomena})
    shift = {at: float(rng.uniform(-v.timing, v.timing)) for at in starts}
    weaken = {at: float(rng.uniform(0.0, v.strength)) for at in starts}
    phenomena = []
    for e in scenario.phenomena:
        fields = _weaker(e, weaken[e.at])
        fields["at"] = max(0.0, e.at + shift[e.at])
        if e.until is not None:
            fields["until"] = fields["at"] + (e.until - e.at)
        phenomena.append(PhenomenonEvent.model_validate(fields))
    objects = []
    for o in scenario.objects:
        dx = float(rng.uniform(-v.placement, v.placement))
        dt = float(rng.uniform(-v.timing, v.timing))
        fields = o.model_dump(exclude_none=True)
        fields["x"] = o.x + dx
        fields["start"] = max(0.0, o.start + dt)
        if o.walk_to is not None:
            fields["walk_to"] = (o.walk_to[0] + dx, o.walk_to[1])
        objects.append(ObjectSpec.model_validate(fields))
    return scenario.model_copy(
        update={
            "seed": seed,
            "vary": None,
            "objects": objects,
            "phenomena": phenomena,
            "faults": _drawn_faults(scenario.faults, v, rng),
        }
    )


def _drawn_faults(faults: list[FaultEvent], v: Variation, rng: Any) -> list[FaultEvent]:
    """``faults`` moved per sensor by ``v.fault_timing``, battery drains scaled by ``v.drain``."""
    if not faults or (v.fault_timing == 0.0 and v.drain == 0.0):
        return faults
    groups = sorted({f.sensor or "battery" for f in faults})
    shift = {g: float(rng.uniform(-v.fault_timing, v.fault_timing)) for g in groups}
    scale = float(rng.uniform(1.0 - v.drain, 1.0 + v.drain))
    out = []
    for f in faults:
        fields = f.model_dump(exclude_none=True)
        fields["at"] = max(0.0, f.at + shift[f.sensor or "battery"])
        if f.fault == "battery_drain" and f.rate is not None:
            fields["rate"] = f.rate * scale
        out.append(FaultEvent.model_validate(fields))
    return out


def parse_scenario(data: Any, *, lines: Any = None, path: str | Path | None = None) -> Scenario:
    """Validate loaded data into a :class:`Scenario` (errors name file, line and field)."""
    from anunnaki._safeyaml import validation_error

    if not isinstance(data, dict):
        raise ModelFileError("a scenario is a mapping", path=path, line=1)
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, path, hint="see docs/simulation.md") from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file.

    Raises:
        ModelFileError: Unreadable or invalid, as ``file:line: element: message``.

    """
    from anunnaki._safeyaml import load_yaml

    data, lines = load_yaml(path)
    return parse_scenario(data, lines=lines, path=path)


class _Segment:
    """One phenomenon event's ramp: from ``start`` at ``at`` to ``target`` over ``ramp`` s."""

    def __init__(
        self,
        at: float,
        start: dict[str, float],
        target: dict[str, float],
        ramp: float,
        until: float | None,
    ) -> None:
        self.at, self.start, self.target, self.ramp, self.until = at, start, target, ramp, until

    def active(self, t: float) -> bool:
        return self.until is None or t < self.until

    def value(self, t: float) -> dict[str, float]:
        w = 1.0 if self.ramp <= 0 else min(max((t - self.at) / self.ramp, 0.0), 1.0)
        return {k: (1.0 - w) * self.start.get(k, v) + w * v for k, v in self.target.items()}


class Timeline:
    """Evaluates a scenario's phenomena and faults at a simulation time (pure, cached)."""

    def __init__(self, scenario: Scenario) -> None:
        from anunnaki.phenomena import PHENOMENA

        self.scenario = scenario
        self._events = sorted(enumerate(scenario.phenomena), key=lambda item: (item[1].at, item[0]))
        self._phenomena = {e.phenomenon: PHENOMENA.create(e.phenomenon) for e in scenario.phenomena}
        self._faults = sorted(scenario.faults, key=lambda f: f.at)

    def _target(self, event: PhenomenonEvent) -> dict[str, float]:
        ph = self._phenomena[event.phenomenon]
        if event.params is not None:
            return ph.validate(event.params)
        assert event.strength is not None
        return ph.strength_params(event.strength)

    def phenomena(self, t: float) -> list[tuple[str, dict[str, float]]]:
        """The phenomena applied at time ``t``: ``[(name, params)]`` in application order."""
        segments: dict[str, _Segment] = {}
        order: list[str] = []
        for _, event in self._events:
            if event.at > t:
                break
            name = event.phenomenon
            prev = segments.get(name)
            start = (
                prev.value(event.at)
                if prev is not None and prev.active(event.at)
                else self._phenomena[name].identity_params()
            )
            segments[name] = _Segment(event.at, start, self._target(event), event.ramp, event.until)
            if name not in order:
                order.append(name)
        return [
            (name, self._phenomena[name].validate(segments[name].value(t)))
            for name in order
            if segments[name].active(t)
        ]

    def faults(self, t: float) -> list[dict[str, Any]]:
        """The faults in force at ``t`` (each as its event's fields, JSON-ready)."""
        active: dict[tuple[str, str | None], dict[str, Any]] = {}
        for f in self._faults:
            if f.at > t:
                break
            if f.fault == "dropout":
                assert f.duration is not None
                if t < f.at + f.duration:
                    active[("dropout", f.sensor)] = f.model_dump(exclude_none=True)
                continue
            active[(f.fault, f.sensor)] = f.model_dump(exclude_none=True)
        return list(active.values())

    def rate(self, sensor: str, default: float, t: float) -> float:
        """The rate of ``sensor`` at ``t`` (the latest ``rate`` fault, else ``default``)."""
        rate = default
        for f in self._faults:
            if f.at > t:
                break
            if f.fault == "rate" and f.sensor == sensor and f.rate is not None:
                rate = f.rate
        return rate

    def silent(self, sensor: str, t: float) -> bool:
        """Whether ``sensor``'s topic is in a dropout at ``t``."""
        return any(
            f.fault == "dropout"
            and f.sensor == sensor
            and f.duration is not None
            and f.at <= t < f.at + f.duration
            for f in self.scenario.faults
        )

    def extra_drain(self, t: float) -> float:
        """Extra battery drain (%/s) at ``t``: the latest ``battery_drain`` fault."""
        drain = 0.0
        for f in self._faults:
            if f.at > t:
                break
            if f.fault == "battery_drain" and f.rate is not None:
                drain = f.rate
        return drain
