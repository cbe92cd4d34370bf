"""``anunnaki run --manager none|random`` and ``--mail-sink`` on the scripted rover (utu.yaml).

At t = 25 s of the trace the oracle reports category 1 and Utu starts the fail-safe (manual
mode, an e-mail to the operator); test_launch.py tells that story with Utu. Here the same
trace runs with the baselines, and with a local SMTP sink that receives the fail-safe's mail.
"""

from __future__ import annotations

import io
import socket
from pathlib import Path

import pytest

from anunnaki.cli.main import main
from anunnaki.launch import LaunchError, MailSink, RunResult, load_launch, run_launch

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover"
EXAMPLE = ROVER / "utu.yaml"


def run(launch_path: Path, **kw) -> RunResult:  # type: ignore[no-untyped-def]
    return run_launch(load_launch(launch_path), out=io.StringIO(), handle_signals=False, **kw)


def run_printed(launch_path: Path, **kw) -> tuple[RunResult, str]:  # type: ignore[no-untyped-def]
    out = io.StringIO()
    result = run_launch(load_launch(launch_path), out=out, handle_signals=False, **kw)
    return result, out.getvalue()


def decision_kinds(printed: str) -> set[str]:
    """The kinds of the decision lines printed (``   25.000  started   fail-safe …``)."""
    kinds = set()
    for line in printed.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0].replace(".", "", 1).isdigit():
            kinds.add(words[1])
    return kinds


def started(result: RunResult) -> list[tuple[float, str | None]]:
    return [(d.t, d.tactic) for d in result.decisions if d.kind == "started"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_none_runs_the_trace_without_adapting() -> None:
    """It prints what it did, nothing adapted, and none of Utu's choices (issue 34, item 6)."""
    result, printed = run_printed(EXAMPLE, speed=50, manager="none")
    assert result.exit_code == 0 and result.reason == "trace ended"
    assert started(result) == []
    assert "manager: none, the baseline without adaptation" in printed
    assert "manager none: nothing adapted (no tactic started)" in printed
    assert decision_kinds(printed) == set(), printed  # no "selected fail-safe", no "deferred"
    # with Utu the same trace selects and starts the fail-safe, and says so
    _, said = run_printed(EXAMPLE, speed=50)
    assert {"selected", "started"} <= decision_kinds(said) and "manager: " not in said


def test_random_draws_where_utu_decides() -> None:
    utu = run(EXAMPLE, speed=50)
    rnd, printed = run_printed(EXAMPLE, speed=50, manager="random", manager_seed=2)
    draws = [d for d in rnd.decisions if d.kind == "random_draw"]
    assert draws, rnd.decisions
    first_utu = started(utu)[0][0]
    assert draws[0].t == pytest.approx(first_utu)  # the same instant, a drawn tactic
    assert [tac for _, tac in started(rnd)][: len(draws)] == [d.tactic for d in draws]
    # what it printed: its draws and what they did, never the planner's own choices
    kinds = decision_kinds(printed)
    assert {"random_draw", "started"} <= kinds and not kinds & {"selected", "deferred"}, printed
    assert "manager: random (seed 2)" in printed
    assert f"manager random: started {draws[0].tactic} at " in printed


def test_a_manager_override_needs_one_process() -> None:
    with pytest.raises(LaunchError, match="--manager and --manager-seed apply in one process"):
        run_launch(
            load_launch(EXAMPLE),
            processes=True,
            manager="none",
            out=io.StringIO(),
            handle_signals=False,
        )
    with pytest.raises(LaunchError, match="unknown manager 'best'"):
        run(EXAMPLE, manager="best")


def test_the_mail_sink_receives_and_prints_the_fail_safes_mail(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port = free_port()
    text = EXAMPLE.read_text()
    for name in ("goals.yaml", "binding.yaml", "tactics.yaml", "trace.jsonl"):
        text = text.replace(f": {name}", f": {ROVER / name}")
    text = text.replace(
        "  run_stop: {service: /rover/stop}\n",
        "  run_stop: {service: /rover/stop}\n"
        f"  notify: {{smtp: {{host: 127.0.0.1, port: {port}, from_addr: utu@rover.example}}}}\n",
    )
    launch = tmp_path / "launch.yaml"
    launch.write_text(text)
    assert (
        main(["run", str(launch), "--speed", "50", "--until", "27", "--mail-sink", str(port)]) == 0
    )
    out = capsys.readouterr().out
    assert f"mail sink: SMTP on 127.0.0.1:{port}" in out
    assert "mail sink: 1 message(s) received" in out
    assert "To: operator@example.com" in out and "Subject: Rover switched to manual" in out
    assert "the rover is now in manual mode" in out


def test_a_sink_on_a_busy_port_says_so() -> None:
    with (
        MailSink(free_port()) as sink,
        pytest.raises(Exception, match="cannot start the mail sink"),
    ):
        MailSink(sink.port)
