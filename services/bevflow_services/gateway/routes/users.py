"""``/api/users`` and ``/api/audit`` (admin only): accounts, API tokens, and who traced whom.

Users are added, removed, given a new password or role; their API tokens made, listed and
revoked. A new password ends the user's sessions and API tokens; whatever ends a credential also
closes the websockets it opened (``ws.access.until_revoked``).

``bevflow users`` does the same from the command line, on the database directly.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query
from pydantic import BaseModel, Field

from bevflow.schemas import iso_utc

from bevflow_services.gateway.auth import AccessDep, Admin, new_api_token
from bevflow_services.gateway.params import Limit, Offset, Page, to_ns
from bevflow_services.gateway.password_policy import PasswordError
from bevflow_services.storage.access import ROLES

router = APIRouter(prefix="/api", tags=["users"])
UserName = Annotated[str, Path(min_length=1, max_length=64)]


class UserView(BaseModel):
    name: str
    role: str
    created: str


class NewUser(BaseModel):
    name: str = Field(min_length=1, max_length=64)
    role: str = Field(description=f"one of {', '.join(ROLES)}")
    password: str = Field(min_length=1, max_length=1024)


class NewPassword(BaseModel):
    password: str = Field(min_length=1, max_length=1024)


class NewRole(BaseModel):
    role: str = Field(description=f"one of {', '.join(ROLES)}")


class NewToken(BaseModel):
    label: str = Field("", max_length=200, description="what the token is for (a wall screen, a script)")


class TokenView(BaseModel):
    id: int
    user: str
    label: str
    created: str
    token: str | None = Field(None, description="the token itself: shown only once, when it is made")


class AuditView(BaseModel):
    time: str
    time_ns: int
    user: str
    action: str = Field(description="trajectory, contacts, track_summaries, or live_tracks (the /ws/tracks stream: "
                                    "a row when it opens and one when it closes, saying how long it ran)")
    track_id: int | None
    client: str = Field(description="the address the request came from")
    detail: str


@router.get("/users", response_model=list[UserView], summary="Every user and their role")
def users(_: Admin, access: AccessDep) -> list[UserView]:
    return [UserView(name=u.name, role=u.role, created=iso_utc(u.created_ns)) for u in access.store.users()]


@router.post("/users", response_model=UserView, status_code=201, summary="Add a user")
def add_user(body: NewUser, _: Admin, access: AccessDep) -> UserView:
    try:
        user = access.store.add_user(body.name, body.role, access.hash_password(body.password, body.name), access.clock())
    except (ValueError, PasswordError) as exc:
        raise HTTPException(409 if "already exists" in str(exc) else 400, str(exc)) from None
    return UserView(name=user.name, role=user.role, created=iso_utc(user.created_ns))


@router.delete("/users/{name}", status_code=204, summary="Remove a user, their sessions and tokens")
def remove_user(name: UserName, principal: Admin, access: AccessDep) -> None:
    if name == principal.name:
        raise HTTPException(400, "you cannot remove yourself; another admin can")
    try:
        access.store.remove_user(name)
    except KeyError:
        raise HTTPException(404, f"no user {name!r}") from None


@router.post("/users/{name}/tokens", response_model=TokenView, status_code=201, summary="Make an API token for a user")
def add_token(name: UserName, _: Admin, access: AccessDep, body: NewToken | None = None) -> TokenView:
    body = body or NewToken()
    secret = new_api_token()
    try:
        token = access.store.add_token(secret, name, body.label, access.clock())
    except KeyError:
        raise HTTPException(404, f"no user {name!r}") from None
    return TokenView(id=token.id, user=token.user, label=token.label, created=iso_utc(token.created_ns), token=secret)


@router.get("/users/{name}/tokens", response_model=list[TokenView], summary="A user's API tokens (not the tokens themselves)")
def tokens(name: UserName, _: Admin, access: AccessDep) -> list[TokenView]:
    if access.store.user(name) is None:
        raise HTTPException(404, f"no user {name!r}")
    return [TokenView(id=t.id, user=t.user, label=t.label, created=iso_utc(t.created_ns)) for t in access.store.tokens(name)]


@router.delete("/users/{name}/tokens/{token_id}", status_code=204,
               summary="Revoke an API token (its open websockets close within a second)")
def revoke_token(name: UserName, token_id: Annotated[int, Path(ge=0, le=2**63 - 1)], _: Admin, access: AccessDep) -> None:
    if token_id not in {t.id for t in access.store.tokens(name)}:
        raise HTTPException(404, f"{name!r} has no API token {token_id}")
    try:
        access.store.revoke_token(token_id)
    except KeyError:  # revoked meanwhile
        raise HTTPException(404, f"{name!r} has no API token {token_id}") from None


@router.put("/users/{name}/password", status_code=204,
            summary="Set a user's password (ends their sessions, API tokens and open websockets)")
def set_password(name: UserName, body: NewPassword, _: Admin, access: AccessDep) -> None:
    try:
        access.store.set_password(name, access.hash_password(body.password, name))
    except PasswordError as exc:
        raise HTTPException(400, str(exc)) from None
    except KeyError:
        raise HTTPException(404, f"no user {name!r}") from None


@router.put("/users/{name}/role", response_model=UserView, summary="Change a user's role")
def set_role(name: UserName, body: NewRole, principal: Admin, access: AccessDep) -> UserView:
    if name == principal.name:
        raise HTTPException(400, "you cannot change your own role; another admin can")
    try:
        access.store.set_role(name, body.role)
    except ValueError as exc:
        raise HTTPException(400, str(exc)) from None
    except KeyError:
        raise HTTPException(404, f"no user {name!r}") from None
    user = access.store.user(name)
    if user is None:
        raise HTTPException(404, f"no user {name!r}")
    return UserView(name=user.name, role=user.role, created=iso_utc(user.created_ns))


@router.get("/audit", response_model=Page[AuditView], summary="Who traced which person, when and from where")
def audit_log(
    _: Admin,
    access: AccessDep,
    since: Annotated[datetime | None, Query(description="ISO-8601 (UTC if no offset) or Unix seconds")] = None,
    until: Annotated[datetime | None, Query(description="ISO-8601 (UTC if no offset) or Unix seconds")] = None,
    user: Annotated[str | None, Query(max_length=64)] = None,
    track: Annotated[int | None, Query(ge=0, le=2**63 - 1)] = None,
    limit: Limit = 100,
    offset: Offset = 0,
) -> Page[AuditView]:
    entries, total = access.store.audit_log(None if since is None else to_ns(since), None if until is None else to_ns(until),
                                            user, track, limit, offset)
    items = [AuditView(time=iso_utc(e.time_ns), time_ns=e.time_ns, user=e.user, action=e.action, track_id=e.track_id,
                       client=e.client, detail=e.detail) for e in entries]
    return Page[AuditView](items=items, total=total, limit=limit, offset=offset)
