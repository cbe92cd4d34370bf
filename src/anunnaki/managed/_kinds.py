"""The built-in managed-system kinds: ``scripted`` (a trace) and ``sim`` (a simulated platform).

Each is a plugin of :data:`anunnaki.managed.MANAGED` (see :mod:`anunnaki.managed._slot`),
imported only when a launch file names it: ``sim`` needs the ``vision`` extra. The robots
(``ros1``, ``ros2``) are in :mod:`anunnaki.managed._robot`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field

from anunnaki.errors import AnunnakiError, MissingExtraError, ModelFileError
from anunnaki.managed._camera import check_camera_chain
from anunnaki.managed._slot import DecisionLike, ManagedContext, UtuSettings
from anunnaki.trace import Record, read_trace

__all__ = ["ScriptedConfig", "ScriptedKind", "SimConfig", "SimKind"]

log = logging.getLogger("anunnaki.managed")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _here(base: Path, p: str) -> str:
    q = Path(p).expanduser()
    return str(q if q.is_absolute() else base / q)


# -- scripted ----------------------------------------------------------------------------------
_NO_SYNC = (
    "delete the key: in one process on clock: sim the replay is in step with Utu on the "
    "run's executor; on threads or across processes it plays on its clock like a bag "
    "(rosbag play waits for no subscriber); docs/running.md"
)


class ScriptedConfig(_Strict):
    """A scripted managed system (:class:`~anunnaki.managed.ScriptedSystem`).

    Attributes:
        trace: The trace to replay (JSONL, ``anunnaki: trace/1``), or a ROS bag: a ROS 1
            ``.bag``, or a rosbag2 (its folder, ``.mcap`` or ``.db3``), read as a trace
            (:func:`~anunnaki.rosbridge.read_bag`).
        bridge: With a bag of a robot: the bridge file that turns its topics into the bus's
            (as the live bridge would publish them); a bag ``anunnaki log`` wrote needs none.
        prefix: The platform's name prefix: services ``<prefix>/set_mode``, ``<prefix>/stop``.
        status_topic: The topic whose ``mode``/``buzzer`` fields follow commands.
        modes: The modes ``set_mode`` accepts.
        speed: Replay speed: 1.0 real time, 10 ten times faster.
        loop: Start over at the end (trace time keeps increasing), until stopped.
        publish_clock: Publish the trace time on ``/clock`` (for ``clock: sim``; always so
            when the run is one program on an executor, where it is Utu's only clock).

    In one process on sim time (``clock: sim``, Utu's five parts composed) the replay is one
    deterministic program: after each instant the replay drains the run's executor (every
    node takes that instant's messages, Utu acts on them) before it moves time on, at any
    ``speed`` (``anunnaki.bus.Executor``, docs/running.md). Anywhere else (Utu on threads
    of its own, or in other processes) the replay plays on its clock as ``rosbag play``
    does, waiting for no subscriber: with ``publish_clock`` an instant's time goes out
    before its messages, and Utu takes whatever has arrived at each cycle.

    """

    #: Options that were removed: what a launch file that still has one is told to do.
    removed: ClassVar[dict[str, str]] = {
        "sync": _NO_SYNC,
        "sync_timeout": _NO_SYNC,
    }

    trace: str
    bridge: str | None = None
    prefix: str = "/rover"
    status_topic: str | None = None
    modes: list[str] = Field(default_factory=lambda: ["autonomous", "manual"], min_length=1)
    speed: Annotated[float, Field(gt=0, le=10_000)] = 1.0
    loop: bool = False
    publish_clock: bool = False


def drive(
    system: Any,
    stop: threading.Event,
    *,
    speed: float,
    loop: bool,
    until: float | None,
    after_instant: Callable[[], object] | None = None,
) -> None:
    """Publish the scripted system's trace live: record time / ``speed`` after the start.

    ``after_instant()`` is called after the records of each instant went out (the run's
    executor drains there).
    """
    base = list(system.records)
    instants = system.instants()
    if not instants:
        return
    first = instants[0]
    gap = instants[1] - instants[0] if len(instants) > 1 else 1.0
    span = instants[-1] - first + gap
    wall0 = time.monotonic()
    offset = 0.0
    while True:
        for instant in instants:
            t = instant + offset
            if until is not None and t > until:
                return
            delay = wall0 + (t - first) / speed - time.monotonic()
            if (delay > 0 and stop.wait(delay)) or stop.is_set():
                return
            system.step(t)
            if after_instant is not None:
                after_instant()
        if not loop:
            return
        offset += span
        system.records.extend(Record(r.t + offset, r.topic, r.msg) for r in base)


class _Running:
    """A started managed system: its thread, why it ends, its close and finish."""

    def __init__(
        self,
        system: Any,
        thread: threading.Thread,
        ended: str,
        finish: Callable[[Sequence[DecisionLike], float], None] | None = None,
        *,
        after_close: Callable[[], None] | None = None,
    ) -> None:
        self.system = system
        self.thread = thread
        self.ended = ended
        self._finish = finish
        self._after_close = after_close

    def finish(self, decisions: Sequence[DecisionLike], ran: float) -> None:
        if self._finish is not None:
            self._finish(decisions, ran)

    def close(self) -> None:
        try:
            self.system.close()
        finally:
            after, self._after_close = self._after_close, None
            if after is not None:
                after()


class ScriptedKind:
    """``kind: scripted``: a trace replayed onto the bus, obeying mode changes and stops."""

    name: ClassVar[str] = "scripted"
    Options: ClassVar[type[BaseModel]] = ScriptedConfig
    #: In one process on sim time, the replay is one program on the run's executor.
    deterministic = True

    def __init__(self, options: BaseModel, *, base: Path) -> None:
        assert isinstance(options, ScriptedConfig)
        bridge = None if options.bridge is None else _here(base, options.bridge)
        self.options = options.model_copy(
            update={"trace": _here(base, options.trace), "bridge": bridge}
        )
        self.speed = self.options.speed
        self.records: list[Record] = []

    def check(self, utu: UtuSettings) -> None:
        """Read the trace now (B5)."""
        self._read()

    def _read(self) -> None:
        from anunnaki.rosbridge import is_bag

        if is_bag(self.options.trace):
            from anunnaki.rosbridge import load_bridge, read_bag

            bridge = self.options.bridge
            spec = None if bridge is None else load_bridge(bridge)
            self.records = read_bag(self.options.trace, spec)
        else:
            self.records = read_trace(self.options.trace).records
        if not self.records:
            raise ModelFileError(
                "the trace has no records", path=self.options.trace, hint="record or write some"
            )

    def notes(self, utu: UtuSettings, speed: float) -> list[str]:
        """Clock and speed combinations that do not do what one may think."""
        out = []
        if utu.clock == "wall" and speed != 1:
            out.append(
                f"note: speed {speed:g}× on the wall clock: rates and staleness are measured "
                "in real time; use clock: sim and publish_clock: true"
            )
        if utu.clock == "sim" and not self.options.publish_clock:
            out.append(
                "note: clock: sim but the scripted system does not publish /clock "
                "(publish_clock: true); Utu's time will not advance unless a simulator "
                "publishes it"
            )
        return out

    def start(self, ctx: ManagedContext) -> _Running:
        """Replay the trace in a thread (on the run's executor, if it has one)."""
        from anunnaki.managed import ScriptedSystem

        sc = self.options
        if not self.records:
            self._read()
        executor = ctx.executor
        system = ScriptedSystem(
            ctx.bus,
            list(self.records),
            prefix=sc.prefix,
            status_topic=sc.status_topic,
            modes=tuple(sc.modes),
            publish_clock=sc.publish_clock or executor is not None,
        )
        recs = self.records
        ctx.say(
            f"managed: scripted {sc.prefix} from {sc.trace} ({len(recs)} records, "
            f"t {recs[0].t:g}–{recs[-1].t:g} s) at {ctx.speed:g}× "
            + ("looping" if sc.loop else "once")
            + (", one thread of delivery" if executor is not None else "")
        )

        def run() -> None:
            if executor is not None:
                executor.bind()  # this thread delivers every message of the run
            try:
                drive(
                    system,
                    ctx.stop,
                    speed=ctx.speed,
                    loop=sc.loop,
                    until=ctx.until,
                    after_instant=None if executor is None else executor.spin_until_idle,
                )
            except AnunnakiError as exc:
                if not ctx.stop.is_set():
                    log.warning("scripted system stopped: %s", exc)
            except Exception:  # a bug: say so; the run then ends as after the trace
                log.exception("the scripted system failed")
            finally:
                if executor is not None:
                    executor.spin_until_idle()
                    executor.release()

        thread = threading.Thread(target=run, name="anunnaki-scripted", daemon=True)
        thread.start()
        return _Running(system, thread, "trace ended")


# -- sim ---------------------------------------------------------------------------------------
class SimConfig(_Strict):
    """A simulated platform, its detector and oracle (:class:`~anunnaki.managed.SimulatedSystem`).

    Attributes:
        scenario: The scenario file (``anunnaki: scenario/1``); its ``platform`` says rover or
            UAV.
        models: The detector's model registry (``anunnaki: models/1``); without it no
            detector runs.
        oracle: The oracle node's options: ``name`` (default ``ground_truth``) and the
            oracle's own (e.g. ``window``); ``null`` runs none.
        scorer: A second oracle run beside it as its live scorer (same form, e.g.
            ``{name: ground_truth, window: 30}`` beside ``oracle: {name: enlil}``); it
            publishes on ``/sim/oracle/scorer``, which Utu does not read, and the report
            gives their agreement and the delay between their category changes.
        shadow: A shadow oracle (same form plus ``domain`` or ``model``: which model it
            assesses, e.g. ``{name: enlil, window: 3, domain: default}``): that model's
            oracle on every frame whichever model is active, published on
            ``/utu/oracle/shadow`` for an agent of Utu's (docs/whole-loop.md).
        speed: Simulated seconds per wall second (0: as fast as the work allows).
        report: Print the per-phase table (detector F1, categories, models, tactics) at the end.
        report_file: Also write the run as data (``sim-report/1`` JSON: every scored frame,
            assessment and tactic); relative to the launch file.
        plot_file: Also draw the run (windowed F1 per model, the oracle's category, the
            tactics; PNG, or any format matplotlib knows by the suffix); relative to the
            launch file.
        scenario_seed: Draw the scenario again from this seed as its ``vary:`` section says
            (:func:`~anunnaki.sim.draw_scenario`: phase timing, object placement, condition
            strength, fault timing, battery drain); ``None`` runs it as written
            (``anunnaki run --seed N``).
        until_landed: End the run at the UAV's touch-down after its flight (nothing of the
            mission changes after it) instead of at the scenario's end
            (``anunnaki run --until-landed``); a rover ignores it.
        torch_threads: torch's intra-op threads while the system runs (the detector's, the
            oracles' and the scorer's networks; process-wide, set at the start and put back
            at the close); ``None`` leaves torch's default, one per core. In one process the
            run has one thread of delivery, so the networks never run at once; on two cores
            shared with other work a second thread spent much of each forward waiting at
            OpenMP's barriers (docs/results.md, issue #30 item 4). The same detections
            either way.

    """

    scenario: str
    models: str | None = None
    oracle: dict[str, Any] | None = Field(default_factory=lambda: {"name": "ground_truth"})
    scorer: dict[str, Any] | None = None
    shadow: dict[str, Any] | None = None
    speed: Annotated[float, Field(gt=0, le=10_000)] = 1.0
    report: bool = True
    report_file: str | None = None
    plot_file: str | None = None
    scenario_seed: Annotated[int, Field(ge=0)] | None = None
    until_landed: bool = False
    torch_threads: Annotated[int, Field(ge=1)] | None = None


def _torch_threads(threads: int) -> Callable[[], None]:
    """Run torch's operators on ``threads`` threads in this process; returns the undo."""
    import anunnaki.lec  # noqa: F401  # sets OMP_WAIT_POLICY before torch is first imported

    try:
        import torch
    except ImportError as exc:
        raise MissingExtraError("torch", "vision") from exc
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    return lambda: torch.set_num_threads(before)


class SimKind:
    """``kind: sim``: a simulated rover or UAV, its detector (LEC node) and its oracle."""

    name: ClassVar[str] = "sim"
    Options: ClassVar[type[BaseModel]] = SimConfig
    #: In one process, the run is one program on the executor: the simulation drains it at
    #: every frame and instant and moves its clock on only then (anunnaki.bus._executor).
    deterministic = True

    def __init__(self, options: BaseModel, *, base: Path) -> None:
        assert isinstance(options, SimConfig)
        o = options
        self.options = o.model_copy(
            update={
                "scenario": _here(base, o.scenario),
                "models": _here(base, o.models) if o.models is not None else None,
                "report_file": None if o.report_file is None else _here(base, o.report_file),
                "plot_file": None if o.plot_file is None else _here(base, o.plot_file),
            }
        )
        self.speed = self.options.speed

    def model_registry(self) -> str | None:
        """The detector's model registry (:class:`~anunnaki.managed.ServesModels` hook)."""
        return self.options.models

    def with_reports(self, *, report: str | None, plot: str | None) -> None:
        """Keep the run as data (``report``, JSON) and draw it (``plot``) at the end."""
        update = {k: v for k, v in (("report_file", report), ("plot_file", plot)) if v}
        self.options = self.options.model_copy(update=update)
        if plot:
            from anunnaki.sim import require_plot_extra

            require_plot_extra()  # before the run, not after it

    def with_scenario(self, *, seed: int | None = None, until_landed: bool = False) -> None:
        """Draw the scenario from ``seed`` (its ``vary:``) and end at the touch-down.

        ``seed=None`` keeps the launch's ``scenario_seed``; ``until_landed=False`` its
        ``until_landed``.
        """
        update: dict[str, Any] = {}
        if seed is not None:
            update["scenario_seed"] = seed
        if until_landed:
            update["until_landed"] = True
        self.options = SimConfig.model_validate({**self.options.model_dump(), **update})

    def check(self, utu: UtuSettings) -> None:
        """Load the scenario and the registry now, so that errors come before bring-up (B5)."""
        from anunnaki.sim import load_scenario, require_plot_extra

        sim = self.options
        load_scenario(sim.scenario)
        if sim.plot_file is not None:
            require_plot_extra()
        check_camera_chain(
            models=sim.models,
            oracle=sim.oracle,
            scorer=sim.scorer,
            default_oracle="ground_truth",
            where="managed.sim",
            shadow=sim.shadow,
        )

    def notes(self, utu: UtuSettings, speed: float) -> list[str]:
        """Nothing to warn about."""
        return []

    def start(self, ctx: ManagedContext) -> _Running:
        """Start the simulated platform, its detector and its oracle; run it in a thread."""
        from anunnaki.managed import SimulatedSystem

        cfg = self.options
        scenario: Any = cfg.scenario
        if cfg.scenario_seed is not None:
            from anunnaki.sim import draw_scenario, load_scenario

            scenario = draw_scenario(load_scenario(cfg.scenario), cfg.scenario_seed)
        undo = None if cfg.torch_threads is None else _torch_threads(cfg.torch_threads)
        try:
            system = SimulatedSystem(
                ctx.bus,
                scenario,
                models=cfg.models,
                oracle=cfg.oracle,
                scorer=cfg.scorer,
                shadow=cfg.shadow,
            )
        except BaseException:
            if undo is not None:
                undo()
            raise
        sc = system.scenario
        end = sc.duration if ctx.until is None else ctx.until
        ctx.say(
            f"managed: simulated {sc.platform} '{sc.name}' from {cfg.scenario} "
            f"(t 0–{end:g} s) at {ctx.speed:g}×"
            + (", one thread of delivery" if system.executor is not None else "")
            + f"; {system.chain.describe()}"
        )

        def run() -> None:
            try:
                system.run(ctx.stop, speed=ctx.speed, until=end, until_landed=cfg.until_landed)
                if system.landed_stop:
                    running.ended = "the UAV landed"
            except Exception:  # a bug: say so; the run then ends as after the scenario
                log.exception("the simulation failed")

        def finish(decisions: Sequence[DecisionLike], ran: float) -> None:
            self._finish(system, decisions, ran, ctx.say)

        thread = threading.Thread(target=run, name="anunnaki-sim", daemon=True)
        running = _Running(system, thread, "scenario ended", finish, after_close=undo)
        thread.start()
        return running

    def _finish(
        self, system: Any, decisions: Sequence[DecisionLike], ran: float, say: Callable[[str], None]
    ) -> None:
        cfg = self.options
        if cfg.report:
            from anunnaki.managed import format_phases, format_scoring

            platform = system.platform
            say(
                f"\nsimulated {platform.t:.1f} s in {ran:.1f} s wall "
                f"({platform.frames} frames, {platform.frames / max(ran, 1e-9):.1f} frames/s); "
                "per phase:"
            )
            say(format_phases(system.phases(list(decisions))))
            summary = getattr(platform, "summary", None)  # the UAV's mission outcome
            if callable(summary):
                say(summary())
            scoring = system.scoring()
            if scoring is not None:
                say(format_scoring(scoring))
        if cfg.report_file or cfg.plot_file:
            from anunnaki.sim import save_run

            try:  # a file that cannot be written is said, never fatal: the run is over
                save_run(
                    system.report(list(decisions)),
                    report=cfg.report_file,
                    plot=cfg.plot_file,
                    say=say,
                )
            except (OSError, AnunnakiError) as exc:
                say(f"report: not written: {exc}")
