"""The site file the gateway was started with, which the calibration routes read and save to."""

from __future__ import annotations

from pathlib import Path


def site_file_of(value: str | Path) -> Path | None:
    """The path to give the gateway (``app.state.site_file``) for its ``--site`` value: the file,
    or None for a built-in site name, which cannot be saved."""
    path = Path(value)
    return path.resolve() if path.is_file() else None
