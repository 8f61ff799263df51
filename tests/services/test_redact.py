"""Credentials are masked in text and in every log record, tracebacks included."""

from __future__ import annotations

import io
import logging

import pytest

from bevflow_services.redact import RedactSecrets, install, redact


@pytest.mark.parametrize(("text", "expected"), [
    ("rtsp://admin:s3cret@10.0.0.7:554/stream1", "rtsp://admin:***@10.0.0.7:554/stream1"),
    ("cannot open camera source 'rtsp://admin:p@ss@cam/x'", "cannot open camera source 'rtsp://admin:***@cam/x'"),
    ("postgresql://bevflow:hunter2@db/history", "postgresql://bevflow:***@db/history"),
    ('"WebSocket /ws/alerts?types=camera_down&token=bvf_Ab-1_z" [accepted]',
     '"WebSocket /ws/alerts?types=camera_down&token=***" [accepted]'),
    ("GET /api/occupancy?access_token=abc&x=1 HTTP/1.1", "GET /api/occupancy?access_token=***&x=1 HTTP/1.1"),
    ("Authorization: Bearer bvf_0123456789abcdef", "Authorization: Bearer bvf_***"),
    ("host=db password=hunter2 dbname=h", "host=db password=*** dbname=h"),
    # nothing secret: unchanged
    ("rtsp://admin@10.0.0.7/stream1", "rtsp://admin@10.0.0.7/stream1"),
    ("rtsp://10.0.0.7:554/stream1", "rtsp://10.0.0.7:554/stream1"),
    ("sqlite:////data/history.db", "sqlite:////data/history.db"),
    ("GET /api/tracks?limit=10&offset=5 HTTP/1.1", "GET /api/tracks?limit=10&offset=5 HTTP/1.1"),
])
def test_redact(text: str, expected: str) -> None:
    assert redact(text) == expected


def _logger(name: str) -> tuple[logging.Logger, io.StringIO]:
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.addFilter(RedactSecrets())
    logger = logging.getLogger(name)
    logger.handlers[:] = [handler]
    logger.propagate = False
    return logger, out


def test_filter_masks_message_arguments_and_traceback() -> None:
    logger, out = _logger("tests.redact.filter")
    logger.warning("cannot open %s", "rtsp://u:secret1@cam/s")
    logger.warning("%(url)s failed", {"url": "postgresql://u:secret2@db/h"})
    try:
        raise RuntimeError("token=bvf_secret3 rejected")
    except RuntimeError:
        logger.exception("request %s", "/ws/alerts?token=bvf_secret4")
    text = out.getvalue()
    for secret in ("secret1", "secret2", "secret3", "secret4"):
        assert secret not in text
    assert "rtsp://u:***@cam/s" in text and "Traceback" in text


def test_install_covers_the_root_handlers_and_uvicorns_loggers() -> None:
    root = logging.getLogger()
    handler = logging.StreamHandler(io.StringIO())
    root.addHandler(handler)
    try:
        install()
        install()
        assert sum(isinstance(f, RedactSecrets) for f in handler.filters) == 1
        for name in ("uvicorn.error", "uvicorn.access"):
            assert sum(isinstance(f, RedactSecrets) for f in logging.getLogger(name).filters) == 1
    finally:
        root.removeHandler(handler)
