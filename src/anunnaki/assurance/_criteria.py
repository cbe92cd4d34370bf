"""The criteria file (``anunnaki: assurance/1``): which measurement develops which claim.

A case's argument comes from the goal model; its evidence comes from the project's own
measurements, and this small file says which of them develops which goal, against what
acceptance criterion (docs/assurance.md, "The criteria file")::

    anunnaki: assurance/1
    case: rover
    goal_model: goals-lm.yaml           # the goal model it develops (relative to this file)
    evidence:
      G16:                              # a goal of the goal model, or an obstacle (O1)
        - kind: detector                # held-out F1 of each model of the launch's registry
          models: [rover-default]
          at_least: 0.9
        - kind: result                  # one figure of a results file
          file: benchmarks/results/case-studies.json
          path: cases.rover.summary.utu.collisions.max
          text: collisions over the 10 seeds under Utu (max)
          at_most: 0
          command: nice -n 10 .venv/bin/python benchmarks/case_studies.py --cases rover
          rests_on: [launch, goal_model, tactics, registry]

Paths are relative to the project root the case is built from (``--root``, default: the
working folder). Nothing in the file is evaluated: a ``path`` is a dotted key path into JSON.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from anunnaki._safeyaml import load_yaml, validation_error
from anunnaki.errors import ModelFileError

__all__ = [
    "CRITERIA_FORMAT",
    "STAGES",
    "Criteria",
    "EvidenceSpec",
    "load_criteria",
    "parse_criteria",
]

CRITERIA_FORMAT = "assurance/1"

#: The AMLAS stages an evidence item is filed under (Hawkins et al., 2021).
STAGES = ("data management", "model learning", "model verification", "model deployment")

Stage = Literal["data management", "model learning", "model verification", "model deployment"]

Kind = Literal["detector", "data", "robustness", "oracle", "oracle_ceiling", "result", "tests"]

#: Each kind's AMLAS stage unless the item names another.
DEFAULT_STAGE: dict[str, Stage] = {
    "data": "data management",
    "detector": "model learning",
    "robustness": "model verification",
    "oracle": "model verification",
    "oracle_ceiling": "model verification",
    "result": "model deployment",
    "tests": "model deployment",
}


class EvidenceSpec(BaseModel):
    """One evidence item of the criteria file (one or more GSN solutions once built).

    Attributes:
        kind: Where the figure comes from: ``detector`` (each model's held-out F1, its
            sidecar), ``data`` (the held-out images each model was measured on),
            ``robustness`` (the Enki comparison, ``benchmarks/results/robustify.json``),
            ``oracle`` (each model oracle's validation accuracy, its sidecar),
            ``oracle_ceiling`` (the oracle's macro-F1 against its labels' ceiling,
            ``benchmarks/results/oracle.json``), ``result`` (one figure of a results file)
            or ``tests`` (pytest node ids, run with ``--run-tests``).
        stage: The AMLAS stage (default: the kind's).
        models: Registry model ids the item covers (default: every model it finds).
        at_least / at_most / equals: The acceptance criterion on the figure.
        relax: Take the criterion from the goal's RELAX operator and threshold instead.
        file: ``result``: the JSON results file; ``robustness`` / ``oracle_ceiling``:
            another file than the default.
        path: ``result``: the dotted key path of the figure in ``file``.
        text: ``result``: what the figure is, in words.
        unit: The figure's unit, for display.
        command: The command that re-measures it (a default per kind otherwise).
        rests_on: Further artefacts the figure rests on: ``launch``, ``goal_model``,
            ``binding``, ``tactics``, ``registry``, ``model:ID``, ``oracle:ID`` or a path.
        measured_sha256: ``result``: a key path in ``file`` holding the sha256 of the
            artefact measured, and which artefact that is (``{path: oracle.sha256,
            artefact: oracle:rover-default}``): the figure is stale when they differ.
        conditions: The conditions (oracle contexts) the figure was measured in, where the
            kind does not know them (``[clear]``, ``[fog]``).
        tests: ``tests``: pytest node ids (``tests/x/test_y.py::test_z``).
        metric: ``robustness``: the measure compared (``mPC`` default, ``hardest``,
            ``random``, ``region``, ``rPC``).
        data: ``detector``: the dataset folder the command re-measures on.

    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Kind
    stage: Stage | None = None
    models: list[str] | None = None
    at_least: float | None = None
    at_most: float | None = None
    equals: float | None = None
    relax: bool = False
    file: str | None = None
    path: str | None = None
    text: str | None = None
    unit: str | None = None
    command: str | None = None
    rests_on: list[str] = Field(default_factory=list)
    measured_sha256: dict[str, str] | None = None
    conditions: list[str] | None = None
    tests: list[str] = Field(default_factory=list)
    metric: str = "mPC"
    data: str | None = None

    @model_validator(mode="after")
    def _shape(self) -> EvidenceSpec:
        given = [x for x in (self.at_least, self.at_most, self.equals) if x is not None]
        if self.kind == "tests":
            if not self.tests:
                raise ValueError("a 'tests' item needs 'tests: [tests/x/test_y.py::test_z]'")
            if given or self.relax:
                raise ValueError("a 'tests' item passes when its tests pass: drop the criterion")
            return self
        if len(given) + int(self.relax) != 1:
            raise ValueError(
                "give exactly one acceptance criterion: 'at_least: N', 'at_most: N', "
                "'equals: N' or 'relax: true' (the goal's RELAX threshold)"
            )
        if self.kind == "result" and not (self.file and self.path and self.text):
            raise ValueError(
                "a 'result' item needs 'file' (a JSON results file), 'path' (the dotted key "
                "path of the figure in it) and 'text' (what the figure is)"
            )
        if self.measured_sha256 is not None and set(self.measured_sha256) != {"path", "artefact"}:
            raise ValueError(
                "measured_sha256 takes 'path' (where the file records the sha256) and "
                "'artefact' (which artefact it is, e.g. oracle:rover-default)"
            )
        return self


class Criteria(BaseModel):
    """A criteria file: evidence items by goal (or obstacle) id."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    anunnaki: Literal["assurance/1"]
    case: str = ""
    description: str = ""
    goal_model: str | None = None
    evidence: dict[str, Annotated[list[EvidenceSpec], Field(min_length=1)]] = Field(
        default_factory=dict
    )
    source: str | None = None


def parse_criteria(data: Any, *, source: str, lines: Any = None) -> Criteria:
    """Check a criteria document (already read from YAML) and return it.

    Raises:
        ModelFileError: Not ``anunnaki: assurance/1``, an unknown field or kind, an item
            without exactly one criterion; naming the file, line and element.

    """
    if not isinstance(data, dict) or data.get("anunnaki") != CRITERIA_FORMAT:
        raise ModelFileError(
            "not an assurance criteria file",
            path=source,
            line=1,
            hint=f"start the file with 'anunnaki: {CRITERIA_FORMAT}' (docs/assurance.md)",
        )
    try:
        parsed = Criteria.model_validate(data)
    except ValidationError as exc:
        raise validation_error(exc, data, lines, source, hint="see docs/assurance.md") from None
    return parsed.model_copy(update={"source": source})


def load_criteria(path: str | Path) -> Criteria:
    """Read a criteria file (safe YAML); errors name the file and line."""
    data, lines = load_yaml(path)
    return parse_criteria(data, source=str(path), lines=lines)
