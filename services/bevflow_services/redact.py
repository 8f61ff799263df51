"""Credentials kept out of log lines and error messages.

Camera streams (``rtsp://admin:pw@cam``), database URLs (``postgresql://bevflow:pw@db``) and API
tokens (``?token=bvf_...`` on a websocket URL, which uvicorn logs with the path) all reach log
lines. ``redact`` masks them in any text; ``install`` puts ``RedactSecrets`` on the handlers of
the root logger and on uvicorn's loggers, so every record a service writes is masked, whatever
code logged it, tracebacks included.

>>> redact("cannot open camera source 'rtsp://admin:s3cret@10.0.0.7/stream1'")
"cannot open camera source 'rtsp://admin:***@10.0.0.7/stream1'"
>>> redact('GET /ws/alerts?types=x&token=bvf_abc123 HTTP/1.1')
'GET /ws/alerts?types=x&token=*** HTTP/1.1'
"""

from __future__ import annotations

import logging
import re

MASK = "***"
# scheme://user:password@ : the password runs to the last '@' before the host's '/' (an
# unencoded '@' inside a password stays masked).
_URL_PASSWORD = re.compile(r"\b([a-zA-Z][a-zA-Z0-9+.-]*://[^/\s:@'\"]*):[^/\s'\"]*@")
# Query parameters and key=value pairs that carry a secret.
_SECRET_PARAMETER = re.compile(r"(?i)\b((?:access_)?token|password|passwd|pwd|secret|api_key|apikey)=[^&\s#'\";,]+")
# The gateway's API tokens, wherever they appear (an Authorization header echoed in an error).
_API_TOKEN = re.compile(r"\bbvf_[A-Za-z0-9_-]+")
# The loggers whose records uvicorn writes itself, with handlers of its own.
UVICORN_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.access")


def redact(text: str) -> str:
    """``text`` with URL passwords, secret query parameters and API tokens replaced by ``***``."""
    text = _URL_PASSWORD.sub(rf"\1:{MASK}@", text)
    text = _SECRET_PARAMETER.sub(rf"\1={MASK}", text)
    return _API_TOKEN.sub(f"bvf_{MASK}", text)


class RedactSecrets(logging.Filter):
    """Masks credentials in a record's message, its arguments and its traceback before any
    handler formats it."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: redact(v) if isinstance(v, str) else v for k, v in record.args.items()}
        if record.exc_info and not record.exc_text:
            record.exc_text = redact(logging.Formatter().formatException(record.exc_info))
        return True


def install() -> None:
    """Mask every record of this process: on the root logger's handlers (``basicConfig``) and on
    uvicorn's loggers (their own handlers, replaced when uvicorn configures logging, so the
    filter goes on the loggers themselves). Calling it again adds nothing."""
    targets: list[logging.Filterer] = [*logging.getLogger().handlers]
    targets += [logging.getLogger(name) for name in UVICORN_LOGGERS]
    for target in targets:
        if not any(isinstance(f, RedactSecrets) for f in target.filters):
            target.addFilter(RedactSecrets())
