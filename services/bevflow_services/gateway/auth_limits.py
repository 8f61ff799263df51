"""Login rate limiting: failed logins per user name and client address.

After ``max_failures`` failed logins for one (name, address) pair within ``window_s`` seconds,
further attempts for that pair, right or wrong, are refused with 429 until the oldest of those
failures is ``window_s`` old; a success clears the pair. Keyed on the pair so that someone guessing
one account's password from one place cannot lock its owner out everywhere.

An attempt is counted as a failure the moment it is let through (``attempt``), before its password
is checked, and cleared again if it succeeds: checking and counting in two steps would let
parallel requests all pass the check before any of them was counted.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable


class LoginLimiter:
    def __init__(self, max_failures: int = 5, window_s: float = 300.0, max_keys: int = 10_000,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if max_failures < 1 or window_s <= 0:
            raise ValueError(f"max_failures must be >= 1 and window_s > 0, got {max_failures}, {window_s}")
        self.max_failures = max_failures
        self.window_s = window_s
        self.max_keys = max_keys
        self.clock = clock
        self._lock = threading.Lock()
        self._failures: OrderedDict[tuple[str, str], deque[float]] = OrderedDict()

    def attempt(self, name: str, client: str) -> int:
        """Let one attempt of the pair through, counted as a failure until ``succeeded`` or
        ``withdraw``, and say 0; or, at the limit, count nothing and say the seconds to wait."""
        now = self.clock()
        key = (name.casefold(), client)
        with self._lock:
            failures = self._recent(*key, now)
            if failures is None:
                failures = self._failures[key] = deque(maxlen=self.max_failures)
            elif len(failures) >= self.max_failures:
                return max(1, math.ceil(failures[0] + self.window_s - now))
            failures.append(now)
            self._failures.move_to_end(key)
            while len(self._failures) > self.max_keys:  # bounded memory under a spray of names
                self._failures.popitem(last=False)
            return 0

    def withdraw(self, name: str, client: str) -> None:
        """Uncount the pair's latest attempt: its password was never checked (the server was busy)
        or it succeeded."""
        with self._lock:
            failures = self._failures.get((name.casefold(), client))
            if failures:
                failures.pop()

    def succeeded(self, name: str, client: str) -> None:
        with self._lock:
            self._failures.pop((name.casefold(), client), None)

    def _recent(self, name: str, client: str, now: float) -> deque[float] | None:
        failures = self._failures.get((name, client))
        if failures is None:
            return None
        while failures and failures[0] <= now - self.window_s:
            failures.popleft()
        return failures
