"""A simulated run as data and as a picture: what the detector scored, what the oracle said.

:meth:`SimulatedSystem.report <anunnaki.managed.SimulatedSystem.report>` gathers a run into a
:class:`RunReport`: every scored frame (simulated time, true/false positives, misses, the
model that ran), every assessment (time, category), the tactics Utu started and how they
ended, collisions and the per-phase table. It is written as JSON (``--report FILE.json``)
and drawn by :func:`plot_report` (``--plot FILE.png``) as three panels over simulated time:

1. the detector's F1 over a sliding window of frames, coloured by the model that ran, with
   the scenario's phases shaded and labelled with their conditions;
2. the oracle's category (0 nominal, 1 degraded, 2 compromised);
3. the tactics Utu started, one row each, marked with their outcome.

Why a sliding window: one frame holds a handful of objects, so a per-frame F1 jumps between
0 and 1; the window (``window`` seconds, default 1 s = 10 frames at the default camera rate)
pools true positives, false positives and misses the way the phase table does, over a span
short enough to show a swap taking effect. matplotlib is imported only by :func:`plot_report`
(``pip install 'anunnaki[plot]'``).
"""

from __future__ import annotations

import bisect
import importlib.util
import json
import math
import statistics
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from anunnaki.errors import AnunnakiError, MissingExtraError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "FrameScore",
    "RunReport",
    "TacticEvent",
    "compare_assessors",
    "draw_report",
    "f1_score",
    "load_report",
    "plot_report",
    "require_plot_extra",
    "rolling_f1",
    "save_run",
]

FORMAT = "sim-report/1"
CATEGORY_NAMES = {0: "nominal", 1: "degraded", 2: "compromised"}
#: The label of the phase after a UAV's touch-down (the table's and the plot's last row).
GROUND = "on the ground"
#: The UAV's modes in the flight panel, in the order of its legend.
MODE_COLOURS = {
    "auto": "#d6eaf8",
    "hover": "#fcf3cf",
    "return_home": "#fadbd8",
    "land": "#e8daef",
    "stopped": "#d5d8dc",
}
_OUTCOMES = {"postcondition_ok": "ok", "postcondition_failed": "failed", "completed": "done"}


def f1_score(tp: int, fp: int, fn: int) -> float | None:
    """F1 of pooled counts, 2·TP / (2·TP + FP + FN); ``None`` with no ground-truth object.

    Where there is nothing to find (TP + FN = 0) recall is undefined and so is F1: a false
    positive there is no F1 of 0 (the counts tell it), and two objects missed are.
    """
    if tp + fn == 0:
        return None
    return 2 * tp / (2 * tp + fp + fn)


@dataclass(frozen=True)
class FrameScore:
    """One frame's detections matched against its ground truth (the F1 rule)."""

    t: float
    tp: int
    fp: int
    fn: int
    model: str


@dataclass
class TacticEvent:
    """A tactic Utu started: when, and how it ended (``None`` while it ran past the end)."""

    t: float
    tactic: str
    outcome: str | None = None
    ended: float | None = None


@dataclass
class RunReport:
    """A simulated run, JSON-ready (``anunnaki: sim-report/1``).

    Attributes:
        name: The scenario's name.
        platform: ``rover`` or ``uav``.
        duration: Simulated seconds run.
        frames: Every scored frame, in time order.
        assessments: ``(t, category)`` per assessment the oracle published.
        tactics: The tactics Utu started, in time order.
        collisions: Simulated times of collisions.
        phases: The per-phase table (:meth:`PhaseScore.as_dict` rows).
        scoring: When a live scorer ran beside the oracle (``managed.sim.scorer``): how
            often they agreed and the delay between their category changes
            (:func:`compare_assessors`); ``None`` otherwise (and absent from the file).
        flight: A UAV's flight (:meth:`UavSim.flight <anunnaki.sim.UavSim.flight>`):
            the mission's outcome — ``delivered`` (the package dropped), ``landing`` (``home``,
            ``forced``, ``elsewhere``, ``airborne``, ``ground``), ``landed_xy``,
            ``battery_at_landing`` — and ``took_off``, ``delivered_at``, ``landed`` (the
            touch-down, s), ``landed_home``, ``battery`` and ``track``, rows of
            ``{t, x, y, altitude, battery, mode}`` at 2 Hz; ``None`` for a rover (and absent
            from the file).

    """

    name: str
    platform: str
    duration: float
    frames: list[FrameScore] = field(default_factory=list)
    assessments: list[tuple[float, int]] = field(default_factory=list)
    tactics: list[TacticEvent] = field(default_factory=list)
    collisions: list[float] = field(default_factory=list)
    phases: list[dict[str, Any]] = field(default_factory=list)
    scoring: dict[str, Any] | None = None
    flight: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (the file format)."""
        doc: dict[str, Any] = {
            "anunnaki": FORMAT,
            "name": self.name,
            "platform": self.platform,
            "duration": self.duration,
            "phases": self.phases,
            "frames": [asdict(f) for f in self.frames],
            "assessments": [[t, c] for t, c in self.assessments],
            "tactics": [asdict(e) for e in self.tactics],
            "collisions": list(self.collisions),
        }
        if self.scoring is not None:
            doc["scoring"] = self.scoring
        if self.flight is not None:
            doc["flight"] = self.flight
        return doc

    def write(self, path: str | Path) -> Path:
        """Write the report as JSON; returns the path."""
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(self.as_dict(), indent=1) + "\n", encoding="utf-8")
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any], *, source: str = "<report>") -> RunReport:
        """Read the file format back (what :meth:`as_dict` wrote)."""
        if doc.get("anunnaki") != FORMAT:
            raise AnunnakiError(
                f"{source}: not a simulation report (expected 'anunnaki: {FORMAT}', "
                f"got {doc.get('anunnaki')!r}); write one with --report FILE.json"
            )
        try:
            return cls(
                name=str(doc["name"]),
                platform=str(doc["platform"]),
                duration=float(doc["duration"]),
                frames=[FrameScore(**f) for f in doc["frames"]],
                assessments=[(float(t), int(c)) for t, c in doc["assessments"]],
                tactics=[TacticEvent(**e) for e in doc["tactics"]],
                collisions=[float(t) for t in doc["collisions"]],
                phases=list(doc["phases"]),
                scoring=dict(doc["scoring"]) if doc.get("scoring") is not None else None,
                flight=dict(doc["flight"]) if doc.get("flight") is not None else None,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise AnunnakiError(f"{source}: malformed simulation report: {exc!r}") from None


def load_report(path: str | Path) -> RunReport:
    """Load a report written by :meth:`RunReport.write`."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise AnunnakiError(f"{p}: cannot read the simulation report: {exc}") from None
    if not isinstance(doc, dict):
        raise AnunnakiError(f"{p}: a simulation report is a JSON object")
    return RunReport.from_dict(doc, source=str(p))


def _changes(series: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """``(frame, category)`` where a per-frame category series takes a new value."""
    out: list[tuple[int, int]] = []
    for seq, cat in series:
        if not out or cat != out[-1][1]:
            out.append((seq, cat))
    return out


def compare_assessors(
    oracle: Sequence[tuple[int, int]],
    scorer: Sequence[tuple[int, int]],
    *,
    rate: float,
    horizon: int = 100,
) -> dict[str, Any]:
    """How an oracle's categories agree with a live scorer's (both ``(frame seq, category)``).

    Agreement is over the frames both assessed. The delay is measured at each change of the
    scorer's category after its first assessment: from the frame it changed to the nearest
    frame (within ``horizon`` frames either way) at which the oracle changed to the same
    category; negative when the oracle was first (a ground-truth scorer pools a window of
    frames, so a frame-by-frame oracle often is). Changes the oracle never matched are
    counted as ``unmatched``.

    Args:
        oracle: The oracle's assessments, in any order (the last per frame counts).
        scorer: The scorer's.
        rate: Camera frames per second (delays in seconds too).
        horizon: How far apart (frames) two changes may be and still be paired.

    Returns:
        ``{"frames", "agreement", "confusion" (scorer row x oracle column), "changes",
        "delays_frames", "median_delay_frames", "median_delay_s", "unmatched"}``.

    """
    mine, theirs = dict(sorted(oracle)), dict(sorted(scorer))
    both = sorted(set(mine) & set(theirs))
    confusion = [[0, 0, 0] for _ in range(3)]
    for seq in both:
        confusion[min(max(theirs[seq], 0), 2)][min(max(mine[seq], 0), 2)] += 1
    agree = sum(confusion[c][c] for c in range(3))
    ours = _changes(sorted(mine.items()))[1:]
    delays: list[int] = []
    unmatched = 0
    changes = _changes(sorted(theirs.items()))[1:]  # a first assessment is no change
    for seq, cat in changes:
        near = [s - seq for s, c in ours if c == cat and abs(s - seq) <= horizon]
        if near:
            delays.append(min(near, key=abs))
        else:
            unmatched += 1
    median = float(statistics.median(delays)) if delays else None
    return {
        "frames": len(both),
        "agreement": None if not both else round(agree / len(both), 4),
        "confusion": confusion,
        "changes": len(changes),
        "delays_frames": delays,
        "median_delay_frames": median,
        "median_delay_s": None if median is None else round(median / rate, 3),
        "unmatched": unmatched,
    }


def tactic_events(decisions: Sequence[Any]) -> list[TacticEvent]:
    """Utu's decisions (``t``, ``kind``, ``tactic``) → the tactics started and their outcome."""
    events: list[TacticEvent] = []
    running: dict[str, list[TacticEvent]] = {}
    for d in decisions:
        if not getattr(d, "tactic", None):
            continue
        if d.kind == "started":
            event = TacticEvent(float(d.t), str(d.tactic))
            events.append(event)
            running.setdefault(d.tactic, []).append(event)
        elif d.kind in _OUTCOMES and running.get(d.tactic):
            event = running[d.tactic].pop()
            event.outcome, event.ended = _OUTCOMES[d.kind], float(d.t)
    return events


def rolling_f1(frames: Sequence[FrameScore], window: float = 1.0) -> list[float | None]:
    """F1 over the frames in ``(t - window, t]`` for each frame (``None``: nothing to find).

    True positives, false positives and misses are pooled over the window (:func:`f1_score`),
    as in the phase table: a window without a ground-truth object has no F1, false positives
    or not. Frames must be in time order.
    """
    if window <= 0:
        raise ValueError(f"window must be > 0 s, got {window}")
    times = [f.t for f in frames]
    sums = [(0, 0, 0)]  # running TP, FP, FN
    for f in frames:
        tp, fp, fn = sums[-1]
        sums.append((tp + f.tp, fp + f.fp, fn + f.fn))
    out: list[float | None] = []
    for k, f in enumerate(frames):
        first = bisect.bisect_right(times, f.t - window, 0, k + 1)
        (tp1, fp1, fn1), (tp0, fp0, fn0) = sums[k + 1], sums[first]
        out.append(f1_score(tp1 - tp0, fp1 - fp0, fn1 - fn0))
    return out


def require_plot_extra() -> None:
    """Raise now, before a run, when :func:`plot_report` could not draw it afterwards.

    Raises:
        MissingExtraError: matplotlib is not installed.

    """
    if importlib.util.find_spec("matplotlib") is None:
        raise MissingExtraError("matplotlib", "plot")


def save_run(
    run: RunReport,
    *,
    report: str | Path | None = None,
    plot: str | Path | None = None,
    say: Callable[[str], object] = print,
) -> None:
    """Write ``run`` as JSON to ``report`` and draw it to ``plot`` (each when given).

    ``say`` is told where each went (``report: PATH``, ``plot: PATH``) as soon as it is
    written, so a plot that fails still leaves the report said.

    Raises:
        OSError: A file could not be written.
        MissingExtraError: ``plot`` without matplotlib.

    """
    if report:
        say(f"report: {run.write(report)}")
    if plot:
        say(f"plot: {plot_report(run, plot)}")


def plot_report(
    report: RunReport, path: str | Path, *, window: float = 1.0, title: str | None = None
) -> Path:
    """Draw ``report`` as a PNG (or any format matplotlib knows by the suffix); returns the path.

    Raises:
        MissingExtraError: matplotlib is not installed.

    """
    fig = draw_report(report, window=window, title=title)
    import matplotlib.pyplot as plt

    out = Path(path)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
    finally:
        plt.close(fig)
    return out


def draw_report(
    report: RunReport, *, window: float = 1.0, title: str | None = None, width: float = 11.0
) -> Figure:
    """The figure :func:`plot_report` saves (``width`` inches wide); close it when done.

    Raises:
        MissingExtraError: matplotlib is not installed.

    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingExtraError("matplotlib", "plot") from None

    track = (report.flight or {}).get("track") or []
    ratios = [3.2, 1.2]
    if track:
        ratios.append(1.8)
    ratios.append(max(1.0, 0.45 * len(report.tactics) + 0.4))
    fig, axes = plt.subplots(
        len(ratios),
        1,
        figsize=(width, 6.4 + (1.8 if track else 0.0)),
        sharex=True,
        gridspec_kw={"height_ratios": ratios},
        squeeze=False,
    )
    panels = list(axes[:, 0])
    ax_f1, ax_cat, ax_tac = panels[0], panels[1], panels[-1]
    end = max(report.duration, 1e-3)
    _shade_phases(report, panels)
    _draw_f1(report, ax_f1, window)
    _draw_categories(report, ax_cat, end)
    if track:
        _draw_flight(report.flight or {}, track, panels[2], end)
    _draw_tactics(report, ax_tac, end)
    ax_tac.set_xlim(0, end)
    ax_tac.set_xlabel("simulated time (s)")
    fig.suptitle(title or f"{report.platform} — {report.name}", fontsize=11)
    fig.tight_layout()
    # The labels are measured in the layout they make room for: placed, laid out, placed again.
    placed = _label_phases(report, ax_f1)
    fig.tight_layout()
    for artist in placed:
        artist.remove()
    _label_phases(report, ax_f1)
    return fig


def _shade_phases(report: RunReport, axes: Sequence[Axes]) -> None:
    """Shade the scenario's phases on every panel (hatched: on the ground after touch-down)."""
    shades = ("#f4f4f4", "#ffffff")
    for k, phase in enumerate(report.phases):
        ground = phase.get("label") == GROUND
        for ax in axes:
            ax.axvspan(
                phase["start"],
                phase["end"],
                facecolor="#eeeeee" if ground else shades[k % 2],
                hatch="//" if ground else None,
                edgecolor="#d5d5d5" if ground else "none",
                zorder=0,
                lw=0,
            )


def _stack_labels(spans: Sequence[tuple[float, float]], *, gap: float = 0.0) -> list[int]:
    """The row of each label so that no two in a row overlap: ``spans`` are ``(left, right)``.

    Greedy, left to right (by left edge): each label takes the lowest row whose last label
    ends at least ``gap`` before it starts. Labels that fit side by side stay in row 0.
    """
    rows: list[float] = []  # each row's right edge so far
    out = [0] * len(spans)
    for k in sorted(range(len(spans)), key=lambda i: spans[i][0]):
        left, right = spans[k]
        row = next((r for r, edge in enumerate(rows) if edge + gap <= left), len(rows))
        if row == len(rows):
            rows.append(right)
        else:
            rows[row] = right
        out[k] = row
    return out


def _label_phases(report: RunReport, ax: Axes) -> list[Any]:
    """Label the phases above ``ax``, stacked in rows where they would overlap.

    Each label is measured as drawn, centred over its phase (moved in where it would run past
    either end of the axis), and put in the lowest row where it overlaps no other; a bracket
    under it spans its phase, so that a label in an upper row still says which phase it names.
    """
    if not report.phases:
        return []
    fig = ax.get_figure()
    assert fig is not None
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    to_px = ax.transData
    x_lo, x_hi = (to_px.transform((x, 0))[0] for x in ax.get_xlim())
    texts, spans = [], []
    for phase in report.phases:
        text = ax.text(
            0.0, 1.0, phase["label"], ha="center", va="bottom", fontsize=8, color="#555555",
            transform=ax.get_xaxis_transform(), gid="phase-label",
        )  # fmt: skip
        box = text.get_window_extent(renderer)
        a, b = (to_px.transform((x, 0))[0] for x in (phase["start"], phase["end"]))
        half = box.width / 2
        centre = min(max((a + b) / 2, x_lo + half), x_hi - half)
        texts.append((text, a, b, centre))
        spans.append((centre - half, centre + half))
    pad = 4.0  # px between two labels in a row
    rows = _stack_labels(spans, gap=pad)
    axes_px = ax.get_window_extent(renderer)
    row_height = (max(t.get_window_extent(renderer).height for t, *_ in texts) + 6.0) / max(
        axes_px.height, 1.0
    )
    to_data = ax.transData.inverted()
    artists: list[Any] = []
    for (text, a, b, centre), row in zip(texts, rows, strict=True):
        y = 1.012 + row * row_height
        text.set_position((to_data.transform((centre, 0))[0], y + 0.012))
        artists.append(text)
        x0, x1 = (to_data.transform((v, 0))[0] for v in (a + 1.0, b - 1.0))
        artists += ax.plot(
            [x0, x1], [y, y], color="#aaaaaa", lw=0.8, clip_on=False,
            transform=ax.get_xaxis_transform(), solid_capstyle="butt",
        )  # fmt: skip
    return artists


def _draw_f1(report: RunReport, ax: Axes, window: float) -> None:
    """Panel 1: the detector's F1 over a ``window``-second window, one colour per model."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    colours = plt.get_cmap("tab10")
    models = list(dict.fromkeys(f.model for f in report.frames))
    colour = {m: colours(i % 10) for i, m in enumerate(models)}
    f1 = rolling_f1(report.frames, window)
    for model in models:
        xs = [f.t for f in report.frames]
        ys = [
            (v if v is not None and f.model == model else math.nan)
            for f, v in zip(report.frames, f1, strict=True)
        ]
        ax.plot(xs, ys, color=colour[model], lw=1.8, label=model)
    for t in report.collisions:
        ax.axvline(t, color="black", lw=1.0, ls=":")
    ax.set_ylim(-0.03, 1.05)
    ax.set_ylabel(f"detector F1\n({window:g} s window)")
    handles = [Line2D([], [], color=colour[m], lw=2, label=m) for m in models]
    if report.collisions:
        handles.append(Line2D([], [], color="black", ls=":", label="collision"))
    if handles:
        ax.legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.9)
    ax.grid(axis="y", color="#dddddd", lw=0.6)


def _draw_categories(report: RunReport, ax: Axes, end: float) -> None:
    """Panel 2: the oracle's category, as the step function it is."""
    if report.assessments:
        ts = [t for t, _ in report.assessments] + [end]
        cs = [c for _, c in report.assessments]
        ax.step(ts, [*cs, cs[-1]], where="post", color="#b03a2e", lw=1.5)
    ax.set_ylim(-0.4, 2.4)
    ax.set_yticks([0, 1, 2], [f"{k} {v}" for k, v in CATEGORY_NAMES.items()], fontsize=8)
    ax.set_ylabel("oracle")


def _draw_tactics(report: RunReport, ax: Axes, end: float) -> None:
    """Panel 3: the tactics, one row each, from start to outcome."""
    marks = {"ok": ("#1e8449", "o"), "done": ("#1e8449", "o"), "failed": ("#b03a2e", "X")}
    for row, event in enumerate(report.tactics):
        stop = event.ended if event.ended is not None else end
        ax.plot([event.t, stop], [row, row], color="#2e4053", lw=3, solid_capstyle="butt")
        ax.plot([event.t], [row], marker="|", color="#2e4053", ms=12)
        if event.outcome is not None:
            c, m = marks.get(event.outcome, ("#7f8c8d", "s"))
            ax.plot([stop], [row], marker=m, color=c, ms=6)
        ax.text(
            event.t,
            row + 0.28,
            f"{event.tactic}" + (f" ({event.outcome})" if event.outcome else ""),
            fontsize=7.5,
            va="bottom",
            clip_on=True,
        )
    ax.set_ylim(-0.6, max(len(report.tactics), 1) - 0.1)
    ax.set_yticks([])
    ax.set_ylabel("tactics")


def _draw_flight(flight: dict[str, Any], track: list[dict[str, Any]], ax: Axes, end: float) -> None:
    """Panel 3 (a UAV): altitude and battery over time, the mode as coloured bands."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    ts = [float(row["t"]) for row in track]
    seen: list[str] = []
    k = 0
    while k < len(track):  # one band per stretch of a mode, to the next sample's time
        mode = str(track[k]["mode"])
        j = k
        while j + 1 < len(track) and track[j + 1]["mode"] == mode:
            j += 1
        stop = ts[j + 1] if j + 1 < len(track) else end
        ax.axvspan(
            ts[k], stop, ymin=0.0, ymax=0.12, color=MODE_COLOURS.get(mode, "#eeeeee"),
            lw=0, zorder=1, gid=f"mode:{mode}",
        )  # fmt: skip
        if mode not in seen:
            seen.append(mode)
        k = j + 1
    ax.plot(ts, [row["altitude"] for row in track], color="#1f618d", lw=1.6, label="altitude")
    ax.set_ylabel("altitude (m)", fontsize=9)
    top = max([float(row["altitude"]) for row in track] + [1.0])
    ax.set_ylim(-0.14 * top, top * 1.5)  # room for the mode bands below, the legend above
    twin = ax.twinx()
    twin.plot(ts, [row["battery"] for row in track], color="#b9770e", lw=1.3, label="battery")
    twin.set_ylim(-14, 150)
    twin.set_yticks([0, 25, 50, 75, 100])
    twin.set_ylabel("battery (%)", fontsize=9)
    landed = flight.get("landed")
    handles: list[Any] = [
        Line2D([], [], color="#1f618d", lw=2, label="altitude"),
        Line2D([], [], color="#b9770e", lw=2, label="battery"),
    ]
    if landed is not None:
        ax.axvline(float(landed), color="#555555", lw=1.0, ls="--")
        handles.append(Line2D([], [], color="#555555", ls="--", label="touch-down"))
    handles += [Patch(color=MODE_COLOURS.get(m, "#eeeeee"), label=m) for m in seen]
    ax.legend(handles=handles, loc="upper center", fontsize=7, ncol=len(handles), framealpha=0.9)
