"""``anunnaki reload`` against a running Utu over zenoh: applied, refused with the error."""

from __future__ import annotations

import importlib.util
import os
import shutil
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from anunnaki.bus import BusConfig, TlsConfig, open_bus
from anunnaki.cli.main import main
from anunnaki.tokens import OPERATOR_TOKEN_ENV, default_token_file
from anunnaki.utu import AutonomicManager, RecordingActuator, parse_config

ROVER = Path(__file__).parents[2] / "examples" / "rover"
ANUNNAKI = [sys.executable, "-m", "anunnaki.cli.main"]


@pytest.fixture
def running(tmp_path: Path) -> Iterator[tuple[str, AutonomicManager]]:
    pytest.importorskip("zenoh")
    cfg = parse_config(
        f"anunnaki: utu/1\nname: rover\ngoal_model: {ROVER}/goals.yaml\n"
        f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.yaml\nfailsafe: fail-safe\n"
        f"reload_dirs: [{tmp_path}]\n"
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


def test_reload_with_another_token_is_refused_and_says_where_its_token_came_from(
    running: tuple[str, Any],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    endpoint, m = running  # started with the user's own token (none was given)
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, "Not-the-running-Utus-token-42")
    assert main(["reload", "--connect", endpoint, "--tactics", str(ROVER / "tactics.yaml")]) == 1
    out, err = capsys.readouterr()
    assert out.startswith("refused: unauthorised: reload needs the operator token")
    assert f"else from the user's {default_token_file()}" in out  # both places clients read
    assert f"hint: this command sent the token in ${OPERATOR_TOKEN_ENV}" in err
    assert not any(d.kind.startswith("reload") for d in m.knowledge.decisions())


def test_reload_says_when_no_utu_answers(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("zenoh")
    with open_bus("zenoh") as bus:  # a bus with no Utu on it
        code = main(
            ["reload", "--connect", bus.endpoints[0], "--tactics", "x.yaml", "--timeout", "0.5"]
        )
    assert code == 2
    assert "no running Utu answered" in capsys.readouterr().err


def test_reload_over_tls_takes_the_operators_certificate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before: ``--connect tls/…`` ended in a pydantic traceback (no certificate options)."""
    pytest.importorskip("zenoh")
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make test certificates")
    helpers = sys.modules.get("bus_helpers")
    if helpers is None:  # the bus tests' PKI (tests/bus/bus_helpers.py), loaded once
        spec = importlib.util.spec_from_file_location(
            "bus_helpers", Path(__file__).parents[1] / "bus" / "bus_helpers.py"
        )
        assert spec is not None and spec.loader is not None
        helpers = sys.modules["bus_helpers"] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(helpers)
    pki = tmp_path / "pki"
    pki.mkdir()
    helpers.make_ca(pki, "ca")
    for name in ("utu", "operator"):
        helpers.make_leaf(pki, name, "ca")
    endpoint = f"tls/127.0.0.1:{helpers.free_port()}"
    tactics = ["--tactics", str(ROVER / "tactics.yaml")]
    assert main(["reload", "--connect", endpoint, *tactics]) == 2
    err = capsys.readouterr().err
    assert f"{endpoint} is a TLS endpoint" in err and "--root-ca, --cert and --key" in err
    assert "Traceback" not in err and "ValidationError" not in err
    cfg = parse_config(
        f"anunnaki: utu/1\nname: rover\ngoal_model: {ROVER}/goals.yaml\n"
        f"binding: {ROVER}/binding.yaml\ntactics: {ROVER}/tactics.yaml\nfailsafe: fail-safe\n"
    )
    tls = {
        "root_ca": str(pki / "ca.pem"),
        "cert": str(pki / "utu.pem"),
        "key": str(pki / "utu.key"),
    }
    with open_bus(BusConfig(kind="zenoh", listen=[endpoint], tls=TlsConfig(**tls))) as bus:
        m = AutonomicManager.from_config(cfg, bus=bus, actuator=RecordingActuator())
        stop = threading.Event()
        spinner = threading.Thread(target=m.spin, args=(stop,), daemon=True)
        spinner.start()
        try:
            certs = ["--root-ca", str(pki / "ca.pem"), "--cert", str(pki / "operator.pem")]
            certs += ["--key", str(pki / "operator.key")]
            code = main(["reload", "--connect", endpoint, *certs, *tactics, "--timeout", "10"])
            assert (code, capsys.readouterr().out.strip()) == (0, f"applied: {ROVER}/tactics.yaml")
        finally:
            stop.set()
            m.wake()
            spinner.join(5.0)
            m.close()


@pytest.mark.slow
def test_reload_reaches_every_node_of_a_launch_split_into_processes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``anunnaki run --processes`` + ``anunnaki reload``: applied by all five node processes."""
    pytest.importorskip("zenoh")
    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)  # Utu makes its own, as for a user
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    text = (ROVER / "utu-processes.yaml").read_text()
    text = text.replace("tcp/127.0.0.1:7447", f"tcp/127.0.0.1:{port}")
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f": {name}", f": {ROVER}/{name}")
    launch = tmp_path / "launch.yaml"
    text = text.replace(
        "  failsafe: fail-safe\n", f"  failsafe: fail-safe\n  reload_dirs: [{tmp_path}]\n"
    )
    launch.write_text(
        text.replace("    publish_clock: true", "    publish_clock: true\n    loop: true")
    )
    db = tmp_path / "run.db"
    proc = subprocess.Popen(
        [*ANUNNAKI, "run", str(launch), "--processes", "--speed", "5", "--knowledge", str(db)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    lines: list[str] = []
    ready = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("ready: "):
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 90
        while not ready.wait(0.1) and proc.poll() is None and time.monotonic() < deadline:
            pass
        assert ready.is_set(), "".join(lines)
        # No token configured: the run says where its own is; reload (below) reads it there.
        where = default_token_file()
        assert f"operator token: {where} (written now, " in "".join(lines)
        assert stat.S_IMODE(where.stat().st_mode) == 0o600
        endpoint = f"tcp/127.0.0.1:{port}"
        good = tmp_path / "good.yaml"
        good.write_text(
            (ROVER / "tactics.yaml").read_text().replace("priority: 100", "priority: 90")
        )
        reload = [*ANUNNAKI, "reload", "--connect", endpoint]
        applied = subprocess.run(
            [*reload, "--tactics", str(good), "--timeout", "20"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert applied.returncode == 0, applied.stdout + applied.stderr + "".join(lines)
        assert applied.stdout.strip() == f"applied: {good}"
        bad = tmp_path / "bad.yaml"
        bad.write_text((ROVER / "tactics.yaml").read_text().replace("goal: G3", "goal: G33", 1))
        refused = subprocess.run(
            [*reload, "--tactics", str(bad), "--timeout", "20"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert refused.returncode == 1 and "G33" in refused.stdout, refused.stdout
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        reader.join(5.0)
        assert proc.stdout is not None
        proc.stdout.close()


def test_reload_models_registers_a_model_into_a_running_model_manager(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``anunnaki reload --models``: taken (a swap to the new model succeeds), or refused."""
    pytest.importorskip("zenoh")
    pytest.importorskip("torch")
    from anunnaki.lec import LecNode, load_registry
    from anunnaki.lec._centernet import CenterNetDetector
    from anunnaki.lec._detector import save_detector, sha256_file
    from anunnaki.topics import SWAP

    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)  # the node and the CLI: the user's
    for model_id, domain in (("uav-default", "default"), ("uav-rain", "rain")):
        det = CenterNetDetector.create(
            ("person", "car"), input_size=(64, 64), width=8, model_id=model_id, domain=domain
        )
        save_detector(det, tmp_path / f"{model_id}.safetensors")
    registry = tmp_path / "registry.yaml"
    entry = "  - file: {0}.safetensors\n    sha256: {1}\n"
    default = entry.format("uav-default", sha256_file(tmp_path / "uav-default.safetensors"))
    registry.write_text("anunnaki: models/1\nmodels:\n" + default)
    rain = entry.format("uav-rain", sha256_file(tmp_path / "uav-rain.safetensors"))
    with (
        open_bus("zenoh") as bus,
        LecNode(bus, load_registry(registry), camera="/uav/camera/image", active_period=None),
    ):
        endpoint = bus.endpoints[0]
        bad = tmp_path / "bad.yaml"
        bad.write_text("anunnaki: models/1\nmodels:\n" + rain)  # no default model
        assert main(["reload", "--connect", endpoint, "--models", str(bad)]) == 1
        out = capsys.readouterr().out
        assert out.startswith(f"refused: {bad}:2: models: no model for the domain 'default'")
        registry.write_text("anunnaki: models/1\nmodels:\n" + default + rain)
        assert main(["reload", "--connect", endpoint, "--models", "--caller", "ops"]) == 0
        assert capsys.readouterr().out.strip() == (
            f"applied: {registry}: models uav-default, uav-rain (added uav-rain; changed none; "
            "removed none); uav-default keeps running"
        )
        assert bus.request(SWAP, {"lec": "detector", "domain": "rain"}).to_body()["ok"]
        monkeypatch.setenv(OPERATOR_TOKEN_ENV, "Not-the-model-managers-token-42")
        assert main(["reload", "--connect", endpoint, "--models"]) == 1
        out, err = capsys.readouterr()
        assert out.startswith("refused: unauthorised: reload needs the operator token")
        assert f"hint: this command sent the token in ${OPERATOR_TOKEN_ENV}" in err
        assert "model manager's token" in err
        assert main(["reload", "--connect", endpoint, "--models", "--tactics", "t.yaml"]) == 2
        assert "a request of its own" in capsys.readouterr().err


def test_reload_models_says_when_no_model_manager_answers(
    capsys: pytest.CaptureFixture[str],
) -> None:
    pytest.importorskip("zenoh")
    with open_bus("zenoh") as bus:
        code = main(["reload", "--connect", bus.endpoints[0], "--models", "--timeout", "0.5"])
    assert code == 2
    assert "no model manager answered" in capsys.readouterr().err
