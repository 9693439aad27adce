"""The alert database: SQLite (stdlib) in WAL mode, one commit per batch, a versioned schema.

Tables: ``meta`` (app marker, schema history, free keys, the run's start/end/watchlist/fault),
``runs`` (unused: kept for files written before), ``alerts``, ``episodes``, ``snapshots`` (the
model as `stream_viz.model.serialize.to_data` JSON whenever its structure changed, so
``analyze`` can rerun the RCA offline) and ``problems`` (plugin problems, unreadable members).
The schema version is ``PRAGMA user_version``; `MIGRATIONS` bring an older file up to date.
"""

from __future__ import annotations

import json
import os
import sqlite3
import tempfile
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np

from stream_viz.detect.episodes import Episode, EpisodeTracker
from stream_viz.errors import StoreError
from stream_viz.model.serialize import from_data, to_data
from stream_viz.output import check_writable
from stream_viz.records import Alert, Sample

APP = "stream-viz.alerts"

# Each entry brings the schema from version i to i + 1 (list index i).
MIGRATIONS: list[list[str]] = [
    [  # 0 -> 1: the first schema
        "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
        "CREATE TABLE runs (id INTEGER PRIMARY KEY, started_at REAL NOT NULL, ended_at REAL, "
        "args TEXT NOT NULL DEFAULT '{}', injected TEXT)",
        "CREATE TABLE alerts (id INTEGER PRIMARY KEY, member TEXT NOT NULL, plugin TEXT NOT NULL, "
        "t REAL NOT NULL, severity TEXT NOT NULL, message TEXT NOT NULL, data TEXT NOT NULL DEFAULT '{}')",
        "CREATE INDEX alerts_member_t ON alerts (member, t)",
        "CREATE INDEX alerts_t ON alerts (t)",
        "CREATE TABLE snapshots (id INTEGER PRIMARY KEY, t REAL NOT NULL, model TEXT NOT NULL)",
        "CREATE INDEX snapshots_t ON snapshots (t)",
        "CREATE TABLE problems (id INTEGER PRIMARY KEY, t REAL, plugin TEXT NOT NULL, kind TEXT NOT NULL, "
        "place TEXT NOT NULL, message TEXT NOT NULL, line TEXT NOT NULL DEFAULT '', "
        "count INTEGER NOT NULL DEFAULT 0)",
    ],
    [  # 1 -> 2: alert episodes (rate-limited storage of ongoing symptoms)
        "CREATE TABLE episodes (id INTEGER PRIMARY KEY, member TEXT NOT NULL, plugin TEXT NOT NULL, "
        "start REAL NOT NULL, end REAL NOT NULL, count INTEGER NOT NULL, max_severity TEXT NOT NULL)",
        "CREATE INDEX episodes_member ON episodes (member, start)",
        "ALTER TABLE alerts ADD COLUMN episode INTEGER REFERENCES episodes (id)",
    ],
]
SCHEMA_VERSION = len(MIGRATIONS)


def default_db_path() -> Path:
    """Return a fresh temp file path for the database when ``--db`` is not given (report it)."""
    fd, name = tempfile.mkstemp(prefix="stream-viz-", suffix=".sqlite")
    os.close(fd)
    return Path(name)


def learned_of(path: str | Path) -> dict[str, Any]:
    """Return what the plugins learned in the run kept in database ``path`` (plugin name to its
    ``ctx.learned``), for a later run to start from (``--healthy``).

    Raises
    ------
    StoreError
        ``path`` is no readable alert database, or its run did not end (killed: nothing learned
        was written) or was kept by a stream-viz that did not save what it learned.
    """
    store = AlertStore(path, readonly=True)
    try:
        learned = store.get_meta("learned")
        ended = store.get_meta("ended_at")
    finally:
        store.close()
    if not isinstance(learned, dict):
        why = "its run did not end (killed?)" if ended is None else "it was kept by an older stream-viz"
        raise StoreError(f"{path}: holds nothing learned to start from: {why}; give --healthy the "
                         "database of a run that ended")
    return learned


@dataclass(frozen=True)
class EpisodeRow:
    """An episode as stored."""

    id: int
    member: str
    plugin: str
    start: float
    end: float
    count: int
    max_severity: str


def _json(value: Any) -> str:
    return json.dumps(value, default=str, sort_keys=True)


def _structure(G: nx.MultiDiGraph) -> tuple[frozenset[str], frozenset[tuple[str, str, int]]]:
    return frozenset(G.nodes), frozenset(G.edges(keys=True))


class AlertStore:
    """The alert database of one file.

    Parameters
    ----------
    path : str or Path
        The SQLite file; created when missing or empty.
    repeat_s, gap_s : float
        Episode rate limit (see `stream_viz.detect.episodes`).
    readonly : bool
        Open for reading only (``analyze`` on a file a monitor may still write).

    Raises
    ------
    StoreError
        The file is not an SQLite database, is corrupt, is another program's database, or was
        written by a newer stream-viz.
    OutputError
        The file cannot be written (not ``readonly``).
    """

    def __init__(self, path: str | Path, *, repeat_s: float = 5.0, gap_s: float = 3.0,
                 readonly: bool = False) -> None:
        self.path = Path(path) if readonly else check_writable(path, "alert database")
        self.readonly = readonly
        self._tracker = EpisodeTracker(repeat_s, gap_s)
        self._last_structure: tuple[frozenset[str], frozenset[tuple[str, str, int]]] | None = None
        self._unreadable: dict[str, str] = {}  # member → why, as last recorded by `add_sample`
        self._db: sqlite3.Connection | None = None
        try:
            if readonly:
                if not self.path.exists():
                    raise StoreError(f"{self.path}: no such alert database")
                self._db = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True)
            else:
                self._db = sqlite3.connect(self.path)
            self._open()
        except (sqlite3.Error, StoreError) as exc:
            if self._db is not None:
                self._db.close()
            if isinstance(exc, StoreError):
                raise
            raise StoreError(f"{self.path}: not a readable stream-viz alert database ({exc})") from exc

    # ------------------------------------------------------------------ schema

    def _open(self) -> None:
        db = self._db
        version = db.execute("PRAGMA user_version").fetchone()[0]  # fails on a non-database
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if version == 0 and tables:
            raise StoreError(f"{self.path}: an SQLite database of another program (tables: "
                             f"{', '.join(sorted(tables))}); not overwriting it")
        if version > 0:
            marker = None
            if "meta" in tables:
                row = db.execute("SELECT value FROM meta WHERE key = 'app'").fetchone()
                marker = row[0] if row else None
            if marker != APP:
                raise StoreError(f"{self.path}: an SQLite database of another program "
                                 f"(user_version {version}, no '{APP}' marker)")
            if version > SCHEMA_VERSION:
                raise StoreError(f"{self.path}: written by a newer stream-viz (schema {version}, "
                                 f"this one knows up to {SCHEMA_VERSION})")
        if self.readonly:
            if version < SCHEMA_VERSION:
                raise StoreError(f"{self.path}: schema {version} needs migrating; open it writable once")
            return
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        self._migrate(version)

    def _migrate(self, version: int) -> None:
        db = self._db
        for v in range(version, SCHEMA_VERSION):
            # An explicit transaction: the sqlite3 module commits each CREATE on its own, so a
            # monitor killed mid-migration would leave a half-made schema no later run could open.
            db.execute("BEGIN IMMEDIATE")
            try:
                for stmt in MIGRATIONS[v]:
                    db.execute(stmt)
                if v == 0:
                    db.execute("INSERT INTO meta (key, value) VALUES ('app', ?)", (APP,))
                    db.execute("INSERT INTO meta (key, value) VALUES ('migrations', '[]')")
                done = json.loads(db.execute("SELECT value FROM meta WHERE key='migrations'").fetchone()[0])
                done.append({"to": v + 1, "at": time.time()})
                db.execute("UPDATE meta SET value = ? WHERE key = 'migrations'", (_json(done),))
                db.execute(f"PRAGMA user_version = {v + 1}")
            except BaseException:
                db.rollback()
                raise
            db.commit()

    @property
    def schema_version(self) -> int:
        """The file's schema version."""
        return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    # ------------------------------------------------------------------ writing

    def add(self, alerts: Iterable[Alert]) -> list[Alert]:
        """Store a batch (one commit); return the alerts that became rows (see episodes)."""
        stored: list[Alert] = []
        touched: dict[int, Episode] = {}
        with self._db as db:
            for a in alerts:
                keep, ep, new = self._tracker.offer(a)
                if new or ep.id is None:
                    cur = db.execute(
                        "INSERT INTO episodes (member, plugin, start, end, count, max_severity) "
                        "VALUES (?, ?, ?, ?, ?, ?)",
                        (ep.member, ep.plugin, ep.start, ep.end, ep.count, ep.max_severity))
                    ep.id = cur.lastrowid
                touched[ep.id] = ep
                if keep:
                    db.execute(
                        "INSERT INTO alerts (member, plugin, t, severity, message, data, episode) "
                        "VALUES (?, ?, ?, ?, ?, ?, ?)",
                        (a.member, a.plugin, float(a.t), a.severity, a.message, _json(a.data), ep.id))
                    stored.append(a)
            for ep in touched.values():
                db.execute("UPDATE episodes SET end = ?, count = ?, max_severity = ? WHERE id = ?",
                           (ep.end, ep.count, ep.max_severity, ep.id))
        return stored

    def add_sample(self, sample: Sample, seen: nx.MultiDiGraph, alerts: Iterable[Alert] = (),
                   problems: Iterable[Any] = ()) -> list[Alert]:
        """Store what one monitor tick changed; return the alerts that became rows (`add`).

        The model ``seen`` (everything seen, vanished members kept) when its structure changed,
        the members that became unreadable (or for another reason), the alerts, the plugin
        problems (`add_problems`).
        """
        # Comparing structures walks the model: only when the sample says it changed.
        if sample.diff or self._last_structure is None:
            self.add_snapshot(sample.t, seen)
        # A member we may not read stays unreadable: record it when that changes, not every tick.
        fresh = {m: why for m, why in sample.unreadable.items() if self._unreadable.get(m) != why}
        if fresh:
            self.add_unreadable(sample.t, fresh)
        self._unreadable = dict(sample.unreadable)
        stored = self.add(alerts)
        problems = list(problems)
        if problems:
            self.add_problems(problems, t=sample.t)
        return stored

    def add_problems(self, problems: Iterable[Any], t: float | None = None) -> None:
        """Store plugin problems (`stream_viz.detect.problems.PluginProblem`), one commit."""
        with self._db as db:
            db.executemany(
                "INSERT INTO problems (t, plugin, kind, place, message, line, count) VALUES (?,?,?,?,?,?,?)",
                [(p.t if p.t is not None else t, p.plugin, p.kind, p.where, p.message, p.line, p.count)
                 for p in problems])

    def add_unreadable(self, t: float, unreadable: Mapping[str, str]) -> None:
        """Store members that could not be read at ``t`` (member → why), one commit."""
        with self._db as db:
            db.executemany(
                "INSERT INTO problems (t, plugin, kind, place, message) VALUES (?, '', 'unreadable', ?, ?)",
                [(t, m, why) for m, why in sorted(unreadable.items())])

    def add_snapshot(self, t: float, G: nx.MultiDiGraph, force: bool = False) -> bool:
        """Store the model at ``t`` when its members or edges changed (or ``force``); True if stored."""
        structure = _structure(G)
        if not force and structure == self._last_structure:
            return False
        if self._last_structure is None and not force:
            row = self._db.execute("SELECT model FROM snapshots ORDER BY t DESC, id DESC LIMIT 1").fetchone()
            if row is not None and _structure(from_data(json.loads(row[0]))) == structure:
                self._last_structure = structure
                return False
        with self._db as db:
            db.execute("INSERT INTO snapshots (t, model) VALUES (?, ?)", (float(t), _json(to_data(G))))
        self._last_structure = structure
        return True

    def begin_run(self, started_at: float) -> None:
        """Mark the file as holding the run started at ``started_at``.

        Raises
        ------
        StoreError
            The file already holds a run that kept alerts or a model: one database is one run, as
            `analyze` and the report read every alert in it, so a second run would mix with it.
        """
        before = self.get_meta("started_at")
        n = self._db.execute("SELECT count(*) FROM alerts").fetchone()[0]
        kept = n or self._db.execute("SELECT count(*) FROM snapshots").fetchone()[0]
        if before is not None and kept:  # a run killed before it kept anything may be taken over
            when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(float(before)))
            raise StoreError(f"{self.path}: already holds a run (started {when}, {n} alerts); "
                             "give --db a new file, one database holds one run")
        self.set_meta("started_at", started_at)

    def set_meta(self, key: str, value: Any) -> None:
        """Set a free meta key to a JSON-able value."""
        if key in ("app", "migrations"):
            raise StoreError(f"{self.path}: meta key {key!r} is reserved")
        with self._db as db:
            db.execute("INSERT INTO meta (key, value) VALUES (?, ?) "
                       "ON CONFLICT (key) DO UPDATE SET value = excluded.value", (key, _json(value)))

    # ------------------------------------------------------------------ reading

    def get_meta(self, key: str, default: Any = None) -> Any:
        """Return a meta value (JSON-decoded), or ``default``."""
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        if row is None:
            return default
        return row[0] if key == "app" else json.loads(row[0])

    def alerts(self, member: str | None = None, since: float | None = None) -> list[Alert]:
        """Return stored alerts in time order, optionally of one member and from ``since`` on."""
        sql = "SELECT member, plugin, t, severity, message, data FROM alerts WHERE 1=1"
        args: list[Any] = []
        if member is not None:
            sql += " AND member = ?"
            args.append(member)
        if since is not None:
            sql += " AND t >= ?"
            args.append(float(since))
        sql += " ORDER BY t, id"
        return [Alert(m, p, t, s, msg, json.loads(d)) for m, p, t, s, msg, d in self._db.execute(sql, args)]

    def series(self) -> dict[str, np.ndarray]:
        """Return member → sorted alert times (the per-member alert time series of the RCA)."""
        out: dict[str, list[float]] = {}
        for m, t in self._db.execute("SELECT member, t FROM alerts ORDER BY member, t"):
            out.setdefault(m, []).append(t)
        return {m: np.array(ts, dtype=float) for m, ts in out.items()}

    def episodes(self, member: str | None = None) -> list[EpisodeRow]:
        """Return the episodes (in start order), optionally of one member."""
        sql = "SELECT id, member, plugin, start, end, count, max_severity FROM episodes"
        args: tuple[Any, ...] = ()
        if member is not None:
            sql += " WHERE member = ?"
            args = (member,)
        return [EpisodeRow(*r) for r in self._db.execute(sql + " ORDER BY start, id", args)]

    def latest_snapshot(self, at: float | None = None) -> nx.MultiDiGraph | None:
        """Return the last model stored at or before ``at`` (default: the last one), or None."""
        if at is None:
            row = self._db.execute("SELECT model FROM snapshots ORDER BY t DESC, id DESC LIMIT 1").fetchone()
        else:
            row = self._db.execute(
                "SELECT model FROM snapshots WHERE t <= ? ORDER BY t DESC, id DESC LIMIT 1", (float(at),)
            ).fetchone()
        return None if row is None else from_data(json.loads(row[0]))

    def snapshots(self) -> list[tuple[float, nx.MultiDiGraph]]:
        """Return every stored ``(t, model)`` in time order."""
        return [(t, from_data(json.loads(m)))
                for t, m in self._db.execute("SELECT t, model FROM snapshots ORDER BY t, id")]

    def problems(self) -> list[dict[str, Any]]:
        """Return stored problems as dicts (``t, plugin, kind, where, message, line, count``)."""
        rows = self._db.execute(
            "SELECT t, plugin, kind, place, message, line, count FROM problems ORDER BY id")
        return [dict(zip(("t", "plugin", "kind", "where", "message", "line", "count"), r, strict=True))
                for r in rows]

    def close(self) -> None:
        """Close the file (everything added is already committed)."""
        self._db.close()

    def __enter__(self) -> AlertStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
