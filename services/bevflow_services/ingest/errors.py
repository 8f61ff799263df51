"""The error of a camera source that cannot be opened or read."""

from __future__ import annotations


class SourceError(RuntimeError):
    """A source that cannot be opened or read (the message names it, password masked)."""
