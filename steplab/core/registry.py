"""Registries: one kind for everything pluggable, each with the entry points of its group.

Integrators, forces, collision detectors, collision methods, broadphase methods, engines,
scenes and studies each have one :class:`Registry`; a distribution adds to one by declaring
entry points of the group ``steplab.<kind>`` in its ``pyproject.toml``::

    [project.entry-points."steplab.integrators"]
    ralston = "my_methods.ralston:Ralston"

A registry holds steplab's own entries, then the entry points of its group, read with
:mod:`importlib.metadata` once, the first time the registry is read (so importing
steplab imports no plugin). A plugin that fails to import, names the wrong kind of
object or takes a name already taken is skipped with one :class:`PluginWarning` line
naming the plugin and its error; steplab's own entries never depend on a plugin. At run
time ``REGISTRY.register(obj)`` (also a class decorator) adds an entry with the same
checks, and ``REGISTRY.lookup(name)`` fails in one style: one line with the unknown name
and the known ones (:class:`UnknownNameError`).

This module is in :mod:`steplab.core`, the lowest layer, and imports nothing of steplab.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable, Iterable, Iterator, MutableMapping
from importlib import metadata

#: the entry-point groups steplab reads, one per registry
GROUPS = ("steplab.integrators", "steplab.forces", "steplab.detectors", "steplab.collision_methods",
          "steplab.broadphase", "steplab.engines", "steplab.scenes", "steplab.studies")
#: where steplab's own entries come from, as ``steplab integrators`` shows it
BUILTIN = "steplab"


class PluginError(ValueError):
    """A plugin or a ``package.module:Name`` reference that cannot be used; one line."""


class PluginWarning(UserWarning):
    """A plugin that was skipped: the message names the plugin and why."""


class UnknownNameError(KeyError, ValueError):
    """A name no registry entry has: one line with the name and the known names.

    Both a KeyError (a registry reads like a dict) and a ValueError (bad input, exit
    status 2 at the command line).
    """

    def __str__(self):
        return self.args[0]


def import_object(reference: str):
    """The object named by ``"package.module:Name"`` (``Name`` may be dotted: ``Outer.Inner``).

    Raises
    ------
    PluginError
        One line: the reference is malformed, its module cannot be imported (missing, or
        its import raised) or has no such attribute.
    """
    module_name, _, attribute = str(reference).partition(":")
    if not module_name or not attribute or ":" in attribute:
        raise PluginError(f"{reference!r} is not of the form package.module:Name")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name is not None and (module_name == err.name or module_name.startswith(err.name + ".")):
            raise PluginError(f"{reference!r}: no module named {err.name!r} (is it installed, or on "
                              "sys.path / PYTHONPATH?)") from None
        raise PluginError(f"{reference!r}: importing {module_name} failed: {_one_line(err)}") from None
    except Exception as err:  # any error inside the plugin's own import
        raise PluginError(f"{reference!r}: importing {module_name} failed: {_one_line(err)}") from None
    value = module
    for part in attribute.split("."):
        try:
            value = getattr(value, part)
        except AttributeError:
            raise PluginError(f"{reference!r}: module {module_name} has no attribute {attribute!r}") from None
    return value


def entry_point_origin(entry_point: metadata.EntryPoint) -> str:
    """Where an entry point comes from: ``"fake-plugin 0.1 (ralston = fake_mod:Ralston)"``."""
    dist = getattr(entry_point, "dist", None)
    where = f"{dist.name} {dist.version}" if dist is not None else "an unnamed distribution"
    return f"{where} ({entry_point.name} = {entry_point.value})"


def function_entry(signature: str) -> Callable[[object], tuple[str | None, object]]:
    """The ``accept`` of a registry of functions: any callable, named by ``register(name=...)`` or
    its entry point (``signature`` says what it must be, for the message)."""

    def accept(obj):
        if not callable(obj):
            raise PluginError(f"{obj!r} is not a function {signature}")
        return getattr(obj, "name", None), obj

    return accept


class Registry(MutableMapping):
    """Name -> entry: steplab's own entries, then the plugins of one entry-point group.

    Reads like a dict. The group's entry points are loaded on the first read (lookup,
    iteration, ``len``, ``in``); :meth:`register` adds an entry with the same checks;
    item assignment stays unchecked, as on a dict, and counts as steplab's own entry
    (tests swap entries with ``monkeypatch.setitem`` or ``clear`` and ``update``).

    Parameters
    ----------
    group : str
        Entry-point group, e.g. ``"steplab.integrators"``.
    what : str
        What an entry is, for messages ("integrator").
    entries : iterable of (name, entry)
        steplab's own entries.
    accept : callable
        ``accept(obj) -> (name, entry)``: turns what a plugin names (an instance, a class,
        ...) into a registry entry, or raises :class:`PluginError` (or TypeError) saying
        what is wrong; the name may be None where the object carries none (a function:
        :meth:`register` then needs ``name=``, an entry point gives its own). It may return
        a list of such pairs for a plugin that brings several (a folder of scenes).
    """

    def __init__(self, group: str, what: str, entries: Iterable[tuple[str, object]],
                 accept: Callable[[object], tuple[str | None, object]]):
        self.group, self.what, self._accept = group, what, accept
        self._entries = dict(entries)
        self._origins = dict.fromkeys(self._entries, BUILTIN)
        self._from_entry_points: set[str] = set()
        self._loaded = False
        #: entry-point name -> one line saying why that plugin was skipped
        self.errors: dict[str, str] = {}

    # --- the dict interface (each read loads the plugins first) -------------------------

    def __getitem__(self, name):
        self.load()
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        self.load()
        return iter(self._entries)

    def __len__(self) -> int:
        self.load()
        return len(self._entries)

    def __contains__(self, name) -> bool:
        self.load()
        return name in self._entries

    def __setitem__(self, name, entry):
        # unchecked, as on a dict, and counted as steplab's own (tests swap entries this way)
        self._entries[name] = entry
        self._origins[name] = BUILTIN

    def __delitem__(self, name):
        del self._entries[name]
        self._origins.pop(name, None)

    def __repr__(self) -> str:
        return f"Registry({self.group!r}, {list(self)})"

    # --- registration -------------------------------------------------------------------

    def register(self, obj=None, *, name: str | None = None, origin: str = "register"):
        """Add ``obj`` (checked by ``accept``) and return the entry; ``name`` names an ``obj``
        that carries no name of its own (a function). Without ``obj``, a decorator::

            @BROADPHASE_METHODS.register(name="toy")
            def toy_pairs(centers, radii): ...

        Raises
        ------
        PluginError
            ``obj`` is not a valid entry, or its name is taken by a different entry.
        """
        if obj is None:
            return lambda obj: self.register(obj, name=name, origin=origin)
        self.load()
        return self._add(obj, origin, name)

    def lookup(self, name, hint: str = ""):
        """The entry ``name``, or :class:`UnknownNameError`: ``unknown engine 'havok'; valid: mujoco,
        bullet, ...`` (``hint`` appended), or the one line of the plugin of that name that failed."""
        try:
            return self[name]
        except (KeyError, TypeError):  # TypeError: an unhashable name
            if isinstance(name, str) and name in self.errors:
                raise UnknownNameError(f"{self.what} {name!r} is unavailable: {self.errors[name]}") from None
            raise UnknownNameError(f"unknown {self.what} {name!r}; valid: {', '.join(self)}{hint}") from None

    def _add(self, obj, origin: str, name: str | None = None, unnamed: str | None = None):
        """Add ``obj`` under its own name, else ``name``, else ``unnamed`` (an entry point's name)."""
        try:
            accepted = self._accept(obj)
        except TypeError as err:
            raise PluginError(str(err)) from None
        if isinstance(accepted, list):  # a plugin with several entries (a folder of scenes)
            return self._add_each(accepted, origin)
        own_name, entry = accepted
        name = next((n for n in (own_name, name, unnamed) if n is not None), None)
        if not isinstance(name, str) or not name:
            raise PluginError(f"{obj!r} has no name: register it with name=\"...\"")
        if name in self._entries:
            if self._entries[name] == entry:  # the same entry again (a module that registers itself)
                return self._entries[name]
            raise PluginError(f"{self.what} name {name!r} is taken (by {self._origins.get(name, BUILTIN)}); "
                              "choose another name")
        self._entries[name] = entry
        self._origins[name] = origin
        return entry

    def _add_each(self, accepted: list[tuple[str, object]], origin: str) -> list:
        """Add each (name, entry) that is free; a taken name skips that entry alone, then raises."""
        added, taken = [], []
        for name, entry in accepted:
            if name in self._entries and self._entries[name] != entry:
                taken.append(f"{name!r} (by {self._origins[name]})")
                continue
            self._entries.setdefault(name, entry)
            self._origins.setdefault(name, origin)
            added.append(entry)
        if taken:
            raise PluginError(f"{self.what} name{'s' if len(taken) > 1 else ''} {', '.join(taken)} taken; "
                              f"{len(added)} other{'s' if len(added) != 1 else ''} added")
        return added

    def origin(self, name: str) -> str:
        """Where the entry ``name`` comes from: ``"steplab"`` or the plugin's distribution."""
        self.load()
        return self._origins[name]

    def load(self) -> None:
        """Load the group's entry points once; a broken one is skipped with one warning line."""
        if self._loaded:
            return
        self._loaded = True  # first: a plugin that reads the registry while it imports sees no loop
        for entry_point in metadata.entry_points(group=self.group):
            origin = entry_point_origin(entry_point)
            before = set(self._entries)
            try:
                self._add(entry_point.load(), origin, unnamed=entry_point.name)
            except Exception as err:  # a plugin's bug must not break steplab's own entries
                message = f"{self.what} plugin {origin} skipped: {_one_line(err)}"
                self.errors[entry_point.name] = message
                warnings.warn(message, PluginWarning, stacklevel=2)
            finally:
                self._from_entry_points |= set(self._entries) - before

    def reset(self) -> None:
        """Forget what the entry points added (entries registered or assigned stay); the group
        is read again on next use. For tests that install a plugin on sys.path."""
        for name in self._from_entry_points:
            self._entries.pop(name, None)
            self._origins.pop(name, None)
        self._from_entry_points = set()
        self._loaded = False
        self.errors = {}


def _one_line(err: BaseException) -> str:
    """``TypeName: message`` on one line (a PluginError's message alone)."""
    text = str(err).replace("\r", "\\r").replace("\n", "\\n")
    return text if isinstance(err, PluginError) else f"{type(err).__name__}: {text}"
