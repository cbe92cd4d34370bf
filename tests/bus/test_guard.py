"""The liveliness guard: a platform stops by itself when Utu is gone (issue #12)."""

from __future__ import annotations

from pathlib import Path

import pytest
from bus_helpers import wait_for

from anunnaki.bus import InprocHub, LivelinessGuard, open_bus
from anunnaki.managed import ScriptedSystem

ROVER = Path(__file__).parents[2] / "examples" / "rover"


def test_a_scripted_rover_stops_by_itself_when_a_utu_node_is_gone() -> None:
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as robot, open_bus("inproc", hub=hub) as utu:
        rover = ScriptedSystem(robot, ROVER / "trace.jsonl", stop_without_utu=0.2)
        try:
            execute = utu.liveliness_token("/utu_execute")
            monitor = utu.liveliness_token("/utu_monitor")
            guard = next(d for d in rover._declared if isinstance(d, LivelinessGuard))
            assert wait_for(lambda: guard._seen == {"/utu_execute", "/utu_monitor"})
            assert not rover.state().get("stopped")
            execute.close()  # as kill -9 of the execute node withdraws it
            assert wait_for(lambda: rover.state().get("stopped") is True)
            (stop,) = [c for c in rover.commands if c[1] == "stop"]
            assert stop[2]["reason"].startswith("Utu lost: /utu_execute gone")
            monitor.close()
        finally:
            rover.close()


def test_a_node_back_within_the_timeout_cancels_the_stop() -> None:
    hub = InprocHub()
    with open_bus("inproc", hub=hub) as robot, open_bus("inproc", hub=hub) as utu:
        lost: list[str] = []
        guard = LivelinessGuard(robot, lost.append, timeout=30.0)
        try:
            token = utu.liveliness_token("/utu_analyze")
            assert wait_for(lambda: "/utu_analyze" in guard._seen)
            token.close()
            assert wait_for(lambda: guard._timer is not None)  # counting down
            token = utu.liveliness_token("/utu_analyze")  # restarted in time
            assert wait_for(lambda: guard._timer is None and not guard._gone)
            other = utu.liveliness_token("/oracle_ground_truth")  # not Utu: not watched
            other.close()
            assert lost == [] and guard.fired is None
            token.close()
        finally:
            guard.close()
    with pytest.raises(ValueError, match="timeout"):
        LivelinessGuard(robot, lost.append, timeout=0)
