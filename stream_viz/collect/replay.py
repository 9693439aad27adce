"""A collector that replays a samples file: the monitor's `Collector` with a recording for a system.

It has the live collector's interface (``start``, ``sample``, ``close``), so the monitor's record,
detect, store, diagnose and show steps run the same code on a replay as on the live run.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from stream_viz.collect.samples_file import SamplesReader
from stream_viz.errors import CollectError
from stream_viz.records import Sample


class ReplayCollector:
    """Returns the samples of ``path`` in order, one per `sample` call, read as they are needed.

    Attributes
    ----------
    header : dict
        The samples file's header (version, configuration, start of the run).
    """

    def __init__(self, path: str | Path) -> None:
        self.reader = SamplesReader(path)
        self.header: dict[str, Any] = self.reader.header
        self._samples: Iterator[Sample] = iter(self.reader)
        self._next: Sample | None = None
        self._advance()

    def _advance(self) -> None:
        self._next = next(self._samples, None)

    @property
    def done(self) -> bool:
        """True once every sample was returned."""
        return self._next is None

    @property
    def next_t(self) -> float | None:
        """The time of the sample `sample` returns next (None when done)."""
        return None if self._next is None else self._next.t

    @property
    def notes(self) -> dict[str, Any]:
        """The file's notes read so far (all of them once `done`)."""
        return self.reader.notes

    @property
    def truncated(self) -> bool:
        """The file ended without its proper end (a run killed while writing it)."""
        return self.reader.truncated

    def start(self) -> None:
        """Nothing to start: the file is open."""

    def sample(self) -> Sample:
        """Return the next recorded sample."""
        if self._next is None:
            raise CollectError(f"{self.reader.path}: no samples left to replay")
        sample = self._next
        self._advance()
        return sample

    def close(self) -> None:
        self.reader.close()
