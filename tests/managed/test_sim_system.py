"""The whole loop's managed system: simulated rover + real detector + ground-truth oracle.

The detector is the committed rover default model (examples/models), so these tests run the
real CenterNet on rendered frames. What they assert does not depend on how good the model is:
one thread of delivery (every frame gets its detections before the next, and a run repeats
itself), scoring against ground truth
per scenario phase, a heavy fog lowering the F1, the launch file's ``managed: sim`` section,
and the hand-over when a swapped-in model does not help.
"""

from __future__ import annotations

import io
import threading
from pathlib import Path
from typing import Any

import pytest
from managed_helpers import fog_scene

from anunnaki import topics
from anunnaki.errors import ModelFileError
from anunnaki.launch import parse_launch, run_launch
from anunnaki.lec import load_registry, sha256_file
from anunnaki.managed import SimulatedSystem, format_phases, scenario_phases
from anunnaki.messages import Detections
from anunnaki.sim import load_report, load_scenario

ROOT = Path(__file__).parents[2]
ROVER = ROOT / "examples" / "rover"
MODEL = ROOT / "examples" / "models" / "rover-default.safetensors"

#: 16 s, no background clutter: a pedestrian crosses 4-5 m ahead and a deer stands in view;
#: a dense fog from t = 5 s.
SCENARIO = fog_scene("fog-test", duration=16, fog_at=5)


def test_phases_split_at_phenomena() -> None:
    sc = load_scenario(ROVER / "demo-scenario.yaml")
    assert scenario_phases(sc) == [(0, 8), (8, 10), (10, 20), (20, 30), (30, 32), (32, 42)]
    assert scenario_phases(sc, 9.0) == [(0, 8), (8, 9)]


def test_every_frame_is_detected_and_fog_lowers_f1(bus: Any, tmp_path: Path) -> None:
    seen: list[int] = []
    bus.subscribe(
        "/lec/detector/detections",
        lambda s: seen.append(s.message.frame_seq) if isinstance(s.message, Detections) else None,
        queue=512,
    )
    with SimulatedSystem(
        bus,
        SCENARIO,
        models=load_registry(write_registry(tmp_path / "m.yaml")),
        oracle={"window": 10},
    ) as system:
        system.run(threading.Event(), speed=1000.0)
        frames = system.platform.frames
        phases = system.phases()
        assert system.oracle is not None and system.oracle.stats().assessments > 0
    assert frames == 160
    assert sorted(seen) == list(range(frames))  # exactly one detection message per frame
    clear, fog = phases
    assert (clear.label, fog.label) == ("clear", "fog")
    assert clear.frames + fog.frames == frames  # every frame scored against its truth
    assert clear.f1 is not None and fog.f1 is not None
    assert clear.tp > 0 and fog.f1 < clear.f1
    assert fog.categories[2] > 0 and clear.categories[2] == 0  # compromised: only in fog
    assert clear.models == fog.models == ["rover-default"]
    table = format_phases(phases)
    assert "0.0–  5.0 s" in table and "fog" in table and f"{clear.f1:.2f}" in table


def test_a_paired_scorer_gets_the_clean_renders_of_the_frames(bus: Any, tmp_path: Path) -> None:
    """A scorer with ``reference: paired`` switches the platform's clean frames on and
    scores the model on both: no drop before the fog (the frames are their clean renders),
    compromised in it (the model finds the pedestrian and the deer only in the renders)."""
    registry = load_registry(write_registry(tmp_path / "m.yaml"))
    scorer = {"window": 10, "min_frames": 5, "reference": "paired", "sparse": "withhold"}
    categories: list[tuple[int, int]] = []
    bus.subscribe(
        topics.SCORER,
        lambda s: categories.append((s.message.frame_seq, s.message.category)),
        queue=512,
    )
    with SimulatedSystem(
        bus, fog_scene("paired", duration=8, fog_at=4), models=registry, scorer=scorer
    ) as system:
        assert system.platform.publish_clean
        system.run(threading.Event(), speed=1000.0)
        window = system.scorer.oracle.metrics()
    assert window is not None and window.clean_f1 is not None and window.clean_f1 > window.f1
    by_frame = dict(categories)
    assert [by_frame[s] for s in range(20, 40) if s in by_frame] == [0] * 20  # no phenomenon
    assert all(by_frame[s] == 2 for s in range(60, 80) if s in by_frame)  # 2 s into the fog
    assert sum(1 for s in range(60, 80) if s in by_frame) >= 10
    with SimulatedSystem(
        bus, fog_scene("plain", duration=1, fog_at=4), models=registry, scorer={"window": 10}
    ) as plain:
        assert not plain.platform.publish_clean  # nobody asked for the renders


def test_each_instant_is_delivered_before_the_clock_moves_on(bus: Any) -> None:
    """On the executor every message of an instant reaches its subscribers, on the
    simulation's thread, before ``on_time`` moves the clock past that instant."""
    events: list[tuple[str, float, str]] = []

    def heard(sample: Any) -> None:
        events.append(("delivered", sample.message.time, threading.current_thread().name))

    bus.subscribe(topics.CLOCK, heard, queue=4)
    system = SimulatedSystem(
        bus, fog_scene("instants", duration=1, fog_at=5), oracle=None,
        on_time=lambda t: events.append(("clock", t, threading.current_thread().name)),
    )  # fmt: skip
    with system:
        runner = threading.Thread(target=system.run, args=(threading.Event(),), name="sim")
        runner.start()
        runner.join(60)
    delivered = [t for what, t, _ in events if what == "delivered"]
    assert len(delivered) == 40 and delivered == sorted(delivered)  # /clock at 40 Hz, 0–0.975
    assert {thread for *_, thread in events} == {"sim"}  # one thread of delivery
    moved = -1.0
    for what, t, _ in events:
        if what == "clock":
            moved = max(moved, t)
        else:  # delivered before the clock moved past its instant
            assert t >= moved - 1e-9
    assert bus.executor.pending == 0


def test_the_same_scenario_runs_the_same_twice(tmp_path: Path) -> None:
    """Two runs of one scenario give the same frames, detections and assessments."""
    from anunnaki.bus import Executor, open_bus

    registry = load_registry(write_registry(tmp_path / "m.yaml"))
    reports = []
    for _ in range(2):
        with (
            open_bus("inproc", executor=Executor()) as b,
            SimulatedSystem(
                b, fog_scene("twice", duration=2, fog_at=1), models=registry,
                oracle={"window": 5}, scorer={"window": 5},
            ) as system,
        ):  # fmt: skip
            system.run(threading.Event(), speed=0)
            reports.append(system.report().as_dict())
    assert reports[0]["frames"] and reports[0]["assessments"]
    assert reports[0] == reports[1]


LAUNCH = """
anunnaki: launch/1
name: sim-test
utu:
  goal_model: ROVER/goals-lm.yaml
  binding: ROVER/binding-lm.yaml
  tactics: ROVER/tactics-lm.yaml
  knowledge: ":memory:"
  clock: sim
  warmup: 2.0     # the ground truth's first verdict needs min_frames (10 frames, 1 s)
  failsafe: fail-safe
  run_stop: {service: /rover/stop}
bus: {kind: inproc}
managed:
  sim:
    scenario: SCENARIO
    models: MODELS
    oracle: {name: ground_truth, window: 20, min_frames: 10, min_objects: 10}
    speed: 1000
"""


def write_registry(path: Path, *domains: str) -> Path:
    """The default model, also registered under each domain: a 'robust' model no better."""
    import shutil

    for part in (MODEL, MODEL.with_suffix(".json")):  # a registry's models sit in its folder
        shutil.copy(part, path.parent / part.name)
    digest = sha256_file(MODEL)
    lines = ["anunnaki: models/1", "lec: detector", "models:"]
    for domain in ("default", *domains):
        lines.append(
            f"  - {{id: rover-{domain}, domain: {domain}, file: {MODEL.name}, sha256: {digest}}}"
        )
    path.write_text("\n".join(lines) + "\n")
    return path


def launch_text(tmp_path: Path, scenario: dict[str, Any], models: Path) -> str:
    import yaml

    sc = tmp_path / "scenario.yaml"
    sc.write_text(yaml.safe_dump({"anunnaki": "scenario/1", **scenario}))
    return (
        LAUNCH.replace("ROVER", str(ROVER))
        .replace("SCENARIO", str(sc))
        .replace("MODELS", str(models))
    )


def test_a_swap_that_does_not_help_hands_the_rover_over_once(tmp_path: Path) -> None:
    """Fog → swap to the 'fog' model (the same weights) → its own verdict: degraded too.

    No model is left to try: ``fail-safe-robust-model-degraded`` hands the rover over as
    soon as the oracle's verdict is about the 'fog' model (the ground truth's first one comes
    a second of frames after the swap), before the swap's deadline; the swap's failure then
    escalates to nothing, since the fail-safe's goal G3 already holds.
    """
    text = launch_text(tmp_path, SCENARIO, write_registry(tmp_path / "models.yaml", "fog"))
    out = io.StringIO()
    result = run_launch(parse_launch(text), out=out, handle_signals=False)
    log = out.getvalue()
    assert result.exit_code == 0, log
    kinds = [(d.kind, d.tactic) for d in result.decisions]
    assert ("started", "swap-to-fog-model") in kinds, log
    swap = next(
        d for d in result.decisions if d.kind == "action" and d.tactic == "swap-to-fog-model"
    )
    assert swap.data["ok"] is True and swap.data["domain"] == "fog"
    failed = next(
        d for d in result.decisions if d.kind == "postcondition_failed" and d.tactic == swap.tactic
    )
    hand_over = next(
        d
        for d in result.decisions
        if d.kind == "action" and d.tactic == "fail-safe-robust-model-degraded"
    )
    assert hand_over.data["mode"] == "manual" and hand_over.data["ok"] is True
    assert swap.t < hand_over.t < failed.t, log
    assert ("started", "fail-safe") not in kinds  # handed over once
    assert not any(d.kind == "escalated" for d in result.decisions)
    assert ("escalation_exhausted", "swap-to-fog-model") in kinds
    # The report: one row per phase, the fog phase ran the fog model and shows the tactics.
    assert "per phase:" in log
    fog_row = next(line for line in log.splitlines() if line.strip().startswith("5.0–"))
    assert "rover-fog" in fog_row and "swap-to-fog-model (failed)" in fog_row


def test_sim_section_errors_name_the_file(tmp_path: Path) -> None:
    models = write_registry(tmp_path / "models.yaml")
    text = launch_text(tmp_path, SCENARIO, models)
    with pytest.raises(ModelFileError, match="unknown oracle 'crystal_ball'") as info:
        parse_launch(text.replace("name: ground_truth", "name: crystal_ball"))
    assert info.value.line is not None and "ground_truth" in (info.value.hint or "")
    with pytest.raises(ModelFileError, match=r"give one managed system: .*keys scripted, sim"):
        parse_launch(
            text.replace("  sim:", "  scripted: {trace: ROVER/trace.jsonl}\n  sim:").replace(
                "ROVER", str(ROVER)
            )
        )
    with pytest.raises(ModelFileError) as missing:
        parse_launch(text.replace(str(tmp_path / "scenario.yaml"), str(tmp_path / "nope.yaml")))
    assert "nope.yaml" in str(missing.value)
    models.write_text(models.read_text().replace("sha256: ", "sha256: 0"))
    with pytest.raises(ModelFileError) as bad:
        parse_launch(text)
    assert "models.yaml" in str(bad.value)


def test_the_demo_swaps_in_the_fog_model_and_back_without_oscillation(run_demo: Any) -> None:
    """The README's demo, the real models: fog → fog model → clear → default → dusk → low light.

    Each swap happens once, in its phase (no oscillation), no fail-safe is needed, the
    rover touches nobody, and the robust models restore the F1 their condition took away.
    """
    demo = run_demo(ROVER / "sim.yaml")
    log = demo.log
    assert [domain for _, domain in demo.swaps] == ["fog", "default", "low_light"], log
    fog_on, back, dusk = (t for t, _ in demo.swaps)
    assert 8.0 <= fog_on < 20.0 and 20.0 <= back < 30.0 and 30.0 <= dusk < 42.0, demo.swaps
    assert {"swap-to-fog-model", "swap-to-low-light-model"} <= set(demo.verified), log
    assert not demo.started("fail-safe"), log
    rows = {
        line.split()[1]: line for line in log.split("per phase:")[1].splitlines() if "–" in line
    }
    assert all(row.split()[-1] == "0" for row in rows.values())  # no collisions in any phase
    assert "rover-low_light" in rows["42.0"]
    # The report file holds the same run: each swap once, verified, models in that order.
    run = load_report(demo.report)
    assert f"report: {demo.report}" in log
    assert len(run.frames) == 420 and run.duration == pytest.approx(42.0)
    swap_events = [e for e in run.tactics if e.tactic.startswith(("swap", "default-model"))]
    # The fog model (Enki's rover-fog-enki) keeps its F1 on clear frames, so the default
    # comes back after 5 s of clear weather (swap-back-to-default), not for a degraded fog
    # model in clear weather (default-model-in-clear-weather, which the --augment rover-fog
    # needed at 21.2 s).
    assert [(e.tactic, e.outcome) for e in swap_events] == [
        ("swap-to-fog-model", "ok"),
        ("swap-back-to-default", "ok"),
        ("swap-to-low-light-model", "ok"),
    ]
    models = [f.model for f in run.frames]
    runs = [m for k, m in enumerate(models) if k == 0 or m != models[k - 1]]
    fog = load_registry(MODEL.parent / "rover.yaml").for_domain("fog").id  # rover-fog-enki
    assert runs == ["rover-default", fog, "rover-default", "rover-low_light"]


def test_the_rover_acts_on_each_frame_s_detections_at_that_frame_s_time(
    bus: Any, tmp_path: Path
) -> None:
    """A slow subscriber thread does not make the stop rule see detections late.

    The rover takes detections on a bus thread; before, the simulation stepped on as soon as
    its own subscriber had them, and on a loaded machine the rover took them some ticks
    later (its trajectory, and every figure after it, then changed with the load). Here the
    rover's thread is made slow on purpose; each frame's detections are still taken at that
    frame's time.
    """
    taken: list[tuple[float, int]] = []
    with SimulatedSystem(
        bus,
        fog_scene("slow-rover", duration=2, fog_at=5),
        models=load_registry(write_registry(tmp_path / "m.yaml")),
        oracle=None,
    ) as system:
        rover: Any = system.platform
        observe = rover.observe_detections

        def slow(det: Detections) -> None:
            threading.Event().wait(0.03)  # a descheduled thread, 3 frames of 10 ms wall
            taken.append((rover.t, det.frame_seq))
            observe(det)

        rover.observe_detections = slow
        system.run(threading.Event(), speed=0)
    frame_t = {seq: seq / 10.0 for _, seq in taken}  # camera at 10 Hz from t = 0
    assert len(taken) == 20
    assert all(t == pytest.approx(frame_t[seq], abs=1e-9) for t, seq in taken), taken
