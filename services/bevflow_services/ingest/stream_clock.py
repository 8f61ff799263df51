"""Capture times from a stream's own timestamps, on this host's wall clock.

A camera stamps its frames (RTP / MPEG-TS presentation times, from its own clock); the time a
frame reaches the ingest adds network and decoder delay that varies from frame to frame. So the
first frame's timestamp is anchored to the wall clock when it arrives, and every later frame is
stamped ``anchor + (its timestamp - the first one's)``: frames keep the spacing the camera gave
them.

A live stream's frame is never stamped later than it arrived. Opening a stream buffers its first
frames while the decoder probes them, so the first frame arrives late and its anchor would put
later frames in the future; the anchor therefore moves back whenever a frame arrives earlier than
its stamp. If the stream's clock falls behind the wall clock by more than ``max_drift_ns``, or
its timestamps jump (backwards at all, forwards by more than the bound), the clock is anchored
again at the frame that shows it, and the log says so (once; later ones at debug level).

A file has no arrival times worth following: its frames are read as fast as they decode, and the
reader waits for each stamp instead (``follow_arrivals=False``), so the file plays in real time.
"""

from __future__ import annotations

import logging

from bevflow.units import NS_PER_S

log = logging.getLogger(__name__)

MAX_DRIFT_NS = 2 * NS_PER_S


class StreamClock:
    """Stamps the frames of one stream (integer ns, wall clock); ``name`` is for the log."""

    def __init__(self, name: str, follow_arrivals: bool = True, max_drift_ns: int = MAX_DRIFT_NS) -> None:
        self.name = name
        self.follow_arrivals = follow_arrivals
        self.max_drift_ns = max_drift_ns
        self.reanchors = 0
        self._offset: int | None = None  # wall clock minus stream time
        self._last_pts_ns: int | None = None

    def stamp(self, pts_ns: int | None, now_ns: int) -> int:
        """The capture time of a frame with stream time ``pts_ns`` (None: the stream has none, so
        the frame is stamped when it arrived) that arrived at ``now_ns``."""
        if pts_ns is None:
            return now_ns
        arrival_offset = now_ns - pts_ns
        if self._offset is None:
            self._offset = arrival_offset
        elif self._last_pts_ns is not None and pts_ns < self._last_pts_ns:
            self._reanchor(arrival_offset, "went backwards")
        elif abs(arrival_offset - self._offset) > self.max_drift_ns:
            self._reanchor(arrival_offset, f"are {(arrival_offset - self._offset) / NS_PER_S:+.1f} s off the wall clock")
        elif self.follow_arrivals and arrival_offset < self._offset:
            self._offset = arrival_offset  # this frame came quicker than the anchor allowed for
        self._last_pts_ns = pts_ns
        return pts_ns + self._offset

    def _reanchor(self, offset: int, why: str) -> None:
        self._offset = offset
        self.reanchors += 1
        level = logging.WARNING if self.reanchors == 1 else logging.DEBUG
        log.log(level, "camera source %s: stream timestamps %s; capture times re-anchored to this host's clock%s",
                self.name, why, " (further re-anchors are logged at debug level)" if self.reanchors == 1 else "")
