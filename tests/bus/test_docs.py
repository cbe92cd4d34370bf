"""docs/bus.md stays true: its quick start runs, and its deployment configuration works."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from bus_helpers import Collector, Pki, free_port

from anunnaki.bus import Bus, BusConfig, BusTimeout, open_bus
from anunnaki.messages import ModeReply, ModeRequest, RunStop

DOC = Path(__file__).resolve().parents[2] / "docs" / "bus.md"


def blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", DOC.read_text(), flags=re.DOTALL)


def test_quick_start_runs(capsys: pytest.CaptureFixture[str]) -> None:
    text = DOC.read_text()
    marker = "<!-- this block runs as a test: tests/bus/test_docs.py -->\n```python\n"
    assert marker in text
    code = text.split(marker, 1)[1].split("```", 1)[0]
    exec(compile(code, str(DOC), "exec"), {"__name__": "docs_quick_start"})
    assert "/rover/sensors" in capsys.readouterr().out


def test_every_yaml_block_is_a_valid_bus_config() -> None:
    found = blocks("yaml")
    assert len(found) >= 2
    for block in found:
        BusConfig.model_validate(yaml.safe_load(block))


def documented(name: str, pki: Pki, endpoint: str) -> dict[str, Any]:
    """The YAML block whose ``mode`` is ``name``, with the test's files and port."""
    for block in blocks("yaml"):
        data = yaml.safe_load(block)
        if data["mode"] == name:
            break
    else:
        raise AssertionError(f"no {name} config in docs/bus.md")
    if name == "router":
        data["listen"] = [endpoint]
    else:
        data["connect"] = [endpoint]
    for field in ("root_ca", "cert", "key"):
        original = Path(data["tls"][field]).name  # e.g. utu.pem, ca.pem
        data["tls"][field] = str(pki.dir / original)
    return data


@pytest.mark.slow
def test_documented_deployment_works(pki: Pki) -> None:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = open_bus(BusConfig.model_validate(documented("router", pki, endpoint)))
    utu_conf = documented("client", pki, endpoint)
    rover_conf = {**utu_conf, "name": "rover"}
    rover_conf["tls"] = {
        "root_ca": str(pki.cert("ca")),
        "cert": str(pki.cert("rover")),
        "key": str(pki.key("rover")),
    }
    utu = open_bus(BusConfig.model_validate(utu_conf))
    rover = open_bus(BusConfig.model_validate(rover_conf))
    try:
        # rover publishes its sensors; utu reads them.
        sensors = Collector()
        utu.subscribe("/rover/**", sensors)
        pub = rover.publisher("/rover/sensors")
        assert pub.wait_for_subscribers(5)
        pub.put({"mode": "autonomous"})
        assert sensors.wait(1)
        # utu calls the rover's service and stops it.
        rover.service("/rover/set_mode", lambda r: ModeReply(mode=r.mode, accepted=True))
        reply = utu.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=5)
        assert reply == ModeReply(mode="manual", accepted=True)
        stops = Collector()
        rover.subscribe("/utu/run_stop", stops)
        stop = utu.publisher("/utu/run_stop")
        assert stop.wait_for_subscribers(5)
        stop.put(RunStop(reason="test", caller="/utu"))
        assert stops.wait(1)
        # Liveliness works for both.
        liveliness = Collector()
        utu.watch_liveliness(lambda node, alive: liveliness((node, alive)))
        rover.liveliness_token("/rover")
        assert liveliness.wait(1)
        assert liveliness.samples[0] == ("/rover", True)
        # What is not allowed does not flow.
        rover.service("/utu/secret", lambda r: None)  # the router refuses the declaration
        with pytest.raises(BusTimeout):
            utu.request("/utu/secret", {}, timeout=0.5)
        forged = utu.subscribe("/utu/oracle/**")
        rover.publisher("/utu/oracle/output", priority="normal").put({"forged": True})
        pub.put({"mode": "end"})  # same priority and link: would arrive after a leaked forgery
        assert sensors.wait(2)
        assert forged.try_recv() is None
    finally:
        for bus in (rover, utu, router):
            bus.close()


def _client(pki: Pki, endpoint: str, name: str) -> Bus:
    """A client of the documented router, as ``name`` (its certificate's common name)."""
    conf = documented("client", pki, endpoint)
    conf["name"] = name
    conf["tls"] = {"root_ca": str(pki.cert("ca")), "cert": str(pki.cert(name)),
                   "key": str(pki.key(name))}  # fmt: skip
    return open_bus(BusConfig.model_validate(conf))


def _answers(bus: Bus, service: str) -> bool:
    """Whether a request to ``service`` from ``bus`` gets a reply (a denied one times out)."""
    try:
        bus.request(service, {}, timeout=0.5)
    except BusTimeout:
        return False
    return True


@pytest.mark.slow
def test_documented_rules_keep_utu_to_its_operators(pki: Pki) -> None:
    """Who may call which of Utu's services, and who may speak on its topics (issue #12)."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    buses: list[Bus] = [open_bus(BusConfig.model_validate(documented("router", pki, endpoint)))]
    try:
        utu, rover, operator, guest = (
            _client(pki, endpoint, name) for name in ("utu", "rover", "operator", "guest")
        )
        buses += [utu, rover, operator, guest]
        calls = Collector()
        for service in ("/utu/pause", "/utu/run_stop", "/utu/knowledge/query", "/utu/ready"):
            utu.service(service, lambda r, s=service: calls(s) or {"ok": True})
        # Every Utu node is CN utu: they reach each other's services (readiness, queries).
        assert _answers(utu, "/utu/ready")
        # The operator may pause and query; the rover may only ask for a run-stop (S4).
        assert _answers(operator, "/utu/pause")
        assert _answers(operator, "/utu/knowledge/query")
        assert _answers(rover, "/utu/run_stop")
        assert not _answers(rover, "/utu/pause")
        assert not _answers(guest, "/utu/run_stop")  # a certificate no rule names: nothing
        assert calls.samples == ["/utu/ready", "/utu/pause", "/utu/knowledge/query",
                                  "/utu/run_stop"]  # fmt: skip
        # The rover cannot pose as an operator service: its declaration is refused.
        rover.service("/utu/approve", lambda r: {"ok": True})
        assert not _answers(operator, "/utu/approve")
        # Utu hears the rover's sensors and the simulation clock, but no forged cycle message.
        heard = Collector()
        utu.subscribe("/clock", heard)
        utu.subscribe("/utu/analyze/state", heard)
        utu.subscribe("/utu/oracle/output", heard)
        clock = rover.publisher("/clock", priority="normal")
        assert clock.wait_for_subscribers(5)
        rover.publisher("/utu/analyze/state", priority="normal").put({"forged": True})
        rover.publisher("/utu/oracle/output", priority="normal").put({"category": 2})
        clock.put({"time": 1.0})  # same priority and link: after any leaked forgery
        assert heard.wait(1)
        assert [s.topic for s in heard.samples] == ["/clock"]
    finally:
        for bus in reversed(buses):
            bus.close()
