"""The QoS table (guidelines S1, S2, S4) and the bounded priority queue."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anunnaki.bus import PRIORITIES, QOS_TABLE, BusConfigError, qos_for
from anunnaki.bus._queue import PriorityQueue


@pytest.mark.parametrize(
    ("topic", "mtype", "cls", "priority", "reliable"),
    [
        ("/utu/run_stop", None, "run_stop", "critical", True),
        ("/rover/estop", "RunStop", "run_stop", "critical", True),
        ("/utu/execute/fail_safe", None, "tactic", "high", True),
        ("/rover/mode_request", "ModeRequest", "tactic", "high", True),
        ("/utu/oracle/output", None, "assessment", "high", True),
        ("/utu/oracle/fog/category", None, "assessment", "high", True),
        ("/rover/camera/image", None, "camera", "low", False),
        ("/camera", None, "camera", "low", False),
        ("/utu/oracle/frame", "Image", "camera", "low", False),
        ("/rover/sensors", None, "default", "normal", True),
        ("/rover/sensors", "Generic", "default", "normal", True),
    ],
)
def test_table(topic: str, mtype: str | None, cls: str, priority: str, reliable: bool) -> None:
    qos = qos_for(topic, mtype)
    assert (qos.topic_class, qos.priority, qos.reliable) == (cls, priority, reliable)
    assert qos.congestion == ("block" if reliable else "drop")
    assert qos.express == (priority in ("critical", "high"))


def test_overrides_per_publisher() -> None:
    qos = qos_for("/rover/camera/image", priority="high", reliable=True)
    assert (qos.priority, qos.reliable, qos.topic_class) == ("high", True, "custom")
    assert qos_for("/utu/run_stop", reliable=False).priority == "critical"
    with pytest.raises(BusConfigError, match="priority must be one of"):
        qos_for("/x", priority="urgent")  # type: ignore[arg-type]


def test_table_is_one_place() -> None:
    assert [row.name for row in QOS_TABLE] == ["run_stop", "tactic", "assessment", "camera"]
    assert PRIORITIES == ("critical", "high", "normal", "low")


def test_queue_drop_oldest_and_newest() -> None:
    q: PriorityQueue[int] = PriorityQueue(3, "oldest")
    assert [q.push(i) for i in range(5)] == [None, None, None, 0, 1]
    assert [q.pop(0) for _ in range(3)] == [2, 3, 4]
    q = PriorityQueue(3, "newest")
    assert [q.push(i) for i in range(5)] == [None, None, None, 3, 4]
    assert [q.pop(0) for _ in range(4)] == [0, 1, 2, None]


def test_queue_priorities() -> None:
    q: PriorityQueue[str] = PriorityQueue(3, "oldest")
    q.push("low1", 3)
    q.push("low2", 3)
    q.push("normal", 2)
    assert q.push("critical", 0) == "low1"  # evicts the oldest of the least urgent
    assert q.push("low3", 3) == "low2"  # as urgent as the least urgent: latest value wins
    assert q.push("high", 1) == "low3"
    assert q.push("low4", 3) == "low4"  # less urgent than all queued: refused
    assert [q.pop(0) for _ in range(3)] == ["critical", "high", "normal"]


def test_queue_newest_still_admits_more_urgent() -> None:
    q: PriorityQueue[str] = PriorityQueue(2, "newest")
    q.push("a", 2)
    q.push("b", 2)
    assert q.push("c", 2) == "c"
    assert q.push("stop", 0) == "b"
    assert [q.pop(0), q.pop(0)] == ["stop", "a"]


def test_queue_close_wakes_waiters_and_returns_leftovers() -> None:
    q: PriorityQueue[int] = PriorityQueue(4)
    out: list[object] = []
    waiter = threading.Thread(target=lambda: out.append(q.pop(None)))
    waiter.start()
    q.push(1)
    waiter.join(5)
    assert out == [1]
    q.push(2)
    waiter = threading.Thread(target=lambda: out.append(q.pop(None)))
    assert q.close() == [2]
    waiter.start()
    waiter.join(5)
    assert out == [1, None]
    assert q.push(3) == 3  # a closed queue takes nothing


def test_queue_rejects_bad_options() -> None:
    with pytest.raises(ValueError):
        PriorityQueue(0)
    with pytest.raises(ValueError):
        PriorityQueue(1, "random")  # type: ignore[arg-type]


@given(
    st.integers(1, 8),
    st.sampled_from(["oldest", "newest"]),
    st.lists(st.tuples(st.booleans(), st.integers(0, 3)), max_size=60),
)
def test_queue_invariants(bound: int, drop: str, ops: list[tuple[bool, int]]) -> None:
    """Length never exceeds the bound; nothing is lost unaccounted; urgent goes first."""
    q: PriorityQueue[tuple[int, int]] = PriorityQueue(bound, drop)  # type: ignore[arg-type]
    pushed = dropped = popped = 0
    for n, (is_push, rank) in enumerate(ops):
        if is_push:
            pushed += 1
            victim = q.push((rank, n), rank)
            if victim is not None:
                dropped += 1
                # A victim is never more urgent than anything left in the queue.
                assert all(victim[0] >= r for r, _ in list_items(q))
        else:
            item = q.pop(0)
            if item is not None:
                popped += 1
                assert all(item[0] <= r for r, _ in list_items(q))
        assert len(q) <= bound
        assert q.high_water <= bound
        assert pushed == dropped + popped + len(q)


def list_items(q: PriorityQueue[tuple[int, int]]) -> list[tuple[int, int]]:
    return [item for lane in q._lanes for item in lane]
