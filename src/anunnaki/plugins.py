"""One plugin mechanism for every slot: phenomena, oracles, detectors, managed systems and more.

Every plugin slot in Anunnaki takes a *name* or an *object* (``"fog"`` or ``Fog()``), the
way pyribs' rankers do. A :class:`Registry` maps names to *factories* (a class, or any
callable that builds the plugin) for one slot; it is generic in what the slot holds, so
the same code serves every slot and one contract holds everywhere:

* **built-ins** are registered by the package that owns the slot, either as objects or
  lazily as ``"module:attribute"`` strings, so a slot whose plugins need a heavy extra
  (``sim`` needs pybullet, a detector needs torch) costs nothing until one is asked for;
* **third parties** add plugins through an ``importlib.metadata`` entry-point group
  (``anunnaki.phenomena``, ``anunnaki.oracles``, ``anunnaki.detectors``,
  ``anunnaki.managed``, …), loaded on the first lookup of a name that is not registered
  otherwise (or when the names are listed), so looking up a built-in imports no plugin;
  so do Anunnaki's own packages above a slot (Enlil's learned oracle registers in
  ``anunnaki.oracles`` by an entry point in ``pyproject.toml``: a slot never names a
  module of a package above it). One that fails to import or fails the slot's check is
  logged and skipped, so a broken plugin never takes the others
  down, and none can shadow a built-in or an explicitly registered name;
* **an unknown name** raises the slot's error type with the valid names listed.

A slot's *check* validates a factory when it is registered (for a class: abstract
methods, required hooks); optional hooks are typed :class:`~typing.Protocol` classes that
the caller tests with ``isinstance``, never found by signature inspection.

**One rule for names**, in every slot (:data:`NAME_RULE`, :func:`check_name`): a name is
an ASCII identifier, a letter or ``_`` followed by letters, digits or ``_`` (``fog``,
``ground_truth``, ``ModeRequest``). No ``.`` (compositions prefix parameters with
``fog.``), no ``+`` (it combines names), no ``-`` or spaces. A factory's name is its
``name`` attribute unless the slot says otherwise (``key``; message types use their type
name).

A slot is a module-level constant, ``SLOT: Registry[Kind] = Registry(...)``; callers use
its methods (``create``, ``factory``, ``names``, ``register``), there are no per-slot
``get_``/``register_``/``available_`` functions.

Example::

    SEARCHES: Registry[Search] = Registry("search strategy", group="anunnaki.searches")
    SEARCHES.register(RandomSearch)                       # under RandomSearch.name
    SEARCHES.register_lazy("enlil", "anunnaki.enlil._search:EnlilSearch")
    search = SEARCHES.create("random", budget=100)        # or pass an instance through
"""

from __future__ import annotations

import importlib
import inspect
import logging
import re
import threading
from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar, cast

from anunnaki.errors import AnunnakiError

__all__ = ["NAME_RULE", "PluginError", "Registry", "check_name"]

log = logging.getLogger("anunnaki.plugins")

T = TypeVar("T")
F = TypeVar("F", bound=Callable[..., Any])

#: The one rule every plugin name follows, in every slot (as written in error messages).
NAME_RULE = "a letter or '_', then letters, digits or '_' (an identifier such as 'fog')"

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class PluginError(AnunnakiError):
    """A plugin is unknown, malformed, or cannot be loaded."""


def check_name(name: object, *, what: str, error: type[AnunnakiError] = PluginError) -> str:
    """Return ``name`` if it follows :data:`NAME_RULE`, else raise ``error`` saying the rule."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise error(f"a {what} name must be an identifier: {NAME_RULE}; got {name!r}")
    return name


def _load_ref(ref: str) -> Any:
    """Import ``"package.module:attribute"``."""
    module, _, attr = ref.partition(":")
    obj: Any = importlib.import_module(module)
    for part in attr.split(".") if attr else []:
        obj = getattr(obj, part)
    return obj


class Registry(Generic[T]):
    """Names → factories of one plugin slot.

    Args:
        what: The slot's name in messages, e.g. ``"phenomenon"``, ``"managed system"``.
        group: Entry-point group third parties register under; ``None`` disables plugins.
        kind: The plugin type; ``create`` passes instances of it through unchanged
            (``None``: nothing passes through, every argument must be a name).
        check: Validates a factory at registration, raising ``error`` with what to fix;
            returns the factory (possibly normalised).
        error: The exception type raised (a subclass of :class:`AnunnakiError`).
        hint: Appended to the unknown-name message (e.g. how to combine names).
        logger: Where skipped entry points are reported (the slot's own logger).
        combine: For slots whose names combine (``"fog+raindrop"``): builds one plugin from
            the plugins the parts of a name that contains ``separator`` name (each part a
            name of this registry, built by it).
        separator: What joins the parts of a combined name (``"+"``).
        key: The name a factory registers under when none is given (default: its ``name``
            attribute, or a function's ``__name__``); e.g. message types use their type name.

    """

    def __init__(
        self,
        what: str,
        *,
        group: str | None = None,
        kind: type[T] | tuple[type, ...] | None = None,
        check: Callable[[Any], Any] | None = None,
        error: type[AnunnakiError] = PluginError,
        hint: str | None = None,
        logger: str = "anunnaki.plugins",
        combine: Callable[[list[T]], T] | None = None,
        separator: str = "+",
        key: Callable[[Any], object] | None = None,
    ) -> None:
        self.what = what
        self._log = logging.getLogger(logger)
        self.group = group
        self.kind = kind
        self.error = error
        self.hint = hint
        self._check = check
        self._combine = combine
        self.separator = separator
        self._key = key
        self._factories: dict[str, Callable[..., T]] = {}
        self._lazy: dict[str, str] = {}
        self._plugins: set[str] = set()  # the names that came from entry points
        self._plugins_loaded = group is None
        self._lock = threading.RLock()

    # -- registration -----------------------------------------------------------------------
    def _name_of(self, factory: Any, name: str | None) -> str:
        found: object = name
        if found is None and self._key is not None:
            found = self._key(factory)
        elif found is None:
            found = getattr(factory, "name", None)
            if not isinstance(found, str) and not inspect.isclass(factory):
                found = getattr(factory, "__name__", None)
        return check_name(found, what=self.what, error=self.error)

    def _validate(self, factory: Any) -> Callable[..., T]:
        if self._check is not None:  # the slot's own rules first: it knows what it needs
            factory = self._check(factory)
        if not callable(factory):
            raise self.error(f"{_a(self.what)} must be a class or a factory, got {factory!r}")
        if inspect.isclass(factory) and inspect.isabstract(factory):
            missing = ", ".join(sorted(getattr(factory, "__abstractmethods__", ())))
            raise self.error(f"{factory.__name__} is abstract; implement {missing}")
        return cast(Callable[..., T], factory)

    def register(self, factory: F, *, name: str | None = None, replace: bool = False) -> F:
        """Register a class or factory under ``name`` (default: its ``name`` attribute).

        Usable as a class decorator. Raises the slot's error when the factory fails the
        slot's check, or when another factory has the name and ``replace`` is false.
        """
        checked = self._validate(factory)
        key = self._name_of(checked, name)
        with self._lock:
            current = self._factories.get(key)
            if current is not None and current is not checked and not replace:
                raise self.error(
                    f"a different {self.what} is already registered as {key!r} "
                    f"({_describe(current)}); pass replace=True to override it"
                )
            if key in self._lazy and not replace:
                raise self.error(
                    f"{key!r} is already registered as a {self.what} ({self._lazy[key]}); "
                    "pass replace=True to override it"
                )
            self._lazy.pop(key, None)
            self._factories[key] = checked
        return factory

    def register_lazy(self, name: str, ref: str) -> None:
        """Register ``"module:attribute"`` under ``name``, imported on first use."""
        key = check_name(name, what=self.what, error=self.error)
        with self._lock:
            if key in self._factories or key in self._lazy:
                raise self.error(f"{key!r} is already registered as a {self.what}")
            self._lazy[key] = ref

    def copy(self, *, entry_points: bool = True) -> Registry[T]:
        """A private registry of the same slot, as a fresh process would have it.

        It has the same rules and what was registered explicitly (built-ins included);
        later registrations in either do not reach the other. Entry points are loaded anew
        on its first need (``entry_points=False``: never, for tests that must not see
        installed plugins).
        """
        other: Registry[T] = Registry(
            self.what,
            group=self.group if entry_points else None,
            kind=self.kind,
            check=self._check,
            error=self.error,
            hint=self.hint,
            logger=self._log.name,
            combine=self._combine,
            separator=self.separator,
            key=self._key,
        )
        with self._lock:
            other._factories = {k: f for k, f in self._factories.items() if k not in self._plugins}
            other._lazy = dict(self._lazy)
        return other

    def unregister(self, name: str) -> None:
        """Forget ``name`` (tests, or a plugin withdrawn at run time)."""
        with self._lock:
            self._factories.pop(name, None)
            self._lazy.pop(name, None)
            self._plugins.discard(name)

    def load_entry_points(self, *, force: bool = False) -> None:
        """Load the entry-point group's plugins (once, unless ``force``); skip broken ones."""
        with self._lock:
            if self.group is None or (self._plugins_loaded and not force):
                return
            self._plugins_loaded = True
            for ep in entry_points(group=self.group):
                try:
                    factory = self._validate(ep.load())
                    key = self._name_of(factory, None if inspect.isclass(factory) else ep.name)
                except Exception as exc:  # a broken plugin must not break the lookup
                    self._log.warning(
                        "skipping %s entry point %r (%s): %s: %s",
                        self.what,
                        ep.name,
                        ep.value,
                        type(exc).__name__,
                        exc,
                    )
                    continue
                current = self._factories.get(key)
                if (current is not None and current is not factory) or key in self._lazy:
                    self._log.warning(
                        "skipping %s entry point %r (%s): the name %r is already taken",
                        self.what,
                        ep.name,
                        ep.value,
                        key,
                    )
                    continue
                if ep.name != key:
                    self._log.warning(
                        "%s entry point %r (%s) registers as %r, its own name",
                        self.what,
                        ep.name,
                        ep.value,
                        key,
                    )
                self._factories[key] = factory
                self._plugins.add(key)

    # -- lookup -----------------------------------------------------------------------------
    def names(self) -> list[str]:
        """The sorted names of every registered plugin (entry points included)."""
        self.load_entry_points()
        with self._lock:
            return sorted({*self._factories, *self._lazy})

    def _registered(self, key: str) -> bool:
        with self._lock:
            return key in self._factories or key in self._lazy

    def __contains__(self, name: object) -> bool:
        if not isinstance(name, str):
            return False
        parts = [name]
        if self._combine is not None and self.separator in name:
            parts = name.split(self.separator)
        keys = [part.strip() for part in parts]
        if all(self._registered(key) for key in keys):  # no entry point is loaded for these
            return True
        names = self.names()
        return all(key in names for key in keys)

    def offers(self, name: str) -> bool:
        """Whether ``name`` is registered or an installed plugin's entry point, importing none.

        For checks of a configuration before a run (``anunnaki check``): ``in`` imports every
        plugin of the group to know their names, and a plugin may pull in a heavy framework
        (Enlil's oracle, torch). An entry point's name is its plugin's name (the registry
        warns when they differ), so this is the answer ``in`` gives, short of a plugin that
        fails to import; :meth:`factory` then says why.
        """
        key = name.strip()
        if self._registered(key):
            return True
        with self._lock:
            if self._plugins_loaded:
                return False
        return self.group is not None and any(
            ep.name == key for ep in entry_points(group=self.group)
        )

    def unknown(self, name: object) -> AnunnakiError:
        """The error for an unknown name: it lists the valid ones."""
        valid = ", ".join(self.names()) or "none registered"
        text = f"unknown {self.what} {name!r}; valid names: {valid}"
        if self.hint:
            text += f" ({self.hint})"
        return self.error(text)

    def factory(self, name: str) -> Callable[..., T]:
        """The class or factory registered as ``name``.

        Raises the slot's error for an unknown name (listing the valid ones) or a lazy
        built-in that cannot be imported (naming the extra to install when the import
        error says so). The entry points are loaded only for a name not registered
        otherwise: looking up a built-in imports no plugin.
        """
        if not isinstance(name, str):
            raise self.error(f"expected a {self.what} name, got {type(name).__name__}")
        key = name.strip()
        found = self._factories.get(key)  # the hot path (a decoder per message): no lock
        if found is not None:
            return found
        if not self._registered(key):
            self.load_entry_points()
        with self._lock:
            found = self._factories.get(key)
            ref = self._lazy.get(key)
        if found is not None:
            return found
        if ref is None:
            raise self.unknown(name)
        try:
            loaded = self._validate(_load_ref(ref))
        except AnunnakiError:
            raise
        except ImportError as exc:
            raise self.error(f"the {self.what} {key!r} cannot be loaded: {exc}") from exc
        with self._lock:
            self._lazy.pop(key, None)
            self._factories[key] = loaded
        return loaded

    def create(self, spec: str | T, /, **kwargs: Any) -> T:
        """An instance for a name (built with ``kwargs``), or the instance itself.

        A name with the slot's ``separator`` is built by its ``combine`` hook, when it has
        one. Raises the slot's error for an unknown name, for keyword options the factory
        does not take, for options given with an instance (configure it yourself), or for
        an argument that is neither a name nor an instance of the slot's kind (a class is
        not an instance, even when it has the attributes a Protocol asks for).
        """
        if isinstance(spec, str):
            if self._combine is not None and self.separator in spec:
                if kwargs:
                    raise self.error(
                        f"options {sorted(kwargs)} apply to a single {self.what}, "
                        f"not to the combination {spec.strip()!r}"
                    )
                parts = [self.create(part.strip()) for part in spec.split(self.separator)]
                return self._combine(parts)
            factory = self.factory(spec)
            if not kwargs:
                return factory()
            try:
                return factory(**kwargs)
            except TypeError as exc:
                raise self.error(
                    f"{self.what} {spec.strip()!r}: bad options {sorted(kwargs)}: {exc}"
                ) from None
        if self.kind is not None and not inspect.isclass(spec) and isinstance(spec, self.kind):
            if kwargs:
                raise self.error(
                    f"options {sorted(kwargs)} apply when {_a(self.what)} is built by name; "
                    "configure the instance yourself"
                )
            return spec
        kind = _a(self.kind.__name__) if isinstance(self.kind, type) else "an"
        got = f"the class {spec.__name__}" if inspect.isclass(spec) else type(spec).__name__
        raise self.error(
            f"expected {_a(self.what)} name or {kind} instance, got {got}; "
            f"valid names: {', '.join(self.names())}"
        )


def _a(noun: str) -> str:
    return f"{'an' if noun[:1].lower() in 'aeiou' else 'a'} {noun}"


def _describe(obj: Any) -> str:
    module = getattr(obj, "__module__", "?")
    return f"{module}.{getattr(obj, '__qualname__', repr(obj))}"
