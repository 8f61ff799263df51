"""Fan-out of live messages to websocket clients, one bounded queue per client.

A client that stops reading (a frozen browser tab, a slow link) must not slow the others or grow
memory without bound. Each subscriber therefore owns a small ``asyncio.Queue``; publishing never
waits, and when a queue is full its OLDEST item is dropped, because a live view wants the newest
state and an alert feed would rather skip stale alerts than stall.

``publish`` may be called from any thread: the item is handed to each subscriber's own event loop
with ``call_soon_threadsafe`` (the bus delivers on its own threads, tests call from the test
thread), and directly when the caller already runs in that loop.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Generic, TypeVar

T = TypeVar("T")


class Subscription(Generic[T]):
    """One client's bounded inbox. ``dropped`` counts items discarded because it was full."""

    def __init__(self, maxsize: int, accept: Callable[[T], bool] | None = None) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize must be at least 1, got {maxsize}")
        self.queue: asyncio.Queue[T] = asyncio.Queue(maxsize=maxsize)
        self.loop = asyncio.get_running_loop()
        self.accept = accept
        self.dropped = 0

    def offer(self, item: T) -> None:
        """Queue ``item`` without waiting, dropping the oldest one if full. Runs in ``self.loop``."""
        if self.accept is not None and not self.accept(item):
            return
        while self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(item)

    async def get(self) -> T:
        return await self.queue.get()


class Broadcaster(Generic[T]):
    """Delivers each published item to every current subscriber that accepts it."""

    def __init__(self, maxsize: int = 64) -> None:
        self.maxsize = maxsize
        self._subscribers: list[Subscription[T]] = []
        self._observers: list[Callable[[T], object]] = []
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._subscribers)

    @property
    def subscriptions(self) -> list[Subscription[T]]:
        """The current subscribers (a copy), e.g. to report how much each one dropped."""
        with self._lock:
            return list(self._subscribers)

    @asynccontextmanager
    async def subscribe(self, accept: Callable[[T], bool] | None = None, maxsize: int | None = None) -> AsyncIterator[Subscription[T]]:
        """Register a subscriber for the duration of the ``async with`` block."""
        sub: Subscription[T] = Subscription(maxsize or self.maxsize, accept)
        with self._lock:
            self._subscribers.append(sub)
        try:
            yield sub
        finally:
            with self._lock:
                self._subscribers.remove(sub)

    def observe(self, callback: Callable[[T], object]) -> None:
        """Call ``callback(item)`` for every item from now on, in ``publish`` itself, before any
        subscriber can see it (the gateway's own bookkeeping: recent alerts, metrics); it must be
        quick and thread-safe. Observers are not subscribers: they are not counted in ``len``."""
        with self._lock:
            self._observers.append(callback)

    def publish(self, item: T) -> None:
        """Hand ``item`` to every observer, then to every subscriber; never blocks."""
        with self._lock:
            subscribers = list(self._subscribers)
            observers = list(self._observers)
        for observer in observers:
            observer(item)
        try:
            current = asyncio.get_running_loop()
        except RuntimeError:
            current = None
        for sub in subscribers:
            if sub.loop is current:
                sub.offer(item)
            elif not sub.loop.is_closed():
                sub.loop.call_soon_threadsafe(sub.offer, item)


async def pump(sub: Subscription[T], send: Callable[[T], Awaitable[None]]) -> None:
    """Forward a subscription's items to ``send`` until cancelled or ``send`` raises.

    Only this client's task waits on a slow ``send``; the broadcaster keeps dropping the oldest
    items of this client's queue meanwhile.
    """
    while True:
        item = await sub.get()
        await send(item)
