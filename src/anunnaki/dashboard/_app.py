"""The web application: one page, a snapshot, a stream of patches, frames and operator calls.

Routes
    ``GET /``                        the page (static HTML, JS and CSS under ``/static``)
    ``GET /api/snapshot``            everything, as JSON (what a page gets first)
    ``GET /api/events``              server-sent events: ``snapshot`` once, then ``patch``
                                     events with what changed, at most ``max_rate`` a second
    ``GET /api/explain/{node}``      why a goal or obstacle has its status
    ``GET /api/frame/{seq}``         a camera frame's bytes (``latest`` for the newest)
    ``POST /api/operator/{action}``  pause, resume, approve, reject, run_stop (needs the token)
    ``GET /api/health``              ``{ok, version, operator}``

The stream is coalesced on the server: after sending a patch a client's stream sleeps
``1/max_rate`` seconds and the next patch carries everything that changed meanwhile, so a
page never receives more than ``max_rate`` updates a second however fast the bus is. An
isolated change (a violation) goes out at once. Every patch carries ``now``, and a patch
goes out at least once a second, so staleness keeps counting on the page.

Operator actions exist only when the server has a token; the token is compared in constant
time (:func:`anunnaki.tokens.token_matches`) and the caller recorded by Utu is
``dashboard:<operator>@<client address>``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import re
import threading
from collections.abc import AsyncIterator
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Header, HTTPException, Request
from fastapi.responses import FileResponse, Response, StreamingResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from anunnaki.dashboard._app_types import Operator
from anunnaki.dashboard._observer import OPERATIONS, OperatorError
from anunnaki.dashboard._state import DashboardState
from anunnaki.dashboard._token import Throttle
from anunnaki.tokens import token_matches, token_weakness

__all__ = ["OperatorRequest", "create_app", "static_dir"]

_CSP = (
    "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"
)
_OPERATOR_NAME = re.compile(r"[^A-Za-z0-9_.@-]+")


def static_dir() -> Path:
    """The folder of the page's HTML, JS and CSS (shipped inside the package)."""
    return Path(str(resources.files("anunnaki.dashboard").joinpath("static")))


class OperatorRequest(BaseModel):
    """The body of an operator action.

    Attributes:
        tactic: The pending tactic (approve, reject).
        reason: Why (run_stop).
        operator: Who acts; recorded as ``dashboard:<operator>@<client address>``.

    """

    tactic: str | None = Field(default=None, max_length=128)
    reason: str | None = Field(default=None, max_length=500)
    operator: str | None = Field(default=None, max_length=64)


def _finite(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def dumps(obj: Any) -> str:
    """JSON for the page: compact, non-finite floats as ``null``, odd objects as strings."""
    try:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False, default=str)
    except ValueError:
        return json.dumps(_finite(obj), separators=(",", ":"), allow_nan=False, default=str)


def _json(obj: Any, status: int = 200) -> Response:
    return Response(
        dumps(obj),
        status_code=status,
        media_type="application/json",
        headers={"Cache-Control": "no-store"},
    )


def create_app(
    state: DashboardState,
    operator: Operator | None = None,
    *,
    token: str | None = None,
    max_rate: float = 15.0,
    heartbeat: float = 1.0,
    stopping: threading.Event | None = None,
) -> FastAPI:
    """Build the dashboard's FastAPI application.

    Args:
        state: What to show.
        operator: Performs operator actions: a :class:`~anunnaki.dashboard.BusObserver`
            or a :class:`~anunnaki.dashboard.Dashboard` (``None``: no bus, read-only).
        token: Enables operator actions; requests must carry ``Authorization: Bearer
            <token>``. ``None``: read-only.
        max_rate: Most patches per second per page.
        heartbeat: Seconds between patches when nothing changes (``now`` for staleness).
        stopping: Set it to end every open event stream (server shutdown).

    """
    if not max_rate > 0:
        raise ValueError(f"max_rate must be > 0, got {max_rate!r}")
    if token is not None and (weak := token_weakness(token)) is not None:
        raise ValueError(f"the operator token is too weak: {weak}")
    app = FastAPI(title=f"Anunnaki dashboard: {state.name}", docs_url=None, redoc_url=None)
    app.state.dashboard = state
    _add_page(app)
    _add_views(
        app,
        state,
        operator_enabled=token is not None,
        stop=stopping or threading.Event(),
        interval=1.0 / max_rate,
        heartbeat=heartbeat,
    )
    _add_operator(app, operator, token)
    return app


def _add_page(app: FastAPI) -> None:
    """``GET /`` (the page, with its security headers) and ``/static``."""
    folder = static_dir()
    app.mount("/static", StaticFiles(directory=str(folder)), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(
            folder / "index.html",
            media_type="text/html",
            headers={
                "Content-Security-Policy": _CSP,
                "X-Content-Type-Options": "nosniff",
                "Referrer-Policy": "no-referrer",
                "Cache-Control": "no-store",
            },
        )


def _add_views(
    app: FastAPI,
    state: DashboardState,
    *,
    operator_enabled: bool,
    stop: threading.Event,
    interval: float,
    heartbeat: float,
) -> None:
    """The read-only routes: health, snapshot, explain, frames and the event stream."""

    @app.get("/api/health")
    def health() -> Response:
        return _json(
            {
                "ok": True,
                "version": state.version,
                "operator": operator_enabled,
                "name": state.name,
            }
        )

    @app.get("/api/snapshot")
    def snapshot() -> Response:
        return _json(state.snapshot())

    @app.get("/api/explain/{node}")
    def explain(node: str) -> Response:
        out = state.explain(node)
        if out is None:
            raise HTTPException(404, f"no goal or obstacle {node!r} in the goal model")
        return _json(out)

    @app.get("/api/assurance.svg")
    def assurance_svg() -> Response:
        drawing = state.case_drawing
        if drawing is None:
            raise HTTPException(404, "no assurance case: the run has none (docs/assurance.md)")
        return Response(drawing, media_type="image/svg+xml", headers={"Cache-Control": "no-store"})

    @app.get("/api/frame/{seq}")
    def frame(seq: str) -> Response:
        return _frame_response(state, seq)

    @app.get("/api/events")
    async def events() -> StreamingResponse:
        return StreamingResponse(
            _stream(state, stop, interval, heartbeat),
            media_type="text/event-stream",
            headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
        )


def _add_operator(app: FastAPI, operator: Operator | None, token: str | None) -> None:
    """``POST /api/operator/{action}``: authorized by ``token``, failed attempts throttled."""
    throttle = Throttle()

    @app.post("/api/operator/{action}")
    def operate(
        action: str,
        request: Request,
        body: OperatorRequest | None = None,
        authorization: str | None = Header(default=None),
    ) -> Response:
        host = request.client.host if request.client is not None else "unknown"
        performer = _throttled(
            throttle, host, token=token, authorization=authorization, action=action,
            operator=operator,
        )  # fmt: skip
        req = body or OperatorRequest()
        who = _OPERATOR_NAME.sub("", req.operator or "") or "operator"
        caller = f"dashboard:{who}@{host}"
        try:
            reply = performer.operate(action, caller=caller, tactic=req.tactic, reason=req.reason)
        except OperatorError as exc:
            raise HTTPException(502, str(exc)) from None
        return _json({"ok": True, "action": action, "caller": caller, "reply": reply})


def _frame_response(state: DashboardState, seq: str) -> Response:
    """A kept frame's encoded bytes (``seq`` a number or ``latest``), or 400/404."""
    if seq == "latest":
        f = state.frame()
    elif seq.isdigit():
        f = state.frame(int(seq))
    else:
        raise HTTPException(400, "give a frame number or 'latest'")
    if f is None:
        raise HTTPException(404, "no such frame (frames are kept only briefly)")
    return Response(
        f.data,
        media_type=f.media_type,
        headers={"Cache-Control": "no-store", "X-Frame-Seq": str(f.seq)},
    )


def _throttled(
    throttle: Throttle,
    host: str,
    *,
    token: str | None,
    authorization: str | None,
    action: str,
    operator: Operator | None,
) -> Operator:
    """:func:`_authorized`, with failed token attempts counted per client (429 past them)."""
    wait = throttle.wait(host)
    if wait > 0:
        raise HTTPException(
            429,
            "too many failed attempts; try again later",
            headers={"Retry-After": str(math.ceil(wait))},
        )
    try:
        return _authorized(token, authorization, action, operator)
    except HTTPException as exc:
        if exc.status_code == 401:
            throttle.failed(host)
        raise


def _authorized(
    token: str | None, authorization: str | None, action: str, operator: Operator | None
) -> Operator:
    """The operator to perform ``action``, once the request may (else 403/401/404/503)."""
    if token is None:
        raise HTTPException(
            403, "read-only dashboard: operator actions need a server started with --token"
        )
    given = ""
    if authorization and authorization.lower().startswith("bearer "):
        given = authorization[7:].strip()
    if not token_matches(given, token):
        raise HTTPException(401, "missing or wrong token", headers={"WWW-Authenticate": "Bearer"})
    if action not in OPERATIONS:
        raise HTTPException(404, f"unknown action {action!r}; actions: {', '.join(OPERATIONS)}")
    if operator is None:
        raise HTTPException(503, "this dashboard is not connected to a bus")
    return operator


async def _stream(
    state: DashboardState, stop: threading.Event, interval: float, heartbeat: float
) -> AsyncIterator[str]:
    loop = asyncio.get_running_loop()
    wake = asyncio.Event()

    def poke() -> None:
        with contextlib.suppress(RuntimeError):  # the loop is gone: the stream ended
            loop.call_soon_threadsafe(wake.set)

    remove = state.add_listener(poke)
    try:
        snap = state.snapshot()
        version = snap["version"]
        decisions = snap["decisions"][-1]["n"] if snap["decisions"] else 0
        timeline = snap["timeline"][-1]["n"] if snap["timeline"] else 0
        yield f"event: snapshot\nid: {version}\ndata: {dumps(snap)}\n\n"
        last = loop.time()
        while not stop.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(wake.wait(), timeout=min(heartbeat, 0.5))
            wake.clear()
            if stop.is_set():
                break
            if state.version <= version and loop.time() - last < heartbeat:
                continue
            patch = state.delta(version, decisions_after=decisions, timeline_after=timeline)
            version = patch["version"]
            if patch.get("decisions"):
                decisions = patch["decisions"][-1]["n"]
            if patch.get("timeline"):
                timeline = patch["timeline"][-1]["n"]
            yield f"event: patch\nid: {version}\ndata: {dumps(patch)}\n\n"
            last = loop.time()
            await asyncio.sleep(interval)
    finally:
        remove()
