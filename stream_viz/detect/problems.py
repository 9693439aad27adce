"""What went wrong with one plugin, named so a user can find it: `PluginProblem`."""

from __future__ import annotations

import traceback
from dataclasses import dataclass


@dataclass(frozen=True)
class PluginProblem:
    """Something wrong with one plugin: which, where, what and the line that failed.

    ``kind`` is one of ``import``, ``validate``, ``duplicate``, ``config``, ``run``, ``timeout``,
    ``garbage``, ``flood``, ``disabled``.
    """

    plugin: str
    where: str
    kind: str
    message: str
    line: str = ""
    t: float | None = None
    count: int = 0

    def __str__(self) -> str:
        at = f" at {self.line}" if self.line else ""
        return f"plugin {self.plugin!r} ({self.where}): {self.kind}: {self.message}{at}"


def failing_line(exc: BaseException) -> str:
    """Return ``file:line in func`` of the innermost frame that is not import machinery."""
    if isinstance(exc, SyntaxError) and exc.filename:
        return f"{exc.filename}:{exc.lineno}"
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<frozen")]
    if not frames:
        return ""
    f = frames[-1]
    return f"{f.filename}:{f.lineno} in {f.name}"


def describe(exc: BaseException) -> str:
    """Return ``Type: message`` of ``exc``."""
    return f"{type(exc).__name__}: {exc}"
