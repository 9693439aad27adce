"""One exception hierarchy; only the CLI turns these into exit codes."""

from __future__ import annotations


class StreamVizError(Exception):
    """Base of every error stream-viz raises on purpose."""


class ConfigError(StreamVizError):
    """A configuration file or option is malformed (names the key and the file)."""


class PluginError(StreamVizError):
    """A plugin failed to load, validate or run (names the plugin and where)."""


class StoreError(StreamVizError):
    """The alert database is unreadable, corrupt or not ours (names the file)."""


class SamplesError(StreamVizError):
    """A samples file is unreadable, corrupt or not ours (names the file and the line)."""


class CollectError(StreamVizError):
    """Observing the ROS 2 system or the OS failed in a way we cannot skip."""


class ModelError(StreamVizError):
    """A member id or graph operation is invalid."""


class OutputError(StreamVizError):
    """An output path (recording, report, database) cannot be written."""


class DemoError(StreamVizError):
    """The demo robot could not be started or driven."""
