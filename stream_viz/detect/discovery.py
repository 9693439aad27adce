"""Finding plugins and validating each plugin class.

Plugins come from the entry-point group ``stream_viz.plugins`` (the built-ins are registered
there exactly like a user's) and from plugin folders (those the config names, then ``./plugins``).
A plugin that fails to import or to validate becomes a `PluginProblem` naming it and where; the
others load.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import inspect
import re
import sys
import types
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stream_viz.detect.api import API_VERSION, Plugin, missing_settings
from stream_viz.detect.problems import PluginProblem, describe, failing_line
from stream_viz.model.ids import KINDS

GROUP = "stream_viz.plugins"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
_SETTING_TYPES = (bool, int, float, str, list, tuple, type(None))


def discover(
    folders: Sequence[str | Path] = (),
    *,
    entry_points: bool = True,
    cwd_plugins: bool = True,
) -> tuple[list[tuple[Plugin, str, str]], list[PluginProblem], set[str]]:
    """Find and validate plugins.

    Parameters
    ----------
    folders : sequence of path
        Plugin folders to scan (``*.py``, not starting with ``_``), in order.
    entry_points : bool
        Load the entry-point group ``stream_viz.plugins`` first.
    cwd_plugins : bool
        Also scan ``./plugins`` when it exists.

    Returns
    -------
    plugins : list of (instance, name, where)
        Valid plugins; on a name given twice the first wins.
    problems : list of PluginProblem
        One per plugin that failed to import or validate, or was a duplicate.
    failed : set of str
        Names (entry-point names, module stems, plugin names) of what failed to load.
    """
    found = _Found()
    if entry_points:
        _load_entry_points(found)
    for folder in _folders(folders, cwd_plugins):
        _load_folder(found, folder)
    return found.plugins, found.problems, found.failed


@dataclass
class _Found:
    """What discovery has found so far."""

    plugins: list[tuple[Plugin, str, str]] = field(default_factory=list)
    problems: list[PluginProblem] = field(default_factory=list)
    failed: set[str] = field(default_factory=set)
    files: set[Path] = field(default_factory=set)  # modules loaded already (an entry point's, a folder's)

    def import_failed(self, name: str, where: str, exc: Exception) -> None:
        self.problems.append(PluginProblem(name, where, "import", describe(exc), failing_line(exc)))
        self.failed.add(name)

    def offer(self, objs: Iterable[Any], fallback_where: str) -> None:
        """Validate each plugin class/instance of ``objs`` and keep the valid, new ones."""
        for obj in objs:
            where = _where_of(obj, fallback_where)
            inst, name, problem = validate(obj, where)
            if problem is not None:
                self.problems.append(problem)
                self.failed.add(name)
                continue
            first = next((w for _, n, w in self.plugins if n == name), None)
            if first is not None:
                self.problems.append(PluginProblem(name, where, "duplicate",
                                                   f"name already taken by the plugin from {first}; ignored"))
                continue
            self.plugins.append((inst, name, where))


def _load_entry_points(found: _Found) -> None:
    for ep in sorted(importlib.metadata.entry_points(group=GROUP), key=lambda e: e.name):
        try:
            obj = ep.load()
        except Exception as exc:
            found.import_failed(ep.name, f"entry point {ep.value}", exc)
            continue
        module = inspect.getmodule(obj)
        if module is not None and getattr(module, "__file__", None):
            found.files.add(Path(module.__file__).resolve())
        found.offer(_candidates(obj), f"entry point {ep.value}")


def _folders(folders: Sequence[str | Path], cwd_plugins: bool) -> list[Path]:
    """The folders to scan: those given, then ``./plugins`` unless given already."""
    dirs = [Path(f) for f in folders]
    local = Path.cwd() / "plugins"
    if cwd_plugins and local.is_dir() and all(local.resolve() != d.resolve() for d in dirs):
        dirs.append(local)
    return dirs


def _load_folder(found: _Found, folder: Path) -> None:
    if not folder.is_dir():
        found.problems.append(PluginProblem(folder.name, str(folder), "import",
                                            "plugin folder does not exist"))
        return
    for path in sorted(folder.glob("*.py")):
        if path.name.startswith("_") or path.resolve() in found.files:
            continue
        found.files.add(path.resolve())
        try:
            module = _import_folder_module(path)
        except Exception as exc:
            found.import_failed(path.stem, str(path), exc)
            continue
        found.offer(_candidates(module), str(path))


def _import_folder_module(path: Path) -> types.ModuleType:
    tag = hashlib.sha1(str(path.parent).encode()).hexdigest()[:10]
    mod_name = f"stream_viz_folder_plugins_{tag}.{path.stem}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(mod_name, None)
        raise
    return module


def _candidates(obj: Any) -> list[Any]:
    """Plugin classes/instances an entry-point target or a folder module offers."""
    if isinstance(obj, types.ModuleType):
        if hasattr(obj, "PLUGINS"):
            return list(obj.PLUGINS)
        return [
            c for _, c in sorted(vars(obj).items())
            if inspect.isclass(c) and issubclass(c, Plugin) and c is not Plugin
            and c.__module__ == obj.__name__ and not c.__name__.startswith("_")
        ]
    if isinstance(obj, list | tuple):
        return list(obj)
    return [obj]


def _where_of(obj: Any, fallback: str) -> str:
    cls = obj if inspect.isclass(obj) else type(obj)
    try:
        return f"{inspect.getsourcefile(cls) or fallback}"
    except TypeError:
        return fallback


def validate(obj: Any, where: str) -> tuple[Plugin | None, str, PluginProblem | None]:
    """Check a plugin class (or instance) and create it.

    Returns
    -------
    tuple
        ``(instance, name, None)``, or ``(None, name, problem)`` with a ``validate`` problem.
    """
    cls = obj if inspect.isclass(obj) else type(obj)
    name = getattr(cls, "name", None)
    shown = name if isinstance(name, str) and name else getattr(cls, "__name__", repr(obj))

    def bad(msg: str, line: str = "") -> tuple[None, str, PluginProblem]:
        return None, shown, PluginProblem(shown, where, "validate", msg, line)

    if not (inspect.isclass(cls) and issubclass(cls, Plugin)):
        return bad(f"{obj!r} is not a stream_viz.detect.api.Plugin subclass")
    wrong = _declaration_problem(cls)
    if wrong:
        return bad(wrong)
    if inspect.isclass(obj):
        try:
            obj = obj()
        except Exception as exc:
            return bad(f"could not be created: {describe(exc)}", failing_line(exc))
    return obj, name, None


def _declaration_problem(cls: type[Plugin]) -> str | None:
    """What is wrong with the declared fields of a `Plugin` subclass, or None."""
    if not isinstance(cls.name, str) or not _NAME.match(cls.name):
        return f"class {cls.__name__}: name must be a word such as 'my_plugin', not {cls.name!r}"
    if cls.api_version != API_VERSION:
        return f"written for plugin API {cls.api_version!r}; this stream-viz speaks {API_VERSION}"
    kinds = cls.kinds
    if not isinstance(kinds, tuple | list) or not kinds or any(k not in KINDS for k in kinds):
        return f"kinds must be a non-empty tuple of {KINDS}, not {kinds!r}"
    if not isinstance(cls.settings, dict) or any(not isinstance(k, str) for k in cls.settings):
        return f"settings must be a dict with str keys, not {cls.settings!r}"
    for key, value in cls.settings.items():
        if not isinstance(value, _SETTING_TYPES):
            return f"setting {key!r}: default {value!r} is not bool/int/float/str/list/None"
    if not isinstance(cls.uses, tuple | list) or not all(callable(h) for h in cls.uses):
        return f"uses must be a tuple of helper functions, not {cls.uses!r}"
    missing = missing_settings(cls)
    if missing:
        readers = sorted({h for hs in missing.values() for h in hs})
        return (f"settings lack {', '.join(map(repr, missing))}, read by {', '.join(readers)} "
                f"(listed in uses): add defaults for them")
    if cls.check is Plugin.check:
        return "does not implement check(ctx)"
    return None
