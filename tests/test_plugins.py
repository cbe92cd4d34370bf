"""The generic plugin registry: names or objects, lazy built-ins, entry points, errors."""

from __future__ import annotations

import abc
import logging
import re
from importlib.metadata import EntryPoint
from typing import Any, Protocol, runtime_checkable

import pytest

from anunnaki import plugins
from anunnaki.errors import AnunnakiError
from anunnaki.plugins import NAME_RULE, PluginError, Registry, check_name


class Widget:
    name = "widget"

    def __init__(self, size: int = 1) -> None:
        self.size = size


class Gadget(Widget):
    name = "gadget"


class Abstract(abc.ABC):
    name = "abstract"

    @abc.abstractmethod
    def go(self) -> None: ...


class SlotError(AnunnakiError):
    pass


def test_register_and_create_by_name_or_instance() -> None:
    reg: Registry[Widget] = Registry("widget", kind=Widget)
    reg.register(Widget)
    reg.register(Gadget)
    made = reg.create("widget", size=3)
    assert isinstance(made, Widget) and made.size == 3
    g = Gadget()
    assert reg.create(g) is g
    assert reg.names() == ["gadget", "widget"]
    assert "gadget" in reg and "nope" not in reg


def test_unknown_name_lists_the_valid_ones_in_the_slot_error() -> None:
    reg: Registry[Widget] = Registry("widget", kind=Widget, error=SlotError, hint="try 'widget'")
    reg.register(Widget)
    with pytest.raises(SlotError, match=r"unknown widget 'wodget'; valid names: widget \(try"):
        reg.create("wodget")
    with pytest.raises(SlotError, match="expected a widget name or a Widget instance, got int"):
        reg.create(3)  # type: ignore[arg-type]


def test_checks_at_registration() -> None:
    def must_be_gadget(cls: Any) -> Any:
        if cls is not Gadget:
            raise SlotError(f"{cls.__name__} is not a gadget")
        return cls

    reg: Registry[Widget] = Registry("widget", check=must_be_gadget, error=SlotError)
    with pytest.raises(SlotError, match="Widget is not a gadget"):  # the slot's rules first
        reg.register(Widget)
    with pytest.raises(SlotError, match="name must be an identifier"):
        reg.register(Gadget, name="two words")
    plain: Registry[Any] = Registry("widget", error=SlotError)
    with pytest.raises(SlotError, match="Abstract is abstract; implement go"):
        plain.register(Abstract)
    with pytest.raises(SlotError, match="a widget must be a class or a factory"):
        plain.register(42)


def test_a_name_is_taken_once_unless_replaced() -> None:
    reg: Registry[Widget] = Registry("widget")
    reg.register(Widget)
    reg.register(Widget)  # the same class again is harmless

    class Other(Widget):
        name = "widget"

    with pytest.raises(PluginError, match="already registered as 'widget'"):
        reg.register(Other)
    reg.register(Other, replace=True)
    assert reg.factory("widget") is Other


def test_factories_register_under_their_function_name() -> None:
    reg: Registry[Widget] = Registry("widget")

    def big_widget() -> Widget:
        return Widget(size=10)

    reg.register(big_widget)
    reg.register(lambda: Widget(2), name="small")
    assert reg.create("big_widget").size == 10
    assert reg.create("small").size == 2


def test_lazy_builtins_import_on_first_use() -> None:
    reg: Registry[Any] = Registry("thing")
    reg.register_lazy("ordered", "collections:OrderedDict")
    reg.register_lazy("broken", "anunnaki_no_such_module:Thing")
    assert reg.names() == ["broken", "ordered"]
    assert reg.create("ordered") == {}
    with pytest.raises(PluginError, match="the thing 'broken' cannot be loaded: No module"):
        reg.factory("broken")
    with pytest.raises(PluginError, match="already registered"):
        reg.register_lazy("ordered", "collections:OrderedDict")


def test_entry_points_load_lazily_and_broken_ones_are_skipped(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    eps = [
        EntryPoint("gadget", f"{__name__}:Gadget", "anunnaki.test"),
        EntryPoint("missing", "anunnaki_no_such_module:Thing", "anunnaki.test"),
        EntryPoint("clash", f"{__name__}:Widget", "anunnaki.test"),
    ]
    calls: list[str] = []

    def fake_entry_points(*, group: str) -> list[EntryPoint]:
        calls.append(group)
        return [ep for ep in eps if ep.group == group]

    monkeypatch.setattr(plugins, "entry_points", fake_entry_points)

    class Builtin(Widget):
        name = "widget"

    reg: Registry[Widget] = Registry("widget", group="anunnaki.test", kind=Widget)
    reg.register(Builtin)
    assert calls == []  # nothing loaded before the first lookup
    assert reg.factory("widget") is Builtin and "widget" in reg
    assert calls == []  # nor by looking up a built-in: no plugin is imported for it
    with caplog.at_level(logging.WARNING, logger="anunnaki.plugins"):
        assert reg.names() == ["gadget", "widget"]
    assert calls == ["anunnaki.test"]
    assert reg.factory("widget") is Builtin  # a plugin cannot shadow a built-in
    assert "skipping widget entry point 'missing'" in caplog.text
    assert "skipping widget entry point 'clash'" in caplog.text
    reg.names()
    assert calls == ["anunnaki.test"]  # once


def test_offers_tells_a_plugins_name_without_importing_it(monkeypatch: pytest.MonkeyPatch) -> None:
    eps = [EntryPoint("gadget", "anunnaki_no_such_module:Gadget", "anunnaki.test")]
    monkeypatch.setattr(
        plugins, "entry_points", lambda *, group: [e for e in eps if e.group == group]
    )
    reg: Registry[Widget] = Registry("widget", group="anunnaki.test")
    reg.register(Widget)
    reg.register_lazy("lazy", "anunnaki_no_such_module:Lazy")
    # built-ins, lazy ones and installed plugins by their entry point, none imported
    assert reg.offers("widget") and reg.offers("lazy") and reg.offers("gadget")
    assert not reg.offers("gizmo")
    # 'in' imports the plugins to know their names: the broken one is skipped
    assert "gadget" not in reg
    assert not reg.offers("gadget")  # once they are loaded, what loaded is the answer
    assert not Registry("widget").offers("gadget")  # no group: no plugins


def test_combined_names_use_the_slots_combine_hook() -> None:
    built: list[list[str]] = []

    def combine(parts: list[Widget]) -> Widget:  # the plugins the parts name, built
        built.append([p.name for p in parts])
        return Widget(size=sum(p.size for p in parts))

    reg: Registry[Widget] = Registry("widget", kind=Widget, combine=combine, separator="+")
    reg.register(Widget)
    reg.register(Gadget)
    assert reg.create(" widget + gadget ").size == 2
    assert built == [["widget", "gadget"]]
    assert "widget+gadget" in reg and "widget+nope" not in reg
    with pytest.raises(PluginError, match="unknown widget 'nope'"):
        reg.create("widget+nope")
    with pytest.raises(PluginError, match=r"options \['size'\] apply to a single widget"):
        reg.create("widget+gadget", size=3)
    plain: Registry[Widget] = Registry("widget")
    plain.register(Widget)
    assert "widget+widget" not in plain  # no hook: '+' is just an unknown name


def test_options_are_checked_where_they_apply() -> None:
    reg: Registry[Widget] = Registry("widget", kind=Widget)
    reg.register(Widget)
    with pytest.raises(PluginError, match=r"widget 'widget': bad options \['colour'\]"):
        reg.create("widget", colour="red")
    with pytest.raises(PluginError, match="apply when a widget is built by name"):
        reg.create(Widget(), size=2)


def test_a_class_is_not_an_instance_of_a_protocol_kind() -> None:
    @runtime_checkable
    class Sized(Protocol):
        name: str

        def size_of(self) -> int: ...

    class Box:
        name = "box"

        def size_of(self) -> int:
            return 1

    reg: Registry[Sized] = Registry("sized thing", kind=Sized)
    reg.register(Box)
    box = Box()
    assert reg.create(box) is box
    with pytest.raises(
        PluginError, match="expected a sized thing name or a Sized instance, got the class Box"
    ):
        reg.create(Box)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "bad", ["two words", "fog.dense", "fog+rain", "heavy-fog", "1st", "", None]
)
def test_one_name_rule_for_every_slot_and_the_error_says_it(bad: object) -> None:
    with pytest.raises(SlotError, match="widget name must be an identifier") as info:
        check_name(bad, what="widget", error=SlotError)
    assert NAME_RULE in str(info.value) and repr(bad) in str(info.value)
    reg: Registry[Widget] = Registry("widget", error=SlotError)
    if isinstance(bad, str):
        with pytest.raises(SlotError, match=re.escape(NAME_RULE)):
            reg.register(Widget, name=bad)
        with pytest.raises(SlotError, match=re.escape(NAME_RULE)):
            reg.register_lazy(bad, "collections:OrderedDict")
    for good in ("fog", "ground_truth", "ModeRequest", "_private", "ros1"):
        assert check_name(good, what="widget") == good


def test_key_names_a_factory_and_copy_is_private() -> None:
    reg: Registry[Widget] = Registry("widget", key=lambda cls: cls.__name__.lower() + "_kind")
    reg.register(Gadget)
    assert reg.names() == ["gadget_kind"]
    private = reg.copy()
    private.register(Widget)
    assert private.names() == ["gadget_kind", "widget_kind"]
    assert reg.names() == ["gadget_kind"]  # the copy's registrations stay in the copy
