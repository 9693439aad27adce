"""The samples file: every `Sample` the collector produced, as gzip-compressed JSON lines.

Line 1 is the header (``format``, the stream-viz version, the configuration, when the run
started). Every further line is one sample, or a note (``{"note": key, "value": …}``, e.g. the
injected fault). A sample carries its graph in full only when the structure changed (members,
edges or their order); otherwise only the members and edges whose attributes changed, the θ that
changed, the events, and the unreadable members when they changed. The writer flushes the
compressor after each line, so a run killed mid-way leaves a file readable up to its last
complete sample. The diff is not stored: the reader recomputes it, as the collector does.

`SampleEncoder` and `SampleDecoder` are the pure delta coding (a sample ↔ a JSON-able dict);
`SamplesWriter` and `SamplesReader` add the file. The format is in docs/contracts.md.
"""

from __future__ import annotations

import gzip
import io
import json
import zlib
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TextIO

import networkx as nx
import numpy as np

from stream_viz.errors import SamplesError
from stream_viz.model.diff import diff
from stream_viz.model.graph import new_graph
from stream_viz.model.serialize import theta_from_list, theta_to_list
from stream_viz.model.theta import SCHEMAS
from stream_viz.output import check_writable
from stream_viz.records import Event, Sample

FORMAT = "stream-viz.samples/v1"
_GZIP_MAGIC = b"\x1f\x8b"


def _plain(value: Any) -> Any:
    """JSON can hold it: numpy scalars and arrays, tuples and sets become numbers and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, set | frozenset):
        return sorted(value, key=str)
    if isinstance(value, bytes):
        return value.hex()
    raise TypeError(f"cannot write a {type(value).__name__} to a samples file")


def _dumps(record: Mapping[str, Any]) -> str:
    return json.dumps(record, separators=(",", ":"), default=_plain)


def run_header(config: Any, started_at: float) -> dict[str, Any]:
    """What a samples file says about its run: the versions, the configuration file (its path and
    text: a replay detects with the same settings) and when the run started."""
    from stream_viz import __version__

    path = config.path
    return {"stream_viz": __version__, "started_at": started_at, "period": config.monitor.period,
            "config": {"path": str(Path(path).resolve()) if path else None,
                       "toml": Path(path).read_text(encoding="utf-8") if path else None}}


def _member_attrs(attrs: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in attrs.items() if k != "theta"}


class SampleEncoder:
    """Turns consecutive samples into records that carry only what changed since the last one."""

    def __init__(self) -> None:
        self._members: list[str] = []
        self._edges: list[tuple[str, str, int]] = []
        self._attrs: dict[str, dict[str, Any]] = {}
        self._edge_attrs: dict[tuple[str, str, int], dict[str, Any]] = {}
        self._theta: dict[str, bytes] = {}  # θ as last written, as bytes: NaN equals NaN, and fast
        self._unreadable: dict[str, str] = {}
        self._graph_attrs: dict[str, Any] = {}

    def encode(self, sample: Sample) -> dict[str, Any]:
        """Return the record of ``sample`` (JSON-able but for numpy values `_dumps` converts)."""
        G = sample.graph
        rec: dict[str, Any] = {"t": sample.t}
        members, edges = list(G.nodes), list(G.edges(keys=True))
        if members != self._members or edges != self._edges:
            self._members, self._edges, self._theta = members, edges, {}
            self._attrs = {m: _member_attrs(a) for m, a in G.nodes(data=True)}
            self._edge_attrs = {(u, v, k): dict(a) for u, v, k, a in G.edges(keys=True, data=True)}
            rec["graph"] = {"members": [[m, a] for m, a in self._attrs.items()],
                            "edges": [[u, v, k, a] for (u, v, k), a in self._edge_attrs.items()]}
        else:
            changed = {}
            for m, a in G.nodes(data=True):
                now = _member_attrs(a)
                if now != self._attrs[m]:
                    changed[m] = self._attrs[m] = now
            if changed:
                rec["attrs"] = changed
            changed_edges = []
            for u, v, k, a in G.edges(keys=True, data=True):
                if a != self._edge_attrs[u, v, k]:
                    self._edge_attrs[u, v, k] = dict(a)
                    changed_edges.append([u, v, k, a])
            if changed_edges:
                rec["edge_attrs"] = changed_edges
        theta: dict[str, list[float | None] | None] = {}
        for m, th in G.nodes(data="theta"):
            if th is None:
                if m in self._theta:
                    theta[m] = None
                    del self._theta[m]
                continue
            now = th.tobytes()
            if self._theta.get(m) != now:
                theta[m] = theta_to_list(th)
                self._theta[m] = now
        if theta:
            rec["theta"] = theta
        if sample.events:
            rec["events"] = [[e.t, e.kind, e.member, e.level, e.text, e.data] for e in sample.events]
        if sample.unreadable != self._unreadable:
            self._unreadable = dict(sample.unreadable)
            rec["unreadable"] = self._unreadable
        if G.graph != self._graph_attrs:  # the graph's own (``qos_version``: a QoS changed in place)
            self._graph_attrs = dict(G.graph)
            rec["graph_attrs"] = self._graph_attrs
        return rec


class SampleDecoder:
    """Rebuilds the samples from the records of a `SampleEncoder`, in order.

    Each sample gets a graph of its own; attribute values that did not change are shared with the
    previous sample's graph (the monitor treats a sample's graph as read-only, as the live one).
    ``schemas`` are the θ attribute names per member kind the file was written with (its header):
    where they differ from this version's `SCHEMAS`, θ is mapped by name (an attribute the file
    lacks is NaN, one this version lacks is dropped).
    """

    def __init__(self, schemas: Mapping[str, list[str]] | None = None) -> None:
        self._remap = {kind: _remap(list(names), SCHEMAS[kind]) for kind, names in (schemas or {}).items()
                       if kind in SCHEMAS and tuple(names) != SCHEMAS[kind]}
        self._members: dict[str, dict[str, Any]] = {}
        self._edges: dict[tuple[str, str, int], dict[str, Any]] = {}
        self._theta: dict[str, np.ndarray] = {}
        self._unreadable: dict[str, str] = {}
        self._graph_attrs: dict[str, Any] = {}
        self._prev = new_graph()

    def decode(self, rec: Mapping[str, Any]) -> Sample:
        """Return the sample of ``rec``; KeyError, TypeError or ValueError when it is malformed."""
        t = float(rec["t"])
        if "graph" in rec:
            graph = rec["graph"]
            self._members = {str(m): dict(a) for m, a in graph["members"]}
            self._edges = {(str(u), str(v), int(k)): dict(a) for u, v, k, a in graph["edges"]}
            self._theta = {}
        # A member or edge not in the graph so far makes a malformed record (KeyError).
        for m, a in rec.get("attrs", {}).items():
            _known(self._members, m)[m] = dict(a)
        for u, v, k, a in rec.get("edge_attrs", []):
            _known(self._edges, (u, v, k))[u, v, k] = dict(a)
        for m, row in rec.get("theta", {}).items():
            _known(self._members, m)
            if row is None:
                self._theta.pop(m, None)
            else:
                th = theta_from_list(row)
                remap = self._remap.get(self._members[m].get("kind"))
                self._theta[m] = th if remap is None else remap(th)
        if "unreadable" in rec:
            self._unreadable = {str(m): str(why) for m, why in rec["unreadable"].items()}
        if "graph_attrs" in rec:
            self._graph_attrs = dict(rec["graph_attrs"])
        G = self._graph()
        events = [Event(float(et), kind, member, level, text, dict(data))
                  for et, kind, member, level, text, data in rec.get("events", [])]
        sample = Sample(t, G, events, diff(self._prev, G), dict(self._unreadable))
        self._prev = G
        return sample

    def _graph(self) -> nx.MultiDiGraph:
        G = new_graph()
        G.graph.update(self._graph_attrs)
        theta = self._theta
        G.add_nodes_from((m, {**a, "theta": theta[m]} if m in theta else a) for m, a in self._members.items())
        G.add_edges_from((u, v, k, a) for (u, v, k), a in self._edges.items())
        return G


def _remap(recorded: list[str], now: tuple[str, ...]) -> Callable[[np.ndarray], np.ndarray]:
    """θ in the ``recorded`` attribute order → θ in the ``now`` order, by name."""
    pairs = [(i, recorded.index(name)) for i, name in enumerate(now) if name in recorded]
    to = np.array([i for i, _ in pairs], dtype=int)
    frm = np.array([j for _, j in pairs], dtype=int)

    def remap(theta: np.ndarray) -> np.ndarray:
        out = np.full(len(now), np.nan)
        out[to] = theta[frm]
        return out

    return remap


def _known(d: dict[Any, Any], key: Any) -> dict[Any, Any]:
    if key not in d:
        raise KeyError(f"{key} is not in the graph")
    return d


class SamplesWriter:
    """Writes samples to ``path`` as they come, one gzip-compressed JSON line each.

    Parameters
    ----------
    path : Path
        The file (``.jsonl.gz`` by convention); replaced if it exists.
    header : mapping
        What the file says about its run (the version, the configuration …), after ``format``.
    """

    def __init__(self, path: str | Path, header: Mapping[str, Any]) -> None:
        self.path = check_writable(Path(path), "samples file")
        self._encoder = SampleEncoder()
        # Level 1: a fifth of level 9's time for a file about a tenth larger (a live run pays it).
        self._gz = gzip.GzipFile(self.path, "wb", compresslevel=1, mtime=0)
        self._line({"format": FORMAT, **header, "theta": {k: list(v) for k, v in SCHEMAS.items()}})

    def write(self, sample: Sample) -> None:
        """Append ``sample`` (and make it readable now, should the run be killed next)."""
        self._line(self._encoder.encode(sample))

    def note(self, key: str, value: Any) -> None:
        """Append a note: something about the run known only while or after it ran."""
        self._line({"note": key, "value": json.loads(json.dumps(value, default=str))})

    def _line(self, record: Mapping[str, Any]) -> None:
        self._gz.write((_dumps(record) + "\n").encode())
        self._gz.flush()  # a sync flush: everything so far decompresses even without the end

    def close(self) -> None:
        """End the file (its gzip trailer). Idempotent."""
        self._gz.close()


def _open_text(path: Path) -> TextIO:
    raw = path.open("rb")
    try:
        gz = raw.read(2) == _GZIP_MAGIC
        raw.seek(0)
    except OSError:
        raw.close()
        raise
    stream = gzip.GzipFile(fileobj=raw, mode="rb") if gz else raw
    return io.TextIOWrapper(stream, encoding="utf-8", newline="\n")


class SamplesReader:
    """Reads a samples file: the header at once, the samples one at a time.

    A file that ends in the middle of a line or of its compressed stream (a run killed while
    writing) ends at its last complete sample: ``truncated`` says so after reading.

    Attributes
    ----------
    header : dict
        The first line.
    notes : dict
        The notes read so far (the last value of each key).
    truncated : bool
        The file ended without its proper end.

    Raises
    ------
    SamplesError
        The file is unreadable, not a samples file, of another format version, or corrupt;
        the message names the file and the line.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.notes: dict[str, Any] = {}
        self.truncated = False
        self.line = 0
        try:
            self._f = _open_text(self.path)
        except OSError as exc:
            raise SamplesError(f"{self.path}: cannot read the samples file: {exc}") from exc
        try:
            try:
                first = self._next_line()
            except SamplesError as exc:
                why = exc.__cause__
                raise SamplesError(f"{self.path}, line 1: not a stream-viz samples file ({why})") from exc
            if first is None:
                raise SamplesError(f"{self.path}: empty, not a stream-viz samples file")
            try:
                header = json.loads(first)
            except ValueError:
                header = None
            if not isinstance(header, dict) or "format" not in header:
                raise SamplesError(f"{self.path}, line 1: not a stream-viz samples file (no header)")
            if header["format"] != FORMAT:
                raise SamplesError(f"{self.path}, line 1: samples format {header['format']!r}; "
                                   f"this stream-viz reads {FORMAT!r}")
        except BaseException:
            self._f.close()
            raise
        self.header: dict[str, Any] = header
        try:
            self._decoder = SampleDecoder(header.get("theta"))
        except (AttributeError, TypeError, ValueError) as exc:
            self._f.close()
            raise SamplesError(f"{self.path}, line 1: a malformed header ({exc})") from exc

    def _next_line(self) -> str | None:
        """The next complete line, None at the end (also at a cut-off end: ``truncated``)."""
        if self.truncated:
            return None
        try:
            line = self._f.readline()
        except EOFError:  # the compressed stream stops short: a killed run
            self.truncated = True
            return None
        except (OSError, zlib.error, UnicodeDecodeError) as exc:
            raise SamplesError(f"{self.path}, line {self.line + 1}: corrupt samples file ({exc})") from exc
        if not line:
            return None
        if not line.endswith("\n"):  # cut off in the middle of a line
            self.truncated = True
            return None
        self.line += 1
        return line

    def __iter__(self) -> Iterator[Sample]:
        while (line := self._next_line()) is not None:
            try:
                rec = json.loads(line)
                if "note" in rec:
                    self.notes[str(rec["note"])] = rec.get("value")
                    continue
                sample = self._decoder.decode(rec)
            except (ValueError, KeyError, TypeError, AttributeError) as exc:
                raise SamplesError(f"{self.path}, line {self.line}: not a sample record "
                                   f"({type(exc).__name__}: {exc})") from exc
            yield sample

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> SamplesReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_samples(path: str | Path) -> tuple[dict[str, Any], list[Sample], dict[str, Any]]:
    """Return the header, every sample and the notes of a samples file (small files, tests)."""
    with SamplesReader(path) as reader:
        samples = list(reader)
        return reader.header, samples, reader.notes
