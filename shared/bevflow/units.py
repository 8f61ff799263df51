"""Units shared by every part of bevflow.

Times cross process boundaries and sit in storage as integer nanoseconds since the Unix epoch
(``time_ns``, ``start_ns``, ...): exact, ordered, and as Python's ``time.time_ns()`` gives them.
Seconds are for people and settings; ``NS_PER_S`` converts between the two.

>>> 1_700_000_000_500_000_000 // NS_PER_S
1700000000
"""

from __future__ import annotations

NS_PER_S = 1_000_000_000
