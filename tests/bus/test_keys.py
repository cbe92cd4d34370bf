"""Names and keys: the ROS <-> zenoh mapping, validation, and wildcard matching."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from anunnaki.bus import (
    TopicNameError,
    key_matches,
    key_to_ros,
    node_key,
    ros_to_key,
    service_key,
    validate_name,
    validate_pattern,
)

segment = st.from_regex(r"[A-Za-z0-9_]{1,6}", fullmatch=True)
names = st.lists(segment, min_size=1, max_size=5).map(lambda s: "/" + "/".join(s))
namespaces = st.lists(segment, min_size=1, max_size=3).map("/".join)


def test_documented_mapping() -> None:
    assert ros_to_key("/utu/oracle/output") == "anunnaki/utu/oracle/output"
    assert key_to_ros("anunnaki/utu/oracle/output") == "/utu/oracle/output"
    assert ros_to_key("rover/mode", "lab/rover1") == "lab/rover1/rover/mode"
    assert ros_to_key("/utu/**", pattern=True) == "anunnaki/utu/**"
    assert key_to_ros("anunnaki/utu/**") == "/utu/**"
    assert service_key("/lm_manager/swap_model") == "anunnaki/srv/lm_manager/swap_model"
    assert node_key("utu_monitor") == "anunnaki/node/utu_monitor"


@given(names.filter(lambda n: not n.startswith("/srv/") and n != "/srv"), namespaces)
def test_mapping_roundtrips(name: str, namespace: str) -> None:
    key = ros_to_key(name, namespace)
    assert not key.startswith("/")
    assert key_to_ros(key, namespace) == name


@pytest.mark.parametrize(
    ("name", "fragment"),
    [
        ("", "empty name"),
        ("/", "empty name"),
        ("//a", "empty segment"),
        ("/a/", "empty segment"),
        ("/a b", "contains ' '"),
        ("/a-b", "contains '-'"),
        ("/caf\u00e9", "contains"),
        ("/a/*", "wildcard '*'"),
        ("/a/**", "wildcard '**'"),
        ("/srv/x", "reserved for services"),
        (42, "not a string"),
    ],
)
def test_bad_topic_names_say_name_and_rule(name: object, fragment: str) -> None:
    with pytest.raises(TopicNameError) as info:
        validate_name(name)  # type: ignore[arg-type]
    text = str(info.value)
    assert fragment in text
    assert repr(name) in text
    assert "rule:" in text
    assert isinstance(info.value, ValueError)


def test_service_and_node_names_may_start_with_srv() -> None:
    assert validate_name("/srv/x", "service") == "/srv/x"
    assert validate_name("srv", "node") == "/srv"


@pytest.mark.parametrize(
    ("pattern", "canonical"),
    [
        ("/a/**/**/b", "/a/**/b"),
        ("/a/**/*", "/a/*/**"),
        ("/**/*/**", "/*/**"),
        ("/**/*/*", "/*/*/**"),
        ("/*/camera/**", "/*/camera/**"),
    ],
)
def test_patterns_are_canonical(pattern: str, canonical: str) -> None:
    assert validate_pattern(pattern) == canonical


def test_bad_patterns() -> None:
    for bad in ("/a/b*", "/a/***", "/a//**", "/a/$*"):
        with pytest.raises(TopicNameError, match="rule:"):
            validate_pattern(bad)


def test_key_to_ros_outside_namespace() -> None:
    with pytest.raises(TopicNameError, match="not under the namespace"):
        key_to_ros("other/utu/x")
    with pytest.raises(TopicNameError, match="namespace"):
        ros_to_key("/a", "/anunnaki")


def test_key_matches_examples() -> None:
    assert key_matches("ns/utu/**", "ns/utu")
    assert key_matches("ns/utu/**", "ns/utu/a/b")
    assert key_matches("ns/*/output", "ns/oracle/output")
    assert not key_matches("ns/*/output", "ns/output")
    assert not key_matches("ns/*", "ns/a/b")
    assert key_matches("ns/**/camera/**", "ns/camera")
    assert not key_matches("ns/a", "ns/a/b")


chunk = st.sampled_from(["a", "b", "camera", "x1"])
pattern_chunk = st.sampled_from(["a", "b", "camera", "x1", "*", "**"])


@given(
    st.lists(pattern_chunk, min_size=1, max_size=5),
    st.lists(chunk, min_size=1, max_size=6),
)
def test_key_matches_agrees_with_zenoh(pattern: list[str], key: list[str]) -> None:
    zenoh = pytest.importorskip("zenoh")
    canonical = "ns" + validate_pattern("/" + "/".join(pattern))
    concrete = "ns/" + "/".join(key)
    expected = zenoh.KeyExpr(canonical).intersects(zenoh.KeyExpr(concrete))
    assert key_matches(canonical, concrete) == expected


def test_docstring_examples() -> None:
    import doctest

    import anunnaki.bus._keys as keys

    result = doctest.testmod(keys)
    assert result.attempted >= 4
    assert result.failed == 0
