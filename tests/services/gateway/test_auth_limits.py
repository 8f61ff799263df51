"""Login limits under load, over a real server: parallel wrong passwords stay within the limit,
password hashing takes a bounded number of slots and refuses the rest at once, and no request
body is read beyond the cap."""

from __future__ import annotations

import json
import socket
import threading
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor

import pytest
from argon2 import PasswordHasher

from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.auth import HASHING_SLOTS
from bevflow_services.gateway.auth_limits import LoginLimiter
from bevflow_services.gateway.body_limit import MAX_BODY_BYTES
from tests.services.gateway.access import CHEAP_HASHER, PASSWORD, secured_access
from tests.services.gateway.live import serve_in_thread


class SlowHasher(PasswordHasher):
    """A cheap hasher whose checks take 50 ms, so that parallel logins overlap."""

    def verify(self, hash: str, password: str | bytes) -> bool:  # noqa: A002  (argon2's name)
        time.sleep(0.05)
        return CHEAP_HASHER.verify(hash, password)


def post_login(address: str, name: str, password: str) -> int:
    body = json.dumps({"name": name, "password": password}).encode()
    request = urllib.request.Request(f"http://{address}/api/auth/login", data=body,
                                     headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as refused:
        return refused.code


def test_the_limiter_lets_exactly_its_limit_through_in_parallel() -> None:
    limiter = LoginLimiter(max_failures=5)
    with ThreadPoolExecutor(40) as pool:
        waits = list(pool.map(lambda _: limiter.attempt("viewer", "10.0.0.9"), range(40)))
    assert waits.count(0) == 5


def test_parallel_wrong_passwords_get_at_most_the_limit_of_401s(site: Site, state: GatewayState) -> None:
    access, _ = secured_access(limiter=LoginLimiter(max_failures=5))
    access.hasher = SlowHasher()
    access.hashing_slots = threading.BoundedSemaphore(40)  # the limit alone is under test here
    with serve_in_thread(create_app(site, state, access=access)) as address:
        with ThreadPoolExecutor(40) as pool:
            codes = list(pool.map(lambda k: post_login(address, "viewer", f"guess {k}"), range(40)))
    assert (codes.count(401), codes.count(429)) == (5, 35)


def test_a_full_hashing_pool_refuses_at_once_without_counting_a_failure(site: Site, state: GatewayState) -> None:
    access, _ = secured_access(limiter=LoginLimiter(max_failures=1))
    with serve_in_thread(create_app(site, state, access=access)) as address:
        for _ in range(HASHING_SLOTS):  # every slot busy, as under a login flood
            assert access.hashing_slots.acquire(blocking=False)
        assert post_login(address, "viewer", PASSWORD) == 503
        for _ in range(HASHING_SLOTS):
            access.hashing_slots.release()
        assert post_login(address, "viewer", PASSWORD) == 200  # the refused try did not count


def raw_request(address: str, head: str, body: bytes = b"") -> bytes:
    """Send ``head`` (and ``body``) on a socket; the server's answer, as far as it has come in 5 s."""
    host, port = address.split(":")
    with socket.create_connection((host, int(port)), timeout=5) as sock:
        sock.sendall(head.encode() + b"\r\n" + body)
        answer = b""
        try:
            while b"\r\n\r\n" not in answer and (chunk := sock.recv(4096)):
                answer += chunk
        except TimeoutError:
            pass
    return answer


def chunked(size: int) -> bytes:
    piece = b"x" * 65536
    chunks = b"".join(b"%x\r\n%s\r\n" % (len(piece), piece) for _ in range(size // len(piece)))
    return chunks + b"0\r\n\r\n"


@pytest.mark.parametrize(("framing", "size", "status"), [
    ("length", 10**9, b" 413 "),           # declared: refused before any of it is sent
    ("chunked", 2 * MAX_BODY_BYTES, b" 413 "),
    ("chunked", 1000, b" 401 "),           # small bodies get through as before
    ("length", 1000, b" 401 "),
])
def test_request_bodies_are_capped(site: Site, state: GatewayState, framing: str, size: int, status: bytes) -> None:
    access, _ = secured_access()
    payload = json.dumps({"name": "viewer", "password": "wrong"}).encode()
    payload += b" " * (size - len(payload))
    with serve_in_thread(create_app(site, state, access=access)) as address:
        head = f"POST /api/auth/login HTTP/1.1\r\nHost: {address}\r\nContent-Type: application/json\r\n"
        if framing == "length":
            body = payload if size < MAX_BODY_BYTES else b""  # the gigabyte is never sent
            answer = raw_request(address, head + f"Content-Length: {size}\r\n", body)
        else:
            body = chunked(size) if size > MAX_BODY_BYTES else b"%x\r\n%s\r\n0\r\n\r\n" % (len(payload), payload)
            answer = raw_request(address, head + "Transfer-Encoding: chunked\r\n", body)
    assert answer.split(b"\r\n", 1)[0].startswith(b"HTTP/1.1") and status in answer.split(b"\r\n", 1)[0]
