"""``anunnaki reload`` against a running Utu over zenoh: applied, refused with the error."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import open_bus
from anunnaki.cli.main import main
from anunnaki.utu import AutonomicManager, RecordingActuator, parse_config

ROVER = Path(__file__).parents[2] / "examples" / "rover"


@pytest.fixture
def running(tmp_path: Path) -> Iterator[tuple[str, AutonomicManager]]:
    pytest.importorskip("zenoh")
    cfg = parse_config(
        f"anunnaki: utu/1\nname: rover\ngoal_model: {ROVER}/goals.yaml\n"
        f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.yaml\nfailsafe: fail-safe\n"
    )
    with open_bus("zenoh") as bus:  # a peer on a free loopback port
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=RecordingActuator())
        stop = threading.Event()
        spinner = threading.Thread(target=m.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            yield bus.endpoints[0], m
        finally:
            stop.set()
            m.wake()
            spinner.join(5.0)
            m.close()


def test_reload_is_applied_or_refused_with_the_error(
    running: tuple[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    endpoint, m = running
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROVER / "tactics.yaml").read_text().replace("goal: G3", "goal: G33", 1))
    assert main(["reload", "--connect", endpoint, "--tactics", str(bad)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("refused: ") and f"{bad}:" in out and "G33" in out
    good = tmp_path / "good.yaml"
    good.write_text((ROVER / "tactics.yaml").read_text().replace("priority: 100", "priority: 90"))
    assert main(["reload", "--connect", endpoint, "--tactics", str(good), "--caller", "ops"]) == 0
    assert capsys.readouterr().out.strip() == f"applied: {good}"
    assert m.knowledge.models_at()["tactics"][0] == str(good)
    assert main(["reload", "--connect", endpoint]) == 2  # nothing to reload


def test_reload_says_when_no_utu_answers(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("zenoh")
    with open_bus("zenoh") as bus:  # a bus with no Utu on it
        code = main(
            ["reload", "--connect", bus.endpoints[0], "--tactics", "x.yaml", "--timeout", "0.5"]
        )
    assert code == 2
    assert "no running Utu answered" in capsys.readouterr().err
