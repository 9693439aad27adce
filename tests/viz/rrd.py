"""Reading a real .rrd back for the viz tests (rerun.chunk.RrdReader; no mocks)."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import pyarrow as pa
from rerun.chunk import RrdReader


def _plain(col: pa.ChunkedArray | pa.Array) -> list[Any]:
    if pa.types.is_timestamp(col.type) or pa.types.is_duration(col.type):
        col = col.cast(pa.int64())
    return col.to_pylist()


def rows(path: str | Path, store=None) -> dict[str, list[dict[str, Any]]]:
    """Return entity path -> rows (column name -> value; timestamps as int64 ns), sorted by time."""
    out: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for chunk in RrdReader(str(path)).stream(store=store):
        rb = chunk.to_record_batch()
        cols = {name: _plain(rb.column(i)) for i, name in enumerate(rb.schema.names)}
        for i in range(rb.num_rows):
            out[chunk.entity_path].append({k: v[i] for k, v in cols.items()})
    for r in out.values():
        r.sort(key=lambda row: (row.get("rca_iteration") or 0, row.get("time") or 0))
    return dict(out)


def strings(path: str | Path, store) -> set[str]:
    """Return every string value anywhere in a store of the file (e.g. the blueprint's view names)."""
    found: set[str] = set()

    def walk(v: Any) -> None:
        if isinstance(v, str):
            found.add(v)
        elif isinstance(v, list | tuple):
            for x in v:
                walk(x)
        elif isinstance(v, dict):
            for x in v.values():
                walk(x)

    for ent in rows(path, store).values():
        for row in ent:
            walk(row)
    return found


def shown(ent_rows: list[dict[str, Any]], timeline: str = "time", at: int | None = None) -> dict[str, Any]:
    """Return what the viewer shows of an entity on ``timeline`` at ``at`` (default: the end):
    each column's value from the latest row at or before ``at`` that has it (latest-at), over
    the rows logged on that timeline (static rows, with no timeline, under everything)."""
    on = [r for r in ent_rows if r.get(timeline) is not None and (at is None or r[timeline] <= at)]
    static = [r for r in ent_rows if all(r.get(k) is None for k in ("time", "rca_iteration"))]
    out: dict[str, Any] = {}
    for row in [*static, *sorted(on, key=lambda r: r[timeline])]:
        out.update({k: v for k, v in row.items() if v is not None and ":" in k})
    return out
