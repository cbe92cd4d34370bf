"""``anunnaki reload``: swap a running Utu's goal model, binding or tactics, and say what happened.

The files are checked by the running Utu as ``anunnaki check`` does: a broken one is refused
at once (the reply carries the error, exit 1); a good one is accepted and applied at the
next cycle, which this command waits for in the decision log (``reloaded``), in either
deployment (one process, or one process per node).

``--models [REGISTRY.yaml]`` asks the learning model manager (``/lm_manager/reload``)
instead to re-read its model registry (the file it runs with, or REGISTRY.yaml): every
model's and oracle's sha256 is checked and every new model loaded once before the new
registry is taken; newly registered models can then be swapped in. Refused, the old
registry stays (exit 1). The operator token is sent as for Utu.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from anunnaki import topics
from anunnaki.bus import BusConfig, BusError, ServiceError, open_bus
from anunnaki.cli._text import plain
from anunnaki.errors import validation_message
from anunnaki.messages import ServiceReply
from anunnaki.tokens import OPERATOR_TOKEN_ENV, client_operator_token, default_token_file

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Add ``anunnaki reload``."""
    p: argparse.ArgumentParser = sub.add_parser(
        "reload",
        help="swap a running Utu's goal model, binding or tactics (applied or refused)",
        description=plain(__doc__),
    )
    p.add_argument("--goal-model", type=Path, metavar="FILE", help="the new goal model")
    p.add_argument("--binding", type=Path, metavar="FILE", help="the new platform binding")
    p.add_argument("--tactics", type=Path, metavar="FILE", help="the new tactics (XML or YAML)")
    p.add_argument(
        "--models",
        nargs="?",
        const="",
        default=None,
        metavar="REGISTRY.yaml",
        help="ask the model manager to re-read its model registry (the file it runs with, or "
        "REGISTRY.yaml), instead of reloading Utu's files",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        default=None,
        help="zenoh endpoint of the running Utu's bus (default tcp/127.0.0.1:7447)",
    )
    tls = p.add_argument_group(
        "TLS (for tls/ or quic/ endpoints: the operator's certificate, CN operator; bus.md)"
    )
    tls.add_argument("--root-ca", type=Path, metavar="PEM", help="the CA that signed the router")
    tls.add_argument("--cert", type=Path, metavar="PEM", help="this operator's certificate")
    tls.add_argument("--key", type=Path, metavar="PEM", help="the private key of --cert")
    p.add_argument("--namespace", default="anunnaki", help="the bus namespace (default anunnaki)")
    p.add_argument("--caller", default="cli", help="who asks (recorded in the decision log)")
    p.add_argument(
        "--timeout", type=float, default=5.0, help="seconds to wait for each answer (default 5)"
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Ask ``/utu/reload``; wait until the decision log says applied or refused."""
    if args.models is not None:
        return _reload_models(args)
    files = {
        "goal_model": args.goal_model,
        "binding": args.binding,
        "tactics": args.tactics,
    }
    request: dict[str, Any] = {
        k: str(v.resolve()) for k, v in files.items() if v is not None
    }  # the running Utu resolves paths against its own folder: send absolute ones
    if not request:
        print("error: give --goal-model, --binding and/or --tactics", file=sys.stderr)
        return 2
    request["caller"] = args.caller
    config = _client(args, request)
    if config is None:
        return 2
    with open_bus(config) as bus:
        try:
            last = bus.request(
                topics.QUERY, {"what": "decisions", "limit": 1}, timeout=args.timeout
            )
            rows = last.to_body().get("decisions", [])
            after = int(rows[-1]["id"]) if rows else 0
            reply = bus.request(topics.RELOAD, request, timeout=args.timeout).to_body()
            if not reply.get("ok"):
                print(f"refused: {reply.get('error', 'no reason given')}")
                if reply.get("status") == "unauthorised":
                    print(f"hint: {_token_hint(request.get('token'), 'Utu')}", file=sys.stderr)
                return 1
            outcome = _wait_outcome(bus, after, args.timeout)
        except BusError as exc:
            print(f"error: no running Utu answered on {config.connect}: {exc}", file=sys.stderr)
            return 2
    if outcome is None:
        print(f"accepted, but not applied within {args.timeout:g} s (is Utu paused or stuck?)")
        return 1
    kind, data = outcome
    if kind == "reloaded":
        print(f"applied: {', '.join(str(f) for f in data.get('files', [])) or 'files reloaded'}")
        return 0
    print(f"refused: {data.get('error', 'no reason given')}")
    return 1


def _reload_models(args: argparse.Namespace) -> int:
    """Ask ``/lm_manager/reload`` to re-read the model registry; print what it says."""
    if any(getattr(args, k) is not None for k in ("goal_model", "binding", "tactics")):
        print(
            "error: --models reloads the model manager's registry, a request of its own; "
            "reload Utu's files with another command",
            file=sys.stderr,
        )
        return 2
    request: dict[str, Any] = {"caller": args.caller}
    if args.models:  # the running node resolves paths against its own folder: send absolute
        request["registry"] = str(Path(args.models).resolve())
    config = _client(args, request)
    if config is None:
        return 2
    with open_bus(config) as bus:
        try:
            reply = bus.request(topics.RELOAD_MODELS, request, timeout=args.timeout)
        except ServiceError as exc:
            print(f"refused: {exc.error}")
            if exc.error.startswith("unauthorised"):
                print(
                    f"hint: {_token_hint(request.get('token'), 'model manager')}", file=sys.stderr
                )
            return 1
        except BusError as exc:
            print(f"error: no model manager answered on {config.connect}: {exc}", file=sys.stderr)
            return 2
    body: dict[str, Any] = dict(reply.body if isinstance(reply, ServiceReply) else reply.to_body())

    def ids(key: str) -> str:
        listed = body.get(key)
        return ", ".join(map(str, listed)) if isinstance(listed, list) and listed else "none"

    print(
        f"applied: {body.get('registry')}: models {ids('models')} "
        f"(added {ids('added')}; changed {ids('changed')}; removed {ids('removed')}); "
        f"{body.get('active')} keeps running"
    )
    return 0


def _client(args: argparse.Namespace, request: dict[str, Any]) -> BusConfig | None:
    """Put the operator token in ``request``; the session to open (``None``: error printed)."""
    if (token := client_operator_token()) is not None:
        request["token"] = token
    config = _bus_config(args)
    if isinstance(config, str):
        print(f"error: {config}", file=sys.stderr)
        return None
    return config


def _token_hint(sent: str | None, who: str) -> str:
    """Where this command's operator token came from, and how to give the right one.

    ``who`` is ``Utu`` or ``model manager``: the process whose token the request needs.
    """
    where = (
        f"${OPERATOR_TOKEN_ENV}"
        if os.environ.get(OPERATOR_TOKEN_ENV) is not None
        else str(default_token_file())
    )
    said = f"the token in {where}" if sent is not None else f"no token (no {where})"
    return f"this command sent {said}; set ${OPERATOR_TOKEN_ENV} to the running {who}'s token " + (
        "(its operator_token_file, or the file its 'anunnaki run' named)"
        if who == "Utu"
        else f"(its ${OPERATOR_TOKEN_ENV}, else its user's {default_token_file().name} file)"
    )


def _bus_config(args: argparse.Namespace) -> BusConfig | str:
    """The client session this command opens, or what is wrong with the options."""
    connect = args.connect or ["tcp/127.0.0.1:7447"]
    given = {k: getattr(args, k) for k in ("root_ca", "cert", "key")}
    over_tls = [ep for ep in connect if ep.startswith(("tls/", "quic/"))]
    if over_tls and not all(given.values()):
        missing = ", ".join(f"--{k.replace('_', '-')}" for k, v in given.items() if v is None)
        return (
            f"{over_tls[0]} is a TLS endpoint: give the operator's certificate with --root-ca, "
            f"--cert and --key (missing: {missing}; docs/bus.md makes them, CN operator)"
        )
    if any(given.values()) and not over_tls:
        return "--root-ca, --cert and --key are for tls/ or quic/ endpoints (give --connect tls/…)"
    if missing_files := [str(v) for v in given.values() if v is not None and not v.is_file()]:
        return f"no such file: {', '.join(missing_files)}"
    try:
        return BusConfig.model_validate(
            {
                "kind": "zenoh",
                "mode": "client",
                "connect": connect,
                "listen": [],
                "namespace": args.namespace,
                "tls": {k: str(v.resolve()) for k, v in given.items()} if over_tls else None,
            }
        )
    except ValidationError as exc:
        return "; ".join(
            f"{'.'.join(map(str, e['loc']))}: {validation_message(e)}" for e in exc.errors()
        )


def _wait_outcome(bus: Any, after: int, timeout: float) -> tuple[str, dict[str, Any]] | None:
    """The first ``reloaded``/``reload_refused`` decision with an id above ``after``."""
    deadline = time.monotonic() + timeout
    pause = threading.Event()
    while True:
        query = {"what": "decisions", "after": after, "limit": 10_000}
        for d in bus.request(topics.QUERY, query, timeout=timeout).to_body().get("decisions", []):
            after = max(after, int(d.get("id", after)))
            if d.get("kind") in ("reloaded", "reload_refused"):
                return str(d["kind"]), dict(d.get("data") or {})
        if time.monotonic() >= deadline:
            return None
        pause.wait(0.05)
