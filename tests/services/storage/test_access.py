"""``AccessStore`` on both backends: users, sessions, API tokens and the audit log."""

from __future__ import annotations

import pytest

from bevflow_services.storage import HistoryDatabase
from bevflow_services.storage.access import AccessStore, check_user_name, digest
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

S = 1_000_000_000
T0 = 1_700_000_000 * S


@pytest.fixture
def store(database_url: str):  # noqa: F811
    with AccessStore.open(database_url) as opened:
        yield opened


def test_users_are_added_listed_and_removed(store: AccessStore) -> None:
    store.add_user("zoe", "viewer", "hash-z", T0)
    store.add_user("ana", "admin", "hash-a", T0 + S)
    assert [(u.name, u.role, u.password_hash) for u in store.users()] == [("ana", "admin", "hash-a"), ("zoe", "viewer", "hash-z")]
    assert store.user_count() == 2
    assert store.user("ana").created_ns == T0 + S
    store.remove_user("zoe")
    assert [u.name for u in store.users()] == ["ana"]
    assert store.user("zoe") is None


@pytest.mark.parametrize(
    ("name", "role", "error"),
    [
        ("ana", "admin", "already exists"),
        ("bob", "root", "role 'root'"),
        ("", "viewer", "user name"),
        (" bob", "viewer", "user name"),
        ("a:b", "viewer", "user name"),
        ("x" * 65, "viewer", "user name"),
    ],
)
def test_bad_users_are_refused(store: AccessStore, name: str, role: str, error: str) -> None:
    store.add_user("ana", "admin", "h", T0)
    with pytest.raises(ValueError, match=error):
        store.add_user(name, role, "h", T0)
    assert [u.name for u in store.users()] == ["ana"]


@pytest.mark.parametrize("action", ["remove_user", "set_password", "set_role"])
def test_changing_an_unknown_user_is_a_key_error(store: AccessStore, action: str) -> None:
    args = {"remove_user": ("nobody",), "set_password": ("nobody", "h"), "set_role": ("nobody", "viewer")}[action]
    with pytest.raises(KeyError, match="nobody"):
        getattr(store, action)(*args)


def test_the_first_admin_is_created_only_while_there_are_no_users(store: AccessStore) -> None:
    first = store.add_first_admin("root", "h1", T0)
    assert first is not None and first.role == "admin"
    assert store.add_first_admin("other", "h2", T0) is None
    assert [u.name for u in store.users()] == ["root"]


def test_sessions_find_their_user_until_they_expire_or_are_removed(store: AccessStore) -> None:
    store.add_user("ana", "operator", "h", T0)
    store.add_session("secret-1", "ana", T0, T0 + 10 * S)
    assert store.session_user("secret-1", T0 + 9 * S).name == "ana"
    assert store.session_user("secret-1", T0 + 10 * S) is None  # expired
    assert store.session_user("secret-2", T0) is None
    store.add_session("secret-2", "ana", T0, T0 + 10 * S)
    store.remove_session("secret-2")
    assert store.session_user("secret-2", T0) is None


def test_secrets_are_stored_only_as_digests(store: AccessStore) -> None:
    store.add_user("ana", "operator", "h", T0)
    store.add_session("session-secret", "ana", T0, T0 + S)
    store.add_token("token-secret", "ana", "ci", T0)
    rows = store.backend.query("SELECT digest FROM sessions UNION ALL SELECT digest FROM api_tokens")
    assert sorted(r[0] for r in rows) == sorted([digest("session-secret"), digest("token-secret")])
    assert digest("abc") == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # SHA-256 test vector


def test_a_new_password_or_removal_ends_sessions_and_tokens(store: AccessStore) -> None:
    store.add_user("ana", "operator", "h", T0)
    store.add_session("s1", "ana", T0, T0 + 100 * S)
    store.add_token("t0", "ana", "made with the old password", T0)
    store.set_password("ana", "h2")
    assert store.session_user("s1", T0) is None
    assert store.token_user("t0") is None
    assert store.user("ana").password_hash == "h2"
    store.add_token("t1", "ana", "ci", T0)
    assert store.token_user("t1").name == "ana"
    store.remove_user("ana")
    assert store.token_user("t1") is None
    assert store.tokens() == []


def test_tokens_are_listed_and_revoked(store: AccessStore) -> None:
    store.add_user("ana", "operator", "h", T0)
    store.add_user("bob", "viewer", "h", T0)
    first = store.add_token("t1", "ana", "wall screen", T0)
    store.add_token("t2", "bob", "script", T0 + S)
    assert [(t.user, t.label) for t in store.tokens()] == [("ana", "wall screen"), ("bob", "script")]
    assert [t.label for t in store.tokens("bob")] == ["script"]
    store.revoke_token(first.id)
    assert store.token_user("t1") is None
    with pytest.raises(KeyError):
        store.revoke_token(first.id)
    with pytest.raises(KeyError, match="nobody"):
        store.add_token("t3", "nobody", "", T0)


@pytest.mark.parametrize(
    ("filters", "expected_ids"),
    [
        ({}, [3, 2, 1]),
        ({"user": "ana"}, [3, 1]),
        ({"track_id": 7}, [2, 1]),
        ({"since_ns": T0 + S}, [3, 2]),
        ({"until_ns": T0 + S}, [2, 1]),
        ({"limit": 1, "offset": 1}, [2]),
    ],
)
def test_the_audit_log_is_filtered_and_paged_newest_first(store: AccessStore, filters: dict, expected_ids: list[int]) -> None:
    store.audit(T0, "ana", "trajectory", 7, "10.0.0.5")
    store.audit(T0 + S, "bob", "contacts", 7, "10.0.0.6", "distance_m=2")
    store.audit(T0 + 2 * S, "ana", "contacts", 9, "10.0.0.5")
    entries, total = store.audit_log(**filters)
    assert [(e.time_ns - T0) // S + 1 for e in entries] == expected_ids
    assert total == len(expected_ids) if "limit" not in filters else total == 3
    first = store.audit_log(user="bob")[0][0]
    assert (first.action, first.track_id, first.client, first.detail) == ("contacts", 7, "10.0.0.6", "distance_m=2")


def test_users_live_in_the_history_database(database_url: str) -> None:  # noqa: F811
    with HistoryDatabase.open(database_url) as history:
        history.row_counts()
    with AccessStore.open(database_url) as store:
        store.add_user("ana", "admin", "h", T0)
    with HistoryDatabase.open(database_url) as history, AccessStore(history.backend) as again:
        assert [u.name for u in again.users()] == ["ana"]


@pytest.mark.parametrize("name", ["ana", "Ana Lopez", "ops.night-shift", "é"])
def test_ordinary_names_are_accepted(name: str) -> None:
    assert check_user_name(name) == name


def test_text_with_nul_characters_is_looked_up_and_stored_safely(store: AccessStore) -> None:
    """PostgreSQL refuses NUL in text: such a name is simply unknown, and audit text is escaped."""
    store.add_user("ana", "admin", "h", T0)
    assert store.user("an\x00a") is None
    with pytest.raises(KeyError):
        store.remove_user("\x00")
    with pytest.raises(KeyError):
        store.add_token("t", "\x00", "", T0)
    store.audit(T0, "ana", "track_summaries", None, "10.0.0.5", "zone=a\x00b")
    assert store.audit_log(user="\x00")[1] == 0
    assert store.audit_log()[0][0].detail == "zone=a\\x00b"
