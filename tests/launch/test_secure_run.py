"""The secure deployment as the docs give it: a TLS router with access control (issue #12).

Everything comes from the docs, so they cannot drift from what works: the certificates are
made by running the ``openssl`` commands of docs/bus.md ("Across machines": step 1, with
its loopback ``subjectAltName`` for the router), the router is the Python program and
``router.yaml`` of step 2 (its access-control rules verbatim), and the launch's ``bus`` is
the block of docs/running.md#across-machines. Only file locations and the port change.

The rover example then runs through the router, in one process and with ``--processes``,
while a client with the rover's certificate forges Utu's cycle messages and the oracle's
output, and callers without the right certificate ask for operator services. Each run must
make the decisions of the same run without TLS and rules (a live run's, within its
tolerance in simulated time: tests/live_rover.py), and every forgery and
unauthorised call must be denied.
"""

from __future__ import annotations

import io
import re
import shutil
import subprocess
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

from anunnaki.bus import Bus, BusConfig, BusConnectError, BusTimeout, open_bus
from anunnaki.bus._zenoh import free_port as bus_free_port
from anunnaki.launch import load_launch, run_launch
from anunnaki.messages import AnalysisState, MonitorBatch
from anunnaki.topics import ready_service
from live_rover import LIVE_LAG, LIVE_SPEED, live_decisions

pytest.importorskip("zenoh")
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
BUS_DOC = ROOT / "docs" / "bus.md"
RUNNING_DOC = ROOT / "docs" / "running.md"
ROVER = ROOT / "examples" / "rover"
SPEED = LIVE_SPEED  # the trace's 50 s in 5 s: time for the forgeries while Utu runs
FORGER = "rover-forger"


# --- what the docs say ------------------------------------------------------------------------
def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start : end if end >= 0 else len(text)]


def _blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", text, flags=re.DOTALL)


def _bus_section() -> str:
    return _section(BUS_DOC.read_text(), "## Across machines")


@dataclass(frozen=True)
class CertRecipe:
    """docs/bus.md's openssl commands: the CA's, and a leaf's (written for ``utu``)."""

    ca: list[str]
    leaf: list[str]
    names: list[str]  # the leaves the docs make ("for each of router, utu, …")
    san: str  # the subjectAltName of the docs' commands
    loopback_san: str  # the one the docs give the router on one machine

    @classmethod
    def from_docs(cls) -> CertRecipe:
        section = _bus_section()
        (block,) = (b for b in _blocks(section, "text") if "openssl genpkey" in b)
        loopback = re.search(r"`(subjectAltName=[^`]*IP:127\.0\.0\.1[^`]*)`", section)
        assert loopback, "docs/bus.md no longer says which SAN the router needs on loopback"
        lines = [ln for ln in block.replace("\\\n", " ").splitlines() if ln.strip()]
        (each,) = (ln for ln in lines if ln.startswith("# for each of"))
        listed = re.match(r"# for each of ([\w, ]+) \(", each)
        assert listed, each
        leaf = lines[lines.index(each) + 1 :]
        san = next(m.group(0) for c in leaf if (m := re.search(r"subjectAltName=[^\\']*", c)))
        return cls(
            ca=lines[: lines.index(each)],
            leaf=leaf,
            names=[n.strip() for n in listed.group(1).split(",")],
            san=san,
            loopback_san=loopback.group(1),
        )

    def make_ca(self, d: Path) -> None:
        for cmd in self.ca:
            _sh(cmd, d)

    def make_leaf(self, d: Path, name: str, *, san: str | None = None) -> None:
        """The docs' leaf commands for ``name`` (CN and files), with ``san`` if given."""
        for cmd in self.leaf:
            _sh(re.sub(r"\butu\b", name, cmd).replace(self.san, san or self.san), d)


def _sh(command: str, cwd: Path) -> None:
    subprocess.run(
        command, shell=True, executable="/bin/bash", cwd=cwd, check=True, capture_output=True,
        timeout=60,
    )  # fmt: skip


def router_config(pki: Path, endpoint: str) -> BusConfig:
    """docs/bus.md's ``router.yaml``, listening on ``endpoint``, with the files in ``pki``."""
    (data,) = (
        d for d in map(yaml.safe_load, _blocks(_bus_section(), "yaml")) if d["mode"] == "router"
    )
    data["listen"] = [endpoint]
    data["tls"] = {k: str(pki / Path(v).name) for k, v in data["tls"].items()}
    return BusConfig.model_validate(data)


def launch_bus(pki: Path, endpoint: str, cert: str = "utu") -> dict[str, Any]:
    """docs/running.md's launch ``bus`` section, connecting to ``endpoint`` as ``cert``."""
    section = _section(RUNNING_DOC.read_text(), "## Across machines")
    (data,) = (d for d in map(yaml.safe_load, _blocks(section, "yaml")) if "bus" in d)
    bus: dict[str, Any] = data["bus"]
    bus["connect"] = [endpoint]
    bus["tls"] = {k: str(pki / Path(v).name.replace("utu", cert)) for k, v in bus["tls"].items()}
    return bus


def launch_file(tmp: Path, bus: dict[str, Any] | None) -> Path:
    """The rover example (examples/rover/utu.yaml) with ``bus`` instead of its own."""
    text = (ROVER / "utu.yaml").read_text()
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f" {name}", f" {ROVER / name}")
    if bus is not None:
        assert "\nbus: {kind: inproc}" in text
        text = text.replace(
            "\nbus: {kind: inproc}",
            "\nbus: " + yaml.safe_dump(bus, default_flow_style=True, width=1000).strip(),
        )
    path = tmp / ("secure.yaml" if bus else "plain.yaml")
    path.write_text(text)
    return path


# --- the deployment --------------------------------------------------------------------------
@dataclass
class Secure:
    """The documented router on a loopback port, and clients by certificate name."""

    pki: Path
    endpoint: str
    buses: list[Bus] = field(default_factory=list)

    def client(self, cert: str, name: str | None = None) -> Bus:
        conf = launch_bus(self.pki, self.endpoint, cert)
        bus = open_bus(BusConfig.model_validate({**conf, "name": name or cert}))
        self.buses.append(bus)
        return bus


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make the certificates")
    d = tmp_path_factory.mktemp("pki")
    recipe = CertRecipe.from_docs()
    assert {"router", "utu", "rover", "operator"} <= set(recipe.names)
    recipe.make_ca(d)
    for name in [*recipe.names, "guest"]:  # guest: a certificate that no rule names
        recipe.make_leaf(d, name, san=recipe.loopback_san if name == "router" else None)
    return d


@pytest.fixture
def secure(pki: Path) -> Iterator[Secure]:
    endpoint = f"tls/127.0.0.1:{bus_free_port()}"
    with open_bus(router_config(pki, endpoint)):
        s = Secure(pki, endpoint)
        try:
            yield s
        finally:
            for bus in reversed(s.buses):
                bus.close()


@pytest.fixture(scope="module")
def plain_decisions(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[float, str, str]]:
    """The decisions of the rover example without router, TLS or rules (in-process bus)."""
    path = launch_file(tmp_path_factory.mktemp("plain"), None)
    # Sim time on the run's executor: the decisions and their times do not depend on the speed.
    result = run_launch(load_launch(path), speed=50.0, out=io.StringIO(), handle_signals=False)
    assert result.exit_code == 0, result.reason
    return [(d.t, d.kind, d.tactic or "") for d in result.decisions]


# --- the attack ------------------------------------------------------------------------------
@dataclass
class Attack:
    """What was tried against a running Utu, and what came of it."""

    forged_seen: list[str] = field(default_factory=list)  # forgeries that reached Utu's side
    marker: threading.Event = field(default_factory=threading.Event)
    answered: dict[str, bool] = field(default_factory=dict)  # caller service -> got a reply
    error: str = ""


def _answered(bus: Bus, service: str, body: dict[str, Any], timeout: float = 0.5) -> bool:
    try:
        reply = bus.request(service, body, timeout=timeout)
    except BusTimeout:
        return False
    return reply is not None


def attack(s: Secure, launch: Bus, out: Attack) -> None:
    """Once Utu is ready: forge, then call operator services as the wrong callers."""
    try:

        def heard(sample: Any) -> None:
            if sample.topic == "/rover/attack_done":
                out.marker.set()
            elif sample.sender == FORGER:
                out.forged_seen.append(sample.topic)

        # Utu's side of the router (the launch's session, CN utu) listens as Utu does.
        for topic in ("/utu/analyze/state", "/utu/monitor/input", "/utu/oracle/output"):
            launch.subscribe(topic, heard)
        launch.subscribe("/rover/attack_done", heard)
        # The nodes the attack meets (with --processes each starts on its own: execute may be
        # ready while knowledge, whose query the operator asks, is still coming up).
        for node in ("execute", "knowledge"):
            for _ in range(600):  # bounded: ready within 30 s
                if _answered(launch, ready_service(node), {}):
                    break
        forger = s.client("rover", FORGER)
        stop_op = [{"op": "run_stop", "caller": "forger", "reason": "forged"}]
        forged = [
            ("/utu/analyze/state", AnalysisState(t=1.0, origin="forged", seq=10**9, ops=stop_op)),
            ("/utu/monitor/input", MonitorBatch(origin="forged", seq=1, t=1.0, ops=stop_op)),
            ("/utu/oracle/output", {"category": 2, "confidence": 1.0}),  # no rule lets it
        ]
        done = forger.publisher("/rover/attack_done", priority="normal")
        done.wait_for_subscribers(5)
        for topic, message in forged:
            forger.publisher(topic, priority="normal").put(message)
        done.put({"sent": len(forged)})  # same link and priority: after any leaked forgery
        operator, guest = s.client("operator"), s.client("guest")
        out.answered = {
            "rover /utu/pause": _answered(forger, "/utu/pause", {}),
            "guest /utu/resume": _answered(guest, "/utu/resume", {}),
            "guest /utu/run_stop": _answered(guest, "/utu/run_stop", {"reason": "x"}),
            # An allowed call returns as its answer comes; the answer needs the router, the
            # knowledge node's process and this one (whose GIL the router and the launch
            # share) to run in turn, which can take longer than 0.5 s on a loaded machine.
            "operator /utu/knowledge/query": _answered(
                operator, "/utu/knowledge/query", {"what": "state"}, timeout=10.0
            ),
        }
    except Exception as exc:  # reported by the test, with its cause
        out.error = f"{type(exc).__name__}: {exc}"


@pytest.mark.parametrize("processes", [False, True], ids=["one-process", "processes"])
def test_documented_secure_run_decides_as_a_plain_one_and_denies_forgeries(
    secure: Secure,
    tmp_path: Path,
    plain_decisions: list[tuple[float, str, str]],
    processes: bool,
) -> None:
    path = launch_file(tmp_path, launch_bus(secure.pki, secure.endpoint))
    attacked = Attack()
    threads: list[threading.Thread] = []

    def on_bus(bus: Bus) -> None:
        t = threading.Thread(target=attack, args=(secure, bus, attacked), daemon=True)
        t.start()
        threads.append(t)

    out = io.StringIO()
    result = run_launch(
        load_launch(path),
        processes=processes,
        speed=SPEED,
        knowledge=str(tmp_path / "kb.db"),
        out=out,
        err=out,
        handle_signals=False,
        on_bus=on_bus,
    )
    for t in threads:
        t.join(timeout=30)
    log = out.getvalue()
    assert result.exit_code == 0, f"{result.reason}\n{log}"
    assert not attacked.error, attacked.error
    decisions = [(d.t, d.kind, d.tactic or "") for d in live_decisions(result.decisions)]
    # A live run (tests/live_rover.py): the same decisions in the same order, none
    # more than LIVE_LAG simulated seconds after the plain run's (the fail-safe may come
    # sooner: G6's slack at 4.8 Hz).
    assert [d[1:] for d in decisions] == [d[1:] for d in plain_decisions], log
    for (t, _, _), (t_plain, _, _) in zip(decisions, plain_decisions, strict=True):
        assert t <= t_plain + LIVE_LAG, log
    assert attacked.marker.is_set(), "the forger's last (allowed) message never arrived"
    assert attacked.forged_seen == []
    assert attacked.answered == {
        "rover /utu/pause": False,
        "guest /utu/resume": False,
        "guest /utu/run_stop": False,
        "operator /utu/knowledge/query": True,
    }


def test_the_documented_router_certificate_is_needed_on_loopback(pki: Path) -> None:
    """With the docs' own SAN (router.lab, 10.0.0.1) a loopback client is told what to add."""
    d = pki / "no-loopback"
    d.mkdir(exist_ok=True)
    for name in ("ca.pem", "ca.key", "utu.pem", "utu.key"):
        shutil.copy(pki / name, d / name)
    CertRecipe.from_docs().make_leaf(d, "router")
    endpoint = f"tls/127.0.0.1:{bus_free_port()}"
    with (
        open_bus(router_config(d, endpoint)),
        pytest.raises(BusConnectError, match=r"subjectAltName=IP:127\.0\.0\.1"),
    ):
        open_bus(BusConfig.model_validate(launch_bus(d, endpoint)))
