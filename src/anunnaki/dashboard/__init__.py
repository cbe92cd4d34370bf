"""The dashboard: Utu's GUI (paper §4.1.4, Fig. 14–15; §4.2.3, Fig. 19–20) as a live web page.

One page shows, live, what the autonomic manager believes and why it acts: the
**Knowledge** pane (agents and their utility values), **Monitor** (each agent's topics with
last value, rate and staleness), **Analyze** (violated goals and the tactics that apply),
**Plan** (the priority-sorted queue, pending approvals marked), **Execute** (tactics run and
their postconditions' result), **Oracle** (category, confidence and perceived context per
assessor), the **goal model** as a tree (green satisfied, red unsatisfied, grey unknown; click
a node for its explanation), the **camera feed** with detection boxes and the active model,
a **timeline** of the root goal's utility with the tactics' events, and the **decision log**.

It is an observer: :class:`BusObserver` subscribes the bus topics Utu's nodes use and writes
into a :class:`DashboardState`; :func:`create_app` serves it (FastAPI; server-sent events;
static HTML/JS/CSS, no build step, nothing from a CDN). Operator actions — pause, resume,
approve or reject a pending tactic, run-stop — exist only when the server has a token; they
are calls of Utu's services over the bus, recorded by Utu with their caller::

    from anunnaki.dashboard import Dashboard
    with Dashboard(bus, model, tactics, port=8765, token=secret) as dash:
        print(dash.url)

From the command line: ``anunnaki dashboard CONFIG`` or ``anunnaki run CONFIG --dashboard``
(docs/dashboard.md). The web parts need ``pip install 'anunnaki[dashboard]'``; this module
itself imports neither fastapi nor uvicorn until a server or app is built.
"""

from anunnaki.dashboard._observer import (
    OPERATIONS,
    BusObserver,
    ObserverConfig,
    OperatorError,
    SimTime,
)
from anunnaki.dashboard._server import (
    DEFAULT_PORT,
    Dashboard,
    DashboardError,
    DashboardServer,
    create_app,
)
from anunnaki.dashboard._state import DashboardState, Frame

__all__ = [
    "DEFAULT_PORT",
    "OPERATIONS",
    "BusObserver",
    "Dashboard",
    "DashboardError",
    "DashboardServer",
    "DashboardState",
    "Frame",
    "ObserverConfig",
    "OperatorError",
    "SimTime",
    "create_app",
]
