"""RELAX specs: what a goal model may write under ``relax:``, checked for shape only.

One pydantic model per operator, gathered in the discriminated union :data:`RelaxSpec`
(tag: ``operator``) that the goal-model schema embeds. The specs check positive
tolerances, finite numbers and non-empty expressions, and say what to write instead; they
compute nothing. :func:`anunnaki.goals._relax.build_operator` turns one into an operator.
This module exists apart from the operators because the schema needs the specs and
nothing else.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

__all__ = [
    "AfterSpec",
    "AsCloseAsPossibleToFrequencySpec",
    "AsCloseAsPossibleToQuantitySpec",
    "AsEarlyAsPossibleSpec",
    "AsFewAsPossibleSpec",
    "AsLateAsPossibleSpec",
    "AsManyAsPossibleSpec",
    "BeforeSpec",
    "EventuallySpec",
    "MayOrSpec",
    "RelaxSpec",
    "RelaxSpecBase",
    "ShallSpec",
    "Side",
    "UntilSpec",
]

_Number = Annotated[float, Field(strict=True)]
"""A float field that accepts ints and floats, but not booleans or strings."""


def _finite(name: str, value: float, example: str) -> None:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value}; write e.g. {example}")


def _check_tolerance(value: float) -> float:
    _finite("tolerance", value, "'tolerance: 0.5'")
    if value <= 0.0:
        raise ValueError(
            f"tolerance must be greater than 0, got {value}: it is the distance over which "
            "the utility falls from 1 to 0. Write a positive width such as 'tolerance: 0.5' "
            "(a requirement with no tolerance is crisp: use 'operator: shall')"
        )
    if not math.isfinite(1.0 / value):
        raise ValueError(f"tolerance {value} is too small to divide by; write e.g. 0.001")
    return value


def _check_within(value: float) -> float:
    _finite("within", value, "'within: 10.0'")
    if value < 0.0:
        raise ValueError(
            f"within must be 0 or more seconds, got {value}; write e.g. 'within: 10.0' "
            "(0 means: at once)"
        )
    return value


def _check_window(value: float | None) -> float | None:
    if value is None:
        return None
    _finite("window", value, "'window: 60.0'")
    if value <= 0.0:
        raise ValueError(
            f"window must be greater than 0 seconds, got {value}; write e.g. 'window: 60.0', "
            "or leave it out to judge the latest episode however long ago it was"
        )
    return value


def _check_expression(value: str, name: str, example: str) -> str:
    text = value.strip()
    if not text:
        raise ValueError(f"{name} must be a non-empty expression; write e.g. {example}")
    return text


_Tolerance = Annotated[_Number, AfterValidator(_check_tolerance)]
_Within = Annotated[_Number, AfterValidator(_check_within)]
_Window = Annotated[_Number | None, AfterValidator(_check_window)]


class RelaxSpecBase(BaseModel):
    """Fields common to every RELAX spec.

    Attributes:
        unit: Unit of the observed value or of time, for display only (e.g. ``Hz``, ``s``).

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    unit: str | None = None


class ShallSpec(RelaxSpecBase):
    """SHALL: the requirement must hold (crisp); utility is the value clamped to [0, 1]."""

    operator: Literal["shall"] = "shall"


class MayOrSpec(RelaxSpecBase):
    """MAY … OR: one or more alternatives; utility is the fuzzy OR (maximum) of theirs.

    Attributes:
        alternatives: Two or more expressions; the evaluator compiles and evaluates each.
            A YAML list is accepted and stored as a tuple.

    """

    operator: Literal["may_or"] = "may_or"
    alternatives: tuple[str, ...]

    @field_validator("alternatives")
    @classmethod
    def _two_or_more(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        example = "'alternatives: [A2.lidar_ok, A3.sonar_ok]'"
        texts = tuple(_check_expression(v, "each of the alternatives", example) for v in value)
        if len(texts) < 2:
            raise ValueError(
                f"alternatives needs at least 2 expressions, got {len(texts)}; write e.g. "
                "'alternatives: [A2.lidar_ok, A3.sonar_ok]' (a single one is 'operator: shall')"
            )
        seen: set[str] = set()
        for text in texts:
            if text in seen:
                raise ValueError(f"alternative '{text}' appears twice; remove the duplicate")
            seen.add(text)
        return texts


Side = Literal["both", "at_least", "at_most"]


class _CloseToSpec(RelaxSpecBase):
    """Shared shape of the AS CLOSE AS POSSIBLE TO operators."""

    target: _Number
    tolerance: _Tolerance
    side: Side = "both"

    @field_validator("target")
    @classmethod
    def _finite_target(cls, value: float) -> float:
        _finite("target", value, "'target: 5.0'")
        return value

    @model_validator(mode="after")
    def _finite_edges(self) -> _CloseToSpec:
        if not (
            math.isfinite(self.target - self.tolerance)
            and math.isfinite(self.target + self.tolerance)
        ):
            raise ValueError("target ± tolerance overflows; use smaller numbers (another unit)")
        return self


class AsCloseAsPossibleToFrequencySpec(_CloseToSpec):
    """AS CLOSE AS POSSIBLE TO [frequency]: something repeats at a rate near ``target`` Hz.

    Attributes:
        target: The required frequency in Hz (> 0).
        tolerance: How far (Hz) the rate may stray before the utility reaches 0 (> 0).
        side: ``both`` (triangle around the target), ``at_least`` (only too slow is
            penalised) or ``at_most`` (only too fast is penalised).

    """

    operator: Literal["as_close_as_possible_to_frequency"] = "as_close_as_possible_to_frequency"

    @field_validator("target")
    @classmethod
    def _positive_frequency(cls, value: float) -> float:
        if value <= 0.0:
            raise ValueError(
                f"target is a frequency in Hz and must be greater than 0, got {value}; "
                "write e.g. 'target: 5.0'"
            )
        return value


class AsCloseAsPossibleToQuantitySpec(_CloseToSpec):
    """AS CLOSE AS POSSIBLE TO [quantity]: a countable quantity near ``target``.

    Attributes:
        target: The required quantity.
        tolerance: How far the quantity may stray before the utility reaches 0 (> 0).
        side: ``both``, ``at_least`` or ``at_most`` (as for the frequency operator).

    """

    operator: Literal["as_close_as_possible_to_quantity"] = "as_close_as_possible_to_quantity"


class _OrdinalSpec(RelaxSpecBase):
    """Shared shape of AS FEW / AS MANY AS POSSIBLE."""

    target: _Number
    tolerance: _Tolerance

    @field_validator("target")
    @classmethod
    def _finite_target(cls, value: float) -> float:
        _finite("target", value, "'target: 3'")
        return value

    @model_validator(mode="after")
    def _finite_edges(self) -> _OrdinalSpec:
        if not (
            math.isfinite(self.target - self.tolerance)
            and math.isfinite(self.target + self.tolerance)
        ):
            raise ValueError("target ± tolerance overflows; use smaller numbers (another unit)")
        return self


class AsFewAsPossibleSpec(_OrdinalSpec):
    """AS FEW AS POSSIBLE: a count should stay at or below ``target``.

    Attributes:
        target: The ideal maximum; utility is 1 at or below it.
        tolerance: Utility falls linearly to 0 at ``target + tolerance`` (> 0).

    """

    operator: Literal["as_few_as_possible"] = "as_few_as_possible"


class AsManyAsPossibleSpec(_OrdinalSpec):
    """AS MANY AS POSSIBLE: a count should reach at least ``target``.

    Attributes:
        target: The ideal minimum; utility is 1 at or above it.
        tolerance: Utility falls linearly to 0 at ``target - tolerance`` (> 0).

    """

    operator: Literal["as_many_as_possible"] = "as_many_as_possible"


class _EventSpec(RelaxSpecBase):
    """Shared shape of the temporal operators that relate the goal to an event."""

    event: str
    tolerance: _Tolerance
    window: _Window = None

    @field_validator("event")
    @classmethod
    def _event_expression(cls, value: str) -> str:
        return _check_expression(value, "event", "'event: A1.obstacle_detected'")


class EventuallySpec(RelaxSpecBase):
    """EVENTUALLY: the condition shall hold at some time within the last ``within`` seconds.

    Attributes:
        within: Seconds since the condition last held that still count as fully met (≥ 0).
        tolerance: Further seconds over which the utility falls from 1 to 0 (> 0).

    """

    operator: Literal["eventually"] = "eventually"
    within: _Within
    tolerance: _Tolerance


class UntilSpec(_EventSpec):
    """UNTIL: the condition shall hold until ``event`` occurs.

    Attributes:
        event: Expression of the event that discharges the obligation.
        tolerance: Seconds of not holding (summed) at which the utility reaches 0 (> 0).
        window: Optional sliding window in seconds; only its time counts. Without it the
            latest episode is judged however long ago it started.

    """

    operator: Literal["until"] = "until"


class BeforeSpec(_EventSpec):
    """BEFORE: the condition shall have held before ``event`` occurs.

    Attributes:
        event: Expression of the event.
        tolerance: Seconds of lateness (condition first holding after the event) at which
            the utility reaches 0 (> 0).
        window: Optional sliding window in seconds (≥ tolerance); older events are forgotten.

    """

    operator: Literal["before"] = "before"

    @model_validator(mode="after")
    def _window_covers_tolerance(self) -> BeforeSpec:
        if self.window is not None and self.window < self.tolerance:
            raise ValueError(
                f"window ({self.window}) must be at least tolerance ({self.tolerance}), or a "
                "late condition would be forgotten before it counts; "
                f"write 'window: {self.tolerance}' or more, or leave window out"
            )
        return self


class AfterSpec(_EventSpec):
    """AFTER: the condition shall hold after ``event`` occurs, within ``within`` seconds.

    Attributes:
        event: Expression of the event that triggers the obligation.
        within: Seconds after the event's onset by which the condition should hold (≥ 0).
        tolerance: Further seconds over which the utility falls from 1 to 0 (> 0).
        window: Optional sliding window in seconds (≥ within + tolerance); older events
            are forgotten.

    """

    operator: Literal["after"] = "after"
    within: _Within = 0.0

    @model_validator(mode="after")
    def _window_covers_deadline(self) -> AfterSpec:
        need = self.within + self.tolerance
        if self.window is not None and self.window < need:
            raise ValueError(
                f"window ({self.window}) must be at least within + tolerance ({need}), or a "
                "missing response would be forgotten before it counts; "
                f"write 'window: {need}' or more, or leave window out"
            )
        return self


class AsEarlyAsPossibleSpec(RelaxSpecBase):
    """AS EARLY AS POSSIBLE: the condition should (again) hold as soon as possible.

    Attributes:
        tolerance: Seconds of not holding at which the utility reaches 0 (> 0).

    """

    operator: Literal["as_early_as_possible"] = "as_early_as_possible"
    tolerance: _Tolerance


class AsLateAsPossibleSpec(RelaxSpecBase):
    """AS LATE AS POSSIBLE: the condition should be delayed as long as possible.

    Attributes:
        target: The desired minimum delay in seconds between two holding periods (> 0);
            a delay of ``target`` or more gives utility 1.

    """

    operator: Literal["as_late_as_possible"] = "as_late_as_possible"
    target: _Number

    @field_validator("target")
    @classmethod
    def _positive_delay(cls, value: float) -> float:
        _finite("target", value, "'target: 60.0'")
        if value <= 0.0 or not math.isfinite(1.0 / value):
            raise ValueError(
                f"target is the desired minimum delay in seconds and must be greater than 0, "
                f"got {value}; write e.g. 'target: 60.0'"
            )
        return value


RelaxSpec = Annotated[
    ShallSpec
    | MayOrSpec
    | AsCloseAsPossibleToFrequencySpec
    | AsCloseAsPossibleToQuantitySpec
    | AsFewAsPossibleSpec
    | AsManyAsPossibleSpec
    | EventuallySpec
    | UntilSpec
    | BeforeSpec
    | AfterSpec
    | AsEarlyAsPossibleSpec
    | AsLateAsPossibleSpec,
    Field(discriminator="operator"),
]
"""Any RELAX spec, told apart by its ``operator`` field (e.g. ``operator: eventually``)."""
