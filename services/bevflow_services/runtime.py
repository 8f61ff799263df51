"""What every service shares at run time, whichever command starts it: the site it runs for, the
signals that stop it, work it repeats on a thread of its own, and the error a user can fix."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from bevflow.site import Site, SiteError, load_site_or_builtin

log = logging.getLogger(__name__)

# A camera silent this long is down, for the tracker's camera_down alert and the gateway's camera
# health alike: a lost stream is then reported within 5 s of its last frame, with margin for the
# last frames still on their way. Cameras send 2-10 frames a second, so a few lost or late ones
# do not reach it.
CAMERA_SILENCE_S = 4.0
# A camera not heard from since the tracker started is reported down only after this long: when a
# whole site starts, the detectors load their models before the first results (about 10 s in
# ``./run demo`` on 2 cores), and each camera counted as down for that would be one false alert.
CAMERA_FIRST_REPORT_S = 30.0


class UserError(Exception):
    """Something the user can fix (a bad path, file or option). Printed as one line, no traceback."""


@contextmanager
def periodically(every_s: float, action: Callable[[], object], name: str) -> Iterator[None]:
    """Call ``action`` every ``every_s`` seconds on a thread named ``name`` while the block runs.
    An exception is logged and the next call tries again: repeated chores (reporting metrics,
    ending lapsed alerts) must never stop the service they serve."""
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(every_s):
            try:
                action()
            except Exception:
                log.exception("%s failed; trying again in %g s", name, every_s)

    thread = threading.Thread(target=loop, name=name, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity, where the system tells)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event set by SIGINT or SIGTERM while the block runs; the previous handlers come back
    after it. Wait on it with a timeout so the handler gets to run promptly on the main thread."""
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def service_site(args: argparse.Namespace) -> tuple[Site, str]:
    """The site a service runs for (``--site``: a file or a built-in name) and its bus name
    (``--site-id``, by default the ``site`` field of the file), the same way for every service."""
    try:
        site = load_site_or_builtin(args.site)
    except SiteError as exc:
        raise UserError(str(exc)) from None
    site_id = getattr(args, "site_id", None) or site.site
    return site, site_id
