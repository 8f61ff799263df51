"""What every store over a ``Backend`` shares: opening a URL with its tables migrated, closing."""

from __future__ import annotations

from typing import Self

from bevflow_services.storage.backend import Backend, open_backend
from bevflow_services.storage.schema import migrate


class Database:
    """Tables behind a ``Backend``; a context manager that closes it."""

    def __init__(self, backend: Backend) -> None:
        self.backend = backend

    @classmethod
    def open(cls, url: str) -> Self:
        """Open (creating or migrating its tables) the database ``url`` names: a SQLite file path,
        ``sqlite:///PATH`` or a ``postgresql://`` URL. ``StorageError`` says what is wrong."""
        backend = open_backend(url)
        try:
            migrate(backend)
        except Exception:
            backend.close()
            raise
        return cls(backend)

    @property
    def url(self) -> str:
        return self.backend.url

    def close(self) -> None:
        self.backend.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()
