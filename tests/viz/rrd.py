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
