"""The one settings mechanism: declare a key, check a table, one error format.

A key has a type, a default and constraints. Config tables are frozen dataclasses whose fields
are the keys (the annotation is the type; `setting` adds the constraints); a plugin's settings
are a plain dict of defaults, the type of each key taken from its default (`plugin_keys`).
Either way `check_table` checks a table and every error reads::

    run.toml: [monitor] period = -1: expected a number > 0
    run.toml: [monitor] unknown key 'perod' (known: forget_gone_s, history, period, ...)

Types: ``bool`` (strict: never 0/1), ``int`` (never a bool), ``float`` (an int stands for it;
finite), ``str``, ``Path`` (from a string), ``Any``, lists (``tuple[str, ...]``, ``list[float]``)
with their item type, and tables of numbers (``dict[str, float]``: the keys are the default's,
a partial table is merged into the default). Constraints: bounds (``gt``, ``ge``, ``lt``,
``le``, on a number or on each item or entry), ``choices`` and one ``rule`` on the whole value.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from stream_viz.errors import ConfigError

T = TypeVar("T")
_META = "stream_viz.setting"
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_PHRASE = {bool: "true or false", int: "an integer", float: "a number", str: "a string",
           Path: "a path", Any: "any value"}
_PLURAL = {bool: "booleans", int: "integers", float: "numbers", str: "strings", Path: "paths",
           Any: "values"}


def _plural(scalar: Any) -> str:
    return _PLURAL.get(scalar) or f"{scalar.__name__} values"


@dataclass(frozen=True)
class Key:
    """One key of a table: its type, default and constraints.

    ``scalar`` is bool, int, float, str, Path or Any; ``container`` is None, ``list`` or ``tuple``
    (a list of ``scalar``), or ``dict`` (a table of ``scalar`` with the default's keys).
    ``rule`` is ``(predicate on the whole value, what it requires)``.
    """

    scalar: Any
    default: Any = None
    container: type | None = None
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[Any, ...] = ()
    rule: tuple[Callable[[Any], bool], str] | None = None

    def expected(self) -> str:
        """Return what a valid value is, in words (``a number > 0``, ``one of a, b``)."""
        if self.choices:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.container is dict:
            what = f"a table of {_plural(self.scalar)}"
        elif self.container is not None:
            what = f"a list of {_plural(self.scalar)}"
        else:
            what = _PHRASE.get(self.scalar) or f"a {self.scalar.__name__}"
        what += self._bounds()
        return f"{what}, {self.rule[1]}" if self.rule else what

    def _bounds(self) -> str:
        if (self.gt, self.ge) != (None, None) and (self.lt, self.le) != (None, None):
            low = f"({self.gt}" if self.gt is not None else f"[{self.ge}"
            high = f"{self.lt})" if self.lt is not None else f"{self.le}]"
            return f" in {low}, {high}"
        bounds = ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le))
        return "".join(f" {op} {v}" for op, v in bounds if v is not None)

    def item_fits(self, value: Any) -> bool:
        """True when ``value`` is a valid scalar (an item or entry for a list or table)."""
        t = self.scalar
        if t is Any:
            return True
        if t is bool or isinstance(value, bool):
            return t is bool and isinstance(value, bool)
        if t is float or t is int:
            if not isinstance(value, int if t is int else int | float) or not math.isfinite(value):
                return False
            return ((self.gt is None or value > self.gt) and (self.ge is None or value >= self.ge)
                    and (self.lt is None or value < self.lt) and (self.le is None or value <= self.le))
        if t is Path:
            return isinstance(value, str | Path)
        return isinstance(value, t) and (not self.choices or value in self.choices)

    def normalise(self, value: Any) -> Any:
        """Return a checked scalar in its declared type (an int given for a float is a float)."""
        if self.scalar is float:
            return float(value)
        return Path(value) if self.scalar is Path else value


def setting(default: Any, *, gt: float | None = None, ge: float | None = None, lt: float | None = None,
            le: float | None = None, choices: tuple[Any, ...] = (),
            rule: tuple[Callable[[Any], bool], str] | None = None) -> Any:
    """Declare a key of a settings dataclass: its default and constraints (its type is the annotation).

    A mutable default (a dict or list) is copied for each instance.
    """
    meta = {_META: {"gt": gt, "ge": ge, "lt": lt, "le": le, "choices": tuple(choices), "rule": rule}}
    if isinstance(default, dict | list):
        return dataclasses.field(default_factory=functools.partial(copy.deepcopy, default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def not_a_key(default_factory: Callable[[], Any]) -> Any:
    """Declare a field of a settings dataclass that the loader fills, not a key of the table."""
    return dataclasses.field(default_factory=default_factory, metadata={_META: None})


@functools.cache
def keys_of(cls: type) -> dict[str, Key]:
    """Return the keys of the settings dataclass ``cls``, by name."""
    hints = typing.get_type_hints(cls)
    keys = {}
    for f in dataclasses.fields(cls):
        if _META in f.metadata and f.metadata[_META] is None:
            continue
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        scalar, container = _split_type(hints[f.name], f"{cls.__name__}.{f.name}")
        keys[f.name] = Key(scalar, default, container, **f.metadata.get(_META, {}))
    return keys


def _split_type(tp: Any, name: str) -> tuple[Any, type | None]:
    """Return ``(scalar type, container)`` of an annotation (``float | None`` is ``float``)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            return _split_type(rest[0], name)
    if origin in (list, tuple) and args and args[0] in _PHRASE:
        return args[0], origin
    if origin is dict and len(args) == 2 and args[0] is str and args[1] in _PHRASE:
        return args[1], dict
    if tp in _PHRASE:
        return tp, None
    raise TypeError(f"{name}: a setting cannot have the type {tp!r}")


def plugin_keys(defaults: Mapping[str, Any]) -> dict[str, Key]:
    """Return the keys of a plugin's ``settings`` dict: each key's type is its default's.

    A list's item type is its first item's (an empty list takes any items); ``None`` takes any value.
    """
    keys = {}
    for name, default in defaults.items():
        if isinstance(default, list | tuple):
            keys[name] = Key(type(default[0]) if default else Any, default, type(default))
        else:
            keys[name] = Key(Any if default is None else type(default), default)
    return keys


# --------------------------------------------------------------------------- errors


def toml_value(value: Any) -> str:
    """Return ``value`` written as in a TOML file (``true``, ``"x"``, ``[1, 2]``, ``{a = 1}``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str | Path):
        return json.dumps(str(value), ensure_ascii=False)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


def toml_key(key: Any) -> str:
    """Return ``key`` as written in a TOML file (quoted unless bare)."""
    key = str(key)
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def bad_value(where: str, section: str, key: str, value: Any, expected: str) -> ConfigError:
    """Return the error for a bad value: ``<where>: [<section>] <key> = <value>: expected <what>``.

    ``section`` empty: ``key`` is a section of the file (``<where>: <key> = <value>: ...``).
    """
    at = f"[{section}] " if section else ""
    return ConfigError(f"{where}: {at}{toml_key(key)} = {toml_value(value)}: expected {expected}")


def unknown_key(where: str, section: str, key: str, known: typing.Iterable[str]) -> ConfigError:
    """Return the error for a key ``section`` does not have, listing the ones it has.

    ``section`` empty: ``key`` names an unknown section of the file.
    """
    listed = ", ".join(sorted(known)) or "none"
    if not section:
        return ConfigError(f"{where}: unknown section [{key}] (known: {listed})")
    return ConfigError(f"{where}: [{section}] unknown key {str(key)!r} (known: {listed})")


def _parent(section: str) -> tuple[str, str]:
    """Split a dotted TOML section name into ``(parent, last key)`` (``topics."/a.b"`` -> topics)."""
    m = re.match(r'^(.*?)\.("[^"]*"|[^."]+)$', section)
    if m is None:
        return "", section
    last = m.group(2)
    return m.group(1), json.loads(last) if last.startswith('"') else last


def expect_table(value: Any, where: str, section: str) -> dict[str, Any]:
    """Return ``value`` if it is a table, else the error for section ``section`` not being one."""
    if not isinstance(value, Mapping):
        parent, key = _parent(section)
        raise bad_value(where, parent, key, value, "a table")
    return dict(value)


# --------------------------------------------------------------------------- checks


def _check_value(key: Key, value: Any, where: str, section: str, name: str) -> Any:
    """Return ``value`` checked against ``key`` and normalised (named ``name`` in ``[section]``).

    A table is checked entry by entry (errors name ``[section.name] entry``) and merged into
    the key's default; a list becomes the key's container type.
    """
    if key.container is dict:
        sub = f"{section}.{toml_key(name)}"
        merged = dict(key.default)
        for k, v in expect_table(value, where, sub).items():
            if k not in key.default:
                raise unknown_key(where, sub, k, key.default)
            if not key.item_fits(v):
                entry = dataclasses.replace(key, container=None, rule=None)
                raise bad_value(where, sub, k, v, entry.expected())
            merged[k] = key.normalise(v)
        out: Any = merged
    elif key.container is not None:
        if not isinstance(value, list | tuple) or not all(key.item_fits(v) for v in value):
            raise bad_value(where, section, name, value, key.expected())
        out = key.container(key.normalise(v) for v in value)
    else:
        if not key.item_fits(value):
            raise bad_value(where, section, name, value, key.expected())
        out = key.normalise(value)
    if key.rule is not None and not key.rule[0](out):
        raise bad_value(where, section, name, value, key.expected())
    return out


def check_table(keys: Mapping[str, Key], table: Any, where: str, section: str) -> dict[str, Any]:
    """Return the keys given in ``table``, checked and normalised (missing keys are left out).

    Parameters
    ----------
    keys : mapping
        Key name to `Key` (`keys_of` a settings dataclass, or `plugin_keys`).
    table : Any
        The table as read (a dict; anything else is an error).
    where : str
        Where it came from (the config file path), named in errors.
    section : str
        The table's name in the file (``monitor``, ``topics."/scan"``), named in errors.

    Raises
    ------
    ConfigError
        At the first unknown key or bad value, in the one format (see the module).
    """
    table = expect_table(table, where, section)
    out = {}
    for name, value in table.items():
        if name not in keys:
            raise unknown_key(where, section, name, keys)
        out[name] = _check_value(keys[name], value, where, section, name)
    return out


def load(cls: type[T], table: Any, where: str, section: str) -> T:
    """Return the settings dataclass ``cls`` from ``table`` (missing keys keep their defaults).

    Raises
    ------
    ConfigError
        As `check_table`.
    """
    return cls(**check_table(keys_of(cls), table, where, section))


def check_plugin_settings(defaults: Mapping[str, Any], given: Any, where: str,
                          section: str) -> dict[str, Any]:
    """Return a plugin's settings: its ``defaults`` with the ``given`` values checked and merged in.

    Parameters
    ----------
    defaults : mapping
        The plugin class's ``settings`` (each key's type is its default's, see `plugin_keys`).
    given : Any
        The ``[plugins.<name>]`` table.
    where, section : str
        As `check_table` (``section`` is ``plugins.<name>``).

    Raises
    ------
    ConfigError
        As `check_table`.
    """
    merged = copy.deepcopy(dict(defaults))
    merged.update(check_table(plugin_keys(defaults), given, where, section))
    return merged
