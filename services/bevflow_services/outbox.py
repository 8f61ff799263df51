"""A persistent, ordered queue of outgoing alerts in a SQLite file, so none is lost while their
receiver (an MQTT broker, a webhook) is unreachable or the sending service restarts.

Messages go out oldest first; one is marked sent only once the receiver acknowledged it. A
message already in the outbox (the same topic and payload: the bus may deliver an event twice)
is not queued again, and sent messages are kept a while (``keep_s``) so a late duplicate still
finds its twin. Across a crash between the acknowledgement and the mark, a message can go out
twice (at least once); otherwise each goes out once, in order.
"""

from __future__ import annotations

import hashlib
import sqlite3
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS outbox (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    digest TEXT NOT NULL UNIQUE,
    topic TEXT NOT NULL,
    payload BLOB NOT NULL,
    queued_ns INTEGER NOT NULL,
    sent_ns INTEGER
);
CREATE INDEX IF NOT EXISTS outbox_unsent ON outbox (seq) WHERE sent_ns IS NULL;
"""
KEEP_SENT_S = 7 * 24 * 3600.0


@dataclass(frozen=True)
class Message:
    seq: int
    topic: str
    payload: bytes


class Outbox:
    """Thread-safe: the bus's threads add, the sender takes and marks."""

    def __init__(self, path: str | Path, keep_s: float = KEEP_SENT_S) -> None:
        self.path = str(path)
        self.keep_ns = int(keep_s * 1e9)
        self._lock = threading.Lock()
        self._added = threading.Condition(self._lock)
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")  # an acknowledged add survives a power cut
        self._db.executescript(SCHEMA)

    def add(self, topic: str, payload: bytes) -> bool:
        """Queue a message; False if the same one is already queued or was sent."""
        digest = hashlib.sha256(topic.encode() + b"\0" + payload).hexdigest()
        with self._added:
            cursor = self._db.execute("INSERT OR IGNORE INTO outbox (digest, topic, payload, queued_ns) VALUES (?, ?, ?, ?)",
                                      (digest, topic, payload, time.time_ns()))
            if cursor.rowcount:
                self._added.notify_all()
            return bool(cursor.rowcount)

    def next(self, timeout: float) -> Message | None:
        """The oldest unsent message, waiting up to ``timeout`` seconds for one."""
        deadline = time.monotonic() + timeout
        with self._added:
            while True:
                row = self._db.execute("SELECT seq, topic, payload FROM outbox WHERE sent_ns IS NULL "
                                       "ORDER BY seq LIMIT 1").fetchone()
                left = deadline - time.monotonic()
                if row is not None or left <= 0:
                    return None if row is None else Message(row[0], row[1], bytes(row[2]))
                self._added.wait(left)

    def mark_sent(self, seq: int) -> None:
        now = time.time_ns()
        with self._lock:
            self._db.execute("UPDATE outbox SET sent_ns = ? WHERE seq = ?", (now, seq))
            self._db.execute("DELETE FROM outbox WHERE sent_ns IS NOT NULL AND sent_ns < ?", (now - self.keep_ns,))

    def backlog(self) -> int:
        """Messages not yet acknowledged by their receiver."""
        with self._lock:
            return self._db.execute("SELECT count(*) FROM outbox WHERE sent_ns IS NULL").fetchone()[0]

    def close(self) -> None:
        with self._lock:
            self._db.close()


def deliver(outbox: Outbox, send: Callable[[Message, threading.Event], bool], stop: threading.Event) -> None:
    """Send the outbox, oldest first, each once the one before it was acknowledged:
    ``send(message, stop)`` returns True once the receiver has it, False if ``stop`` came first."""
    while not stop.is_set():
        message = outbox.next(timeout=0.5)
        if message is not None and send(message, stop):
            outbox.mark_sent(message.seq)
