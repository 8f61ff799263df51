"""Track ids that survive a restart: ids are reserved on disk in blocks before any is published.

A restarted tracker (after a crash, kill -9, a host reboot) must never hand out an id that its
predecessor published, or an operator tracing person #42 would get two people's paths. Writing
the next id after every tick would cost a disk sync per tick; instead the tracker writes the end
of a block of ids before it uses the first of them, and a restart starts past that end. At most a
block of ids is skipped per restart, which is harmless.
"""

from __future__ import annotations

import os
from pathlib import Path

BLOCK = 1000


class TrackIdError(RuntimeError):
    """The reservation file cannot be read or written: the tracker must not start or go on."""


class TrackIdReservation:
    """``first_id(floor)`` once at start, then ``cover(next_id)`` before publishing each tick."""

    def __init__(self, path: Path, block: int = BLOCK) -> None:
        if block < 1:
            raise ValueError("block must be at least 1")
        self.path = Path(path)
        self.block = block
        self.reserved_end = 0  # every id below this may have been published

    def first_id(self, floor: int = 1) -> int:
        """Where this run starts: past every id a previous run may have used, and at least ``floor``."""
        start = max(floor, self._read())
        self._write(start + self.block)
        return start

    def cover(self, next_id: int) -> None:
        """Make sure every id below ``next_id`` is reserved (a write only once per block)."""
        if next_id > self.reserved_end:
            self._write(next_id + self.block)

    def _read(self) -> int:
        try:
            text = self.path.read_text().strip()
        except FileNotFoundError:
            return 0
        except OSError as exc:
            raise TrackIdError(f"{self.path}: cannot read the track id reservation: {exc.strerror}") from exc
        try:
            value = int(text)
        except ValueError:
            raise TrackIdError(f"{self.path}: expected one whole number (the next free track id), got {text[:40]!r}; "
                               "remove the file only if no earlier run's ids matter") from None
        if value < 0:
            raise TrackIdError(f"{self.path}: the next free track id cannot be negative ({value})")
        return value

    def _write(self, end: int) -> None:
        partial = self.path.with_name(self.path.name + ".partial")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with partial.open("w") as out:
                out.write(f"{end}\n")
                out.flush()
                os.fsync(out.fileno())
            os.replace(partial, self.path)
        except OSError as exc:
            raise TrackIdError(f"{self.path}: cannot write the track id reservation: {exc.strerror}") from exc
        self.reserved_end = end
