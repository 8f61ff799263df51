"""``/api/auth``: log in and out of the dashboard, who am I, and the first admin's setup.

- ``POST /api/auth/login`` ``{"name", "password"}``: sets the session cookie (HttpOnly,
  SameSite=Strict, Secure over TLS). Repeated failures for one name from one address (5 in 5
  minutes), or for any names from one address (30), answer 429 with ``Retry-After``.
- ``POST /api/auth/logout`` (and ``GET /logout``, which then shows the login page): ends the session.
- ``GET /api/auth/me``: the caller's name and role.
- ``POST /api/auth/setup`` ``{"token", "name", "password"}``: while there are no users, creates the
  first admin with the one-time token the gateway printed in its log, and logs them in.
"""

from __future__ import annotations

import logging

from fastapi import APIRouter, HTTPException, Request, Response
from fastapi.responses import RedirectResponse
from pydantic import BaseModel, Field

from bevflow_services.gateway.auth import (
    SESSION_COOKIE,
    Access,
    AccessDep,
    HashingBusy,
    Viewer,
    client_address,
)
from bevflow_services.gateway.password_policy import PasswordError
from bevflow_services.storage.access import User, check_user_name

log = logging.getLogger(__name__)
router = APIRouter(tags=["auth"])


class Credentials(BaseModel):
    name: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


class Setup(Credentials):
    token: str = Field(min_length=1, max_length=256, description="the one-time setup token from the gateway's log")


class Me(BaseModel):
    name: str
    role: str
    via: str = Field(description="session, token, or off (access control is off)")
    auth: bool = Field(description="whether access control is on")


def _set_cookie(response: Response, access: Access, secret: str) -> None:
    response.set_cookie(SESSION_COOKIE, secret, max_age=int(access.session_s), path="/", httponly=True,
                        samesite="strict", secure=access.secure_cookies)


def _logged_in(response: Response, access: Access, user: User) -> Me:
    _set_cookie(response, access, access.start_session(user))
    return Me(name=user.name, role=user.role, via="session", auth=access.enabled)


@router.post("/api/auth/login", response_model=Me, summary="Log in (sets the dashboard's session cookie)",
             responses={401: {"description": "wrong name or password"}, 429: {"description": "too many failures"}})
def login(credentials: Credentials, request: Request, response: Response, access: AccessDep) -> Me:
    if not access.enabled:
        raise HTTPException(400, "access control is off on this gateway (--auth off): there is nothing to log in to")
    client, name = client_address(request), credentials.name
    wait_s = access.address_limiter.attempt("", client)
    if wait_s:
        raise HTTPException(429, f"too many failed logins from {client}: try again in {wait_s} s",
                            headers={"Retry-After": str(wait_s)})
    wait_s = access.limiter.attempt(name, client)
    if wait_s:
        access.address_limiter.withdraw("", client)
        raise HTTPException(429, f"too many failed logins for {name!r} from {client}: try again in {wait_s} s",
                            headers={"Retry-After": str(wait_s)})
    try:
        user = access.verify_password(name, credentials.password)
    except HashingBusy:
        access.limiter.withdraw(name, client)  # nothing was checked: not a guess
        access.address_limiter.withdraw("", client)
        raise
    if user is None:
        log.warning("failed login for %r from %s", name, client)
        raise HTTPException(401, "wrong user name or password")
    access.limiter.succeeded(name, client)
    access.address_limiter.withdraw("", client)
    log.info("%s logged in from %s", user.name, client)
    return _logged_in(response, access, user)


def _end_session(request: Request, response: Response, access: Access) -> None:
    secret = request.cookies.get(SESSION_COOKIE)
    if secret:
        access.store.remove_session(secret)
    response.delete_cookie(SESSION_COOKIE, path="/", httponly=True, samesite="strict", secure=access.secure_cookies)


@router.post("/api/auth/logout", status_code=204, summary="Log out (ends the session)")
def logout(request: Request, access: AccessDep) -> Response:
    response = Response(status_code=204)
    _end_session(request, response, access)
    return response


@router.get("/logout", include_in_schema=False)
def logout_page(request: Request, access: AccessDep) -> Response:
    # A GET that changes state is safe here: the SameSite=Strict cookie is not sent along when
    # another site links or embeds this URL, so only the user's own click logs them out.
    response = RedirectResponse("/login.html?logged_out=1", status_code=303)
    _end_session(request, response, access)
    return response


@router.get("/api/auth/me", response_model=Me, summary="Who the caller is")
def me(principal: Viewer, access: AccessDep) -> Me:
    return Me(name=principal.name, role=principal.role, via=principal.via, auth=access.enabled)


@router.post("/api/auth/setup", response_model=Me, status_code=201, summary="Create the first admin (first run only)",
             responses={403: {"description": "wrong or used-up setup token"}, 409: {"description": "users exist already"}})
def setup(body: Setup, request: Request, response: Response, access: AccessDep) -> Me:
    client = client_address(request)
    wait_s = access.limiter.attempt("(setup)", client)
    if wait_s:
        raise HTTPException(429, f"too many wrong setup tokens from {client}: try again in {wait_s} s",
                            headers={"Retry-After": str(wait_s)})
    if not access.setup_token_matches(body.token):
        raise HTTPException(403, "wrong or used-up setup token: use the one in the gateway's log, or "
                            "`bevflow users add NAME --role admin --db URL`")
    access.limiter.succeeded("(setup)", client)
    try:
        check_user_name(body.name)
        password_hash = access.hash_password(body.password, body.name)
    except (ValueError, PasswordError) as exc:
        raise HTTPException(400, str(exc)) from None
    user = access.store.add_first_admin(body.name, password_hash, access.clock())
    access.setup_token = None
    if user is None:
        raise HTTPException(409, "users exist already: log in instead")
    log.warning("first admin %r created from %s with the setup token", user.name, client)
    response.status_code = 201
    return _logged_in(response, access, user)
