"""The deterministic executor: one thread of delivery, in publication order (issue #30)."""

from __future__ import annotations

import threading

import pytest

from anunnaki.bus import (
    BusConfigError,
    Executor,
    ExecutorOverrun,
    InprocHub,
    open_bus,
)
from anunnaki.messages import ModeReply, ModeRequest


def _bus(ex: Executor, **kwargs: object):
    return open_bus("inproc", executor=ex, **kwargs)


def test_publication_order_across_subscribers_and_hops() -> None:
    ex = Executor()
    seen: list[str] = []
    with _bus(ex) as bus:

        def first(sample):
            seen.append(f"first:{sample.topic}:{sample.message.to_body()['n']}")
            if sample.topic == "/a":
                bus.publish("/b", {"n": sample.message.to_body()["n"] * 10})

        bus.subscribe("/a", first)
        bus.subscribe("/**", lambda s: seen.append(f"all:{s.topic}:{s.message.to_body()['n']}"))
        bus.publish("/a", {"n": 1})
        bus.publish("/a", {"n": 2})
        assert seen == []  # nothing runs before the drain
        assert ex.spin_until_idle() == 6
    # FIFO: each message to its subscribers in declaration order, hops queued behind
    assert seen == [
        "first:/a:1",
        "all:/a:1",
        "first:/a:2",
        "all:/a:2",
        "all:/b:10",
        "all:/b:20",
    ]


def test_no_threads_and_callbacks_on_the_draining_thread() -> None:
    ex = Executor()
    before = threading.active_count()
    threads: set[str] = set()
    with _bus(ex) as bus:
        for k in range(5):
            bus.subscribe(f"/t{k}", lambda s: threads.add(threading.current_thread().name))
        bus.service("/srv", lambda req: None)
        bus.watch_liveliness(lambda node, alive: None)
        assert threading.active_count() == before
        for k in range(5):
            bus.publish(f"/t{k}", {"k": k})
        ex.spin_until_idle()
    assert threads == {threading.current_thread().name}


def test_a_request_in_a_callback_is_answered_in_the_same_drain() -> None:
    ex = Executor()
    order: list[str] = []
    with _bus(ex) as bus:

        def set_mode(req):
            order.append(f"service:{req.mode}")
            return ModeReply(mode=req.mode, accepted=True)

        bus.service("/rover/set_mode", set_mode)

        def on_cmd(sample):
            order.append("callback")
            reply = bus.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=5.0)
            order.append(f"reply:{reply.mode}")

        bus.subscribe("/cmd", on_cmd)
        bus.subscribe("/cmd", lambda s: order.append("second subscriber"))
        bus.publish("/cmd", {})
        ex.spin_until_idle()
    assert order == ["callback", "service:manual", "reply:manual", "second subscriber"]


def test_a_request_from_another_thread_waits_for_the_drain() -> None:
    ex = Executor()
    ex.bind()  # this thread runs the executor
    with _bus(ex) as bus:
        served_on: list[str] = []

        def handler(req):
            served_on.append(threading.current_thread().name)
            return ModeReply(mode=req.mode, accepted=True)

        bus.service("/rover/set_mode", handler)
        replies: list[str] = []
        asked = threading.Event()

        def ask() -> None:
            asked.set()
            reply = bus.request("/rover/set_mode", ModeRequest(mode="manual"), timeout=30)
            replies.append(reply.mode)

        t = threading.Thread(target=ask, name="operator")
        t.start()
        asked.wait(5)
        while t.is_alive():  # the request is queued; this thread's drain answers it
            ex.spin_until_idle()
            t.join(0.01)
    assert replies == ["manual"]
    assert served_on == [threading.current_thread().name]


def test_only_the_bound_thread_drains() -> None:
    ex = Executor()
    ex.spin_until_idle()  # binds this thread
    errors: list[BaseException] = []

    def other() -> None:
        try:
            ex.spin_until_idle()
        except RuntimeError as exc:
            errors.append(exc)

    t = threading.Thread(target=other, name="intruder")
    t.start()
    t.join()
    assert errors and "may only post" in str(errors[0])
    ex.release()
    t = threading.Thread(target=ex.spin_until_idle, name="next-owner")
    t.start()
    t.join()


def test_pull_doorbells_and_idle_hooks_run_in_order() -> None:
    ex = Executor()
    events: list[str] = []
    stepped_at: list[int] = []
    with _bus(ex) as bus:
        sub = bus.subscribe("/in", on_ready=lambda: events.append("doorbell"))
        bus.subscribe("/in", lambda s: events.append("callback"))
        instant = [0]

        def idle() -> bool:  # like Utu's step at the present instant: once per instant
            if stepped_at and stepped_at[-1] == instant[0]:
                return False
            stepped_at.append(instant[0])
            events.append(f"idle:{len(list(iter(sub.try_recv, None)))}")
            bus.publish("/out", {})  # work made by the hook is run before the drain ends
            return True

        ex.on_idle(idle)
        bus.subscribe("/out", lambda s: events.append("out"))
        bus.publish("/in", {})
        ex.spin_until_idle()
        instant[0] = 1
        ex.spin_until_idle()
    assert events == ["doorbell", "callback", "idle:1", "out", "idle:0", "out"]


def test_failures_are_counted_and_a_runaway_drain_stops() -> None:
    ex = Executor(limit=50)
    seen: list[int] = []
    with _bus(ex) as bus:

        def boom(sample):
            raise ValueError("bad")

        bus.subscribe("/x", boom)
        bus.subscribe("/x", lambda s: seen.append(1))
        bus.publish("/x", {})
        ex.spin_until_idle()
        assert seen == [1]
        assert bus.stats().errors == {"/x": 1}
        bus.subscribe("/ping", lambda s: bus.publish("/ping", {}))
        bus.publish("/ping", {})
        with pytest.raises(ExecutorOverrun, match="more than 50"):
            ex.spin_until_idle()


def test_liveliness_on_the_executor() -> None:
    ex = Executor()
    seen: list[tuple[str, bool]] = []
    with _bus(ex) as bus:
        bus.watch_liveliness(lambda node, alive: seen.append((node, alive)))
        token = bus.liveliness_token("/utu_manager")
        ex.spin_until_idle()
        token.close()
        ex.spin_until_idle()
    assert seen == [("/utu_manager", True), ("/utu_manager", False)]


def test_configuration_errors() -> None:
    ex = Executor()
    with pytest.raises(BusConfigError, match="only the inproc bus"):
        open_bus("zenoh", executor=ex)
    with pytest.raises(BusConfigError, match="another executor"):
        open_bus("inproc", hub=InprocHub(executor=Executor()), executor=ex)
    hub = InprocHub(executor=ex)
    with open_bus("inproc", hub=hub) as a, open_bus("inproc", hub=hub) as b:
        assert a.executor is ex and b.executor is ex
    with open_bus("inproc") as plain:
        assert plain.executor is None
    with pytest.raises(ValueError, match="limit"):
        Executor(limit=0)


def test_a_closed_subscriber_gets_nothing_queued_before() -> None:
    ex = Executor()
    seen: list[int] = []
    with _bus(ex) as bus:
        sub = bus.subscribe("/x", lambda s: seen.append(1))
        bus.publish("/x", {})
        sub.close()
        ex.spin_until_idle()
    assert seen == []
    ex.close()
    ex.post(lambda: seen.append(2))
    assert ex.pending == 0
