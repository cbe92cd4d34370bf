"""A new tactic action type is one class and its tag: parsed, planned and executed as it says.

The class below is the whole of a new action type. Nothing else is told of it: the YAML and
XML readers take it by its tag, the decision log says what its ``describe`` says, and the
executor sends what its ``send`` gives, with its own timeout, through the actuator.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

import pytest

from anunnaki.errors import ModelFileError
from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.plugins import PluginError
from anunnaki.tactics import (
    ACTIONS,
    ServiceRequest,
    TacticAction,
    dump_tactics_xml,
    dump_tactics_yaml,
    parse_tactics_xml,
    parse_tactics_yaml,
)
from anunnaki.utu import AutonomicManager, RecordingActuator

ROVER = Path(__file__).parents[2] / "examples" / "rover"


class SlowDownAction(TacticAction):
    """Ask the platform to drive at most ``speed`` m/s (the one class of a new action type)."""

    type: Literal["slow_down"] = "slow_down"
    speed: float
    service: str = "set_mode"  # a logical name: the binding maps it

    def send(self) -> ServiceRequest:
        return ServiceRequest(self.service, {"mode": "slow", "speed": self.speed}, 0.75)

    def describe(self, resolve: Callable[[str], str] = lambda name: name) -> dict[str, Any]:
        return {"service": resolve(self.service), "speed": self.speed}


@pytest.fixture
def slow_down() -> Iterator[type[SlowDownAction]]:
    ACTIONS.register(SlowDownAction)
    try:
        yield SlowDownAction
    finally:
        ACTIONS.unregister("slow_down")


YAML = """\
anunnaki: tactics/1
tactics:
  - name: careful
    preconditions: [{expression: "A4.category >= 1"}]
    actions:
      - {type: slow_down, speed: 0.5}
      - {type: notify, channel: log, message: slowed down}
"""

XML = """\
<tactics>
  <tactic name="careful">
    <preconditions><expression>A4.category &gt;= 1</expression></preconditions>
    <actions>
      <slow_down speed="0.5"/>
      <notify channel="log">slowed down</notify>
    </actions>
  </tactic>
</tactics>
"""


class TimedActuator(RecordingActuator):
    """Records each request's timeout too."""

    def __init__(self) -> None:
        super().__init__()
        self.timeouts: list[float] = []

    def request(self, service: str, payload: Mapping[str, Any], timeout: float) -> Any:
        self.timeouts.append(timeout)
        return super().request(service, payload, timeout)


@pytest.mark.parametrize("form", ["yaml", "xml"])
def test_a_new_action_type_goes_through_parse_plan_and_execute(
    slow_down: type[SlowDownAction], form: str
) -> None:
    tactics = parse_tactics_yaml(YAML) if form == "yaml" else parse_tactics_xml(XML)
    action = tactics.tactic("careful").actions[0]
    assert action == SlowDownAction(speed=0.5)
    # both forms write it back from its fields, and read it back equal
    assert parse_tactics_xml(dump_tactics_xml(tactics)) == tactics
    assert parse_tactics_yaml(dump_tactics_yaml(tactics)) == tactics
    assert [ref.name for ref in tactics.referenced_endpoints()] == ["set_mode"]

    binding = load_binding(ROVER / "binding.yaml")
    model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
    actuator = TimedActuator()
    m = AutonomicManager(model, tactics, actuator=actuator, warmup=0.5)
    try:
        for i in range(20):
            t = round(i * 0.1, 6)
            m.feed("/rover/status", {"mode": "autonomous", "buzzer": False, "bumper": False})
            m.feed("/rover/camera/info", {"seq": i})
            m.feed("/rover/ultrasonic", {"range": 3.0})
            m.feed("/utu/oracle/output", {"category": 1 if t >= 1.0 else 0, "confidence": 0.9})
            m.step(t)
        assert actuator.calls[0] == ("request", "/rover/set_mode", {"mode": "slow", "speed": 0.5})
        assert actuator.timeouts == [0.75]  # the class's own timeout
        assert actuator.calls[1][0] == "notify"
        logged = [d.data for d in m.knowledge.decisions() if d.kind == "action"]
        assert logged[0]["type"] == "slow_down"
        assert {"service": "/rover/set_mode", "speed": 0.5}.items() <= logged[0].items()
        assert "payload" not in logged[0]  # its describe, not the default
        assert {"channel": "log", "subject": ""}.items() <= logged[1].items()
    finally:
        m.close()


def test_an_unregistered_type_is_an_error_that_lists_the_registered_ones(
    slow_down: type[SlowDownAction],
) -> None:
    ACTIONS.unregister("slow_down")
    with pytest.raises(ModelFileError, match="unknown action type 'slow_down'") as info:
        parse_tactics_yaml(YAML)
    assert "valid action types: publish, request, change_mode, swap_model, notify" in str(
        info.value
    )
    with pytest.raises(ModelFileError, match="<slow_down> is not allowed inside <actions>"):
        parse_tactics_xml(XML)
    ACTIONS.register(SlowDownAction)
    with pytest.raises(ModelFileError, match="swap_model, notify, slow_down"):
        parse_tactics_yaml(YAML.replace("slow_down", "slow_dawn"))


def test_an_action_field_is_checked_where_it_is_written(slow_down: type[SlowDownAction]) -> None:
    with pytest.raises(ModelFileError) as info:
        parse_tactics_yaml(YAML.replace("speed: 0.5", "speed: fast"))
    assert info.value.line == 6
    assert info.value.element == "tactics[careful].actions[0].speed"
    with pytest.raises(ModelFileError, match="<slow_down> needs the attribute 'speed'"):
        parse_tactics_xml(XML.replace(' speed="0.5"', ""))


def test_registration_refuses_doubt() -> None:
    class Untagged(TacticAction):
        def send(self) -> ServiceRequest:
            return ServiceRequest("x")

    with pytest.raises(PluginError, match='type: Literal\\["untagged"\\] = "untagged"'):
        ACTIONS.register(Untagged)

    class Listy(TacticAction):
        type: Literal["listy"] = "listy"
        names: list[str]

        def send(self) -> ServiceRequest:
            return ServiceRequest("x")

    with pytest.raises(PluginError, match=r"Listy\.names: an action's fields other than"):
        ACTIONS.register(Listy)

    class Publish(TacticAction):
        type: Literal["publish"] = "publish"

        def send(self) -> ServiceRequest:
            return ServiceRequest("x")

    with pytest.raises(PluginError, match="already registered as 'publish'"):
        ACTIONS.register(Publish)

    class Silent(TacticAction):
        type: Literal["silent"] = "silent"

    with pytest.raises(PluginError, match="Silent is abstract; implement send"):
        ACTIONS.register(Silent)
