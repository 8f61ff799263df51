from __future__ import annotations

import pytest

from bevflow_services.storage import StorageError
from bevflow_services.storage.backend import backend_kind, open_backend, redact


@pytest.mark.parametrize(
    ("url", "kind"),
    [
        ("postgresql://bevflow:secret@db.local/history", "postgresql"),
        ("postgres://db.local/history", "postgresql"),
        ("/var/lib/bevflow/history.db", "sqlite"),
        ("history.db", "sqlite"),
        ("sqlite:///var/lib/bevflow/history.db", "sqlite"),
        ("mysql://db.local/history", StorageError),
        ("https://example.com/history.db", StorageError),
    ],
)
def test_the_url_names_the_backend(url: str, kind) -> None:
    if isinstance(kind, str):
        assert backend_kind(url) == kind
    else:
        with pytest.raises(kind, match="use a SQLite file path, sqlite:///PATH or postgresql://"):
            backend_kind(url)


@pytest.mark.parametrize(
    ("url", "shown"),
    [
        ("postgresql://bevflow:s3cr3t@db/history", "postgresql://bevflow:***@db/history"),
        ("postgresql://bevflow@db/history", "postgresql://bevflow@db/history"),
        ("/data/history.db", "/data/history.db"),
    ],
)
def test_passwords_never_show(url: str, shown: str) -> None:
    assert redact(url) == shown


def test_an_empty_url_is_refused() -> None:
    with pytest.raises(StorageError, match="database URL is empty"):
        open_backend("  ")
