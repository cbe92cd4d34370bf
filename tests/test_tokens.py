"""Utu's operator services are never open by accident (issue 21, item 7).

Before: a Utu given no operator token let anyone on the bus clear a run-stop with
``/utu/resume``, approve a tactic or reload its files.
"""

from __future__ import annotations

import stat
import threading
from pathlib import Path

import pytest

from anunnaki.bus import open_bus
from anunnaki.errors import ModelFileError
from anunnaki.goals import load_binding, parse_goal_model
from anunnaki.tactics import load_tactics
from anunnaki.tokens import (
    OPERATOR_TOKEN_ENV,
    client_operator_token,
    default_token_file,
    service_operator_token,
    token_weakness,
    user_operator_token,
)
from anunnaki.utu import AutonomicManager, RecordingActuator

ROVER = Path(__file__).parents[1] / "examples" / "rover"


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """No token given: neither the variable nor a file in the configuration."""
    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    return tmp_path / "config" / "anunnaki" / "operator-token"


def test_a_utu_given_no_token_makes_one_only_the_user_can_read_and_refuses_anonymous_callers(
    home: Path,
) -> None:
    binding = load_binding(ROVER / "binding.yaml")
    model = parse_goal_model((ROVER / "goals.yaml").read_text(), binding=binding)
    with open_bus("inproc") as bus:
        manager = AutonomicManager(
            model, load_tactics(ROVER / "tactics.xml"), bus=bus, actuator=RecordingActuator()
        )
        try:
            assert default_token_file() == home
            assert stat.S_IMODE(home.stat().st_mode) == 0o600
            token = home.read_text().strip()
            assert token_weakness(token) is None
            assert bus.request("/utu/run_stop", {"caller": "anyone"}).to_body()["ok"]  # S4
            for service in ("/utu/resume", "/utu/pause", "/utu/reload"):
                reply = bus.request(service, {"caller": "anyone"}).to_body()
                assert (reply["ok"], reply["status"]) == (False, "unauthorised"), service
            manager.step(1.0)
            assert manager.run_stopped  # the anonymous resume did not clear it
            assert client_operator_token() == token  # what reload and the dashboard send
            reply = bus.request("/utu/resume", {"caller": "op", "token": token}).to_body()
            assert reply["ok"] is True
            manager.step(2.0)
            assert not manager.run_stopped
        finally:
            manager.close()


def test_processes_starting_at_once_end_with_one_token(home: Path) -> None:
    tokens: list[str] = []
    start = threading.Barrier(8)

    def racer() -> None:
        start.wait()
        tokens.append(user_operator_token()[0])

    threads = [threading.Thread(target=racer) for _ in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(tokens) == 8 and len(set(tokens)) == 1
    assert user_operator_token() == (tokens[0], home, False)  # kept, not made again
    assert [p.name for p in home.parent.iterdir()] == ["operator-token"]  # no leftovers


def test_the_variable_wins_and_a_file_open_to_others_is_refused(
    home: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert client_operator_token() is None  # no Utu has started here yet
    user_operator_token()
    home.chmod(0o644)
    with pytest.raises(ModelFileError, match=r"open to others \(mode 0644\)") as err:
        client_operator_token()
    assert f"chmod 600 {home}" in str(err.value)
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, "Explicit-token-wins-0123456789")
    assert client_operator_token() == "Explicit-token-wins-0123456789"


def test_a_token_that_cannot_be_written_is_an_error_naming_the_file_and_the_fix(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)
    (tmp_path / "config").write_text("a file where a folder should be\n")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    with pytest.raises(ModelFileError, match="cannot write the operator token") as err:
        user_operator_token()
    assert str(default_token_file()) in str(err.value) and OPERATOR_TOKEN_ENV in str(err.value)


def test_every_service_finds_its_token_one_way_given_then_variable_then_file_then_user(
    home: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    strong = "k" * 10 + "Q9x-Tz_4bW7yLm2Np8Rv5Hs3"
    file = tmp_path / "token"
    file.write_text("F" + strong + "\n", encoding="utf-8")
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, "E" + strong)
    assert service_operator_token("utu", given="G" + strong, file=file) == "G" + strong
    assert service_operator_token("utu", file=file) == "E" + strong
    monkeypatch.delenv(OPERATOR_TOKEN_ENV)
    assert service_operator_token("utu", file=file) == "F" + strong
    assert not default_token_file().exists()  # a token was found: no user file written
    made = service_operator_token("the model manager")
    assert default_token_file().read_text(encoding="utf-8").strip() == made
    assert service_operator_token("utu") == made  # both services share the user's token


def test_a_weak_token_is_refused_naming_the_service_and_where_it_came_from(
    home: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    file = tmp_path / "token"
    file.write_text("secret\n", encoding="utf-8")
    with pytest.raises(ModelFileError, match=r"of utu is too weak") as raised:
        service_operator_token("utu", file=file)
    assert raised.value.path == str(file)
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, "secret")
    with pytest.raises(ModelFileError, match=r"model manager is too weak") as raised:
        service_operator_token("the model manager")
    assert raised.value.element == f"${OPERATOR_TOKEN_ENV}"
