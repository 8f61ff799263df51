"""The message bus: the one module that talks to Zenoh.

Everything a service needs to move bevflow's messages between processes lives here: how a session is
configured (``BusConfig``, ``add_bus_arguments``; TLS and passwords from the site file's ``bus:``
section, ``Security``), where each message goes (``Keys``), how it is
encoded (JSON for :mod:`bevflow.schemas` messages, raw pixels plus a JSON header for frames), how
received samples reach the code that wants them, and which services are up (liveliness).

Zenoh calls subscribers back on its own threads and has no asyncio API. Four ways to receive:

- ``subscribe``: a plain callback, run on a Zenoh thread; for quick handlers.
- ``AsyncSubscription``: decoded messages go to an event loop through ``call_soon_threadsafe``
  into a bounded queue that drops its oldest item when full, so a stalled consumer never makes
  memory grow and always sees recent data.
- ``LatestSubscription``: a blocking ``take()`` for a worker thread that only ever wants the newest
  sample (a detector that is slower than its camera); older samples are dropped, not queued.
- ``HistorySubscription``: a plain callback that also receives what a ``CachedPublication`` kept
  while it was not running (alerts for the recorder); messages may arrive twice.

A bad payload never raises inside a Zenoh callback: it is counted in ``BusStats`` by reason and
logged (at most once per reason per ``log_every_s``), and the stream goes on. So is a message with
a capture time beyond the receiver's clock plus a few seconds (``bevflow.capture_time``, reason
``future_time``): one forged far-future tick must not pin the subscribers' "keep the newest" rules.

>>> keys = Keys("hall")
>>> keys.cylinders("cam1")
'bevflow/hall/cam/cam1/cylinders'
>>> keys.camera_of("bevflow/hall/cam/cam1/cylinders")
'cam1'
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import logging
import math
import os
import re
import socket
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Literal, Protocol, TypeVar, overload

import numpy as np
import zenoh
import zenoh.ext
from pydantic import TypeAdapter, ValidationError

from bevflow.capture_time import CaptureWindow
from bevflow.schemas import SCHEMA_VERSION, FrameHeader
from bevflow.site import BusSecurity, SiteError, load_site_or_builtin
from bevflow_services.bus_flags import add_bus_arguments  # noqa: F401  (part of this module's API)

log = logging.getLogger(__name__)

M = TypeVar("M")
Mode = Literal["peer", "client", "router"]
MODES: tuple[str, ...] = ("peer", "client", "router")
MiB = 1 << 20


# --- sessions ------------------------------------------------------------------------------------
class BusError(Exception):
    """Bus settings a user got wrong, or a bus that cannot be joined (an endpoint in use, a bad
    address, a bad config file). One line, fit to show as is."""


@dataclass(frozen=True)
class Security:
    """TLS files and credentials for a session, from the site file's ``bus:`` section
    (:class:`bevflow.site.BusSecurity`) with the password already read from its file or variable."""

    root_ca: Path | None = None
    cert: Path | None = None
    key: Path | None = None
    mutual: bool = False
    user: str | None = None
    password: str | None = field(default=None, repr=False)
    users_file: Path | None = None

    @property
    def tls(self) -> bool:
        return self.root_ca is not None or self.cert is not None

    @classmethod
    def from_site(cls, section: BusSecurity | None, environ: Mapping[str, str] = os.environ) -> Security | None:
        """Check that every file named exists and read the password; ``BusError`` otherwise."""
        if section is None or (section.tls is None and section.auth is None):
            return None
        tls, auth = section.tls, section.auth
        return cls(
            root_ca=_readable(tls.root_ca if tls else None, "bus.tls.root_ca"),
            cert=_readable(tls.cert if tls else None, "bus.tls.cert"),
            key=_readable(tls.key if tls else None, "bus.tls.key"),
            mutual=bool(tls and tls.mutual),
            user=auth.user if auth else None,
            password=_password(auth.password_file, auth.password_env, environ) if auth and auth.user else None,
            users_file=_readable(auth.users_file if auth else None, "bus.auth.users_file"),
        )

    def apply(self, conf: zenoh.Config) -> None:
        tls = "transport/link/tls/"
        for key, value in ((tls + "root_ca_certificate", self.root_ca), (tls + "listen_certificate", self.cert),
                           (tls + "listen_private_key", self.key)):
            if value is not None:
                conf.insert_json5(key, json.dumps(str(value)))
        if self.mutual:
            conf.insert_json5(tls + "enable_mtls", "true")
            conf.insert_json5(tls + "connect_certificate", json.dumps(str(self.cert)))
            conf.insert_json5(tls + "connect_private_key", json.dumps(str(self.key)))
        if self.user is not None:
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(self.user))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(self.password))
        if self.users_file is not None:
            conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(self.users_file)))


def _readable(path: str | None, what: str) -> Path | None:
    if not path:
        return None
    resolved = Path(path).expanduser()
    try:
        with resolved.open("rb"):
            pass
    except OSError as exc:
        raise BusError(f"{what}: cannot read {path} ({exc.strerror or exc})") from None
    return resolved


def _password(path: str | None, variable: str | None, environ: Mapping[str, str]) -> str:
    if variable is not None:
        if not environ.get(variable):
            raise BusError(f"bus.auth.password_env: the environment variable {variable} is not set")
        return environ[variable]
    assert path is not None  # the site model requires one of them
    file = _readable(path, "bus.auth.password_file")
    assert file is not None
    password = file.read_text(encoding="utf-8").rstrip("\r\n")
    if not password:
        raise BusError(f"bus.auth.password_file: {path} is empty")
    return password


_LOOPBACK = re.compile(r"[a-z0-9]+/(127\.\d+\.\d+\.\d+|localhost|\[::1\])(:\d+)?([#?].*)?")
_ENCRYPTED = ("tls/", "quic/", "unixsock-stream/")


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the bus. Multicast scouting is off by default: deployments name their
    endpoints, and tests on one machine must not find each other by accident."""

    mode: Mode = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast_scouting: bool = False
    shared_memory: bool = True
    # Zenoh's default pool is 16 MB; a few 1280x1280 BGR frames (4.9 MB each) in flight exhaust it.
    shm_pool_bytes: int = 64 * MiB
    timestamping: bool = False
    zenoh_config_file: Path | None = None
    security: Security | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise BusError(f"bus mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.mode == "client" and not self.connect:
            raise BusError("client mode needs at least one --connect endpoint (a router's address)")
        for endpoint in (*self.connect, *self.listen):
            if not re.fullmatch(r"[a-z0-9]+/\S+", endpoint):
                raise BusError(f"endpoint {endpoint!r} is not of the form PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447")
        if self.security is not None and self.security.tls:
            # With TLS configured, plain links may stay only on this host (a local demo, a
            # sidecar); anything that crosses the network must be encrypted.
            for endpoint in (*self.connect, *self.listen):
                if not endpoint.startswith(_ENCRYPTED) and not _LOOPBACK.fullmatch(endpoint):
                    address = endpoint.split("/", 1)[1]
                    raise BusError(f"the site's bus.tls is set, but endpoint {endpoint} is not encrypted: "
                                   f"use tls/{address}")

    def to_zenoh(self) -> zenoh.Config:
        """The Zenoh configuration: the optional file first, then these settings on top."""
        conf = zenoh.Config.from_file(self.zenoh_config_file) if self.zenoh_config_file else zenoh.Config()
        conf.insert_json5("mode", json.dumps(self.mode))
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast_scouting))
        conf.insert_json5("transport/shared_memory/enabled", json.dumps(self.shared_memory))
        conf.insert_json5("transport/shared_memory/transport_optimization/pool_size", str(self.shm_pool_bytes))
        if self.timestamping:
            conf.insert_json5("timestamping/enabled", "true")
        if self.security is not None:
            self.security.apply(conf)
            if self.security.tls and self.mode == "peer" and not self.listen:
                # A peer's default listener is plain TCP on every interface; with TLS, none.
                conf.insert_json5("listen/endpoints", "[]")
        return conf


def open_session(cfg: BusConfig) -> zenoh.Session:
    """Open a Zenoh session; failures become one ``BusError`` line that names the settings."""
    try:
        return zenoh.open(cfg.to_zenoh())
    except (zenoh.ZError, ValueError) as exc:
        where = f"mode={cfg.mode} listen={list(cfg.listen)} connect={list(cfg.connect)}"
        if cfg.zenoh_config_file:
            where += f" config={cfg.zenoh_config_file}"
        # Zenoh's messages end with Rust source locations, which mean nothing to an operator.
        reason = re.sub(r"\s+at /\S+?\.rs:\d+\.?", "", str(exc)).strip(" .[]")
        raise BusError(f"cannot join the bus ({where}): {reason}") from None


def config_from_args(args: argparse.Namespace, *, mode: Mode | None = None) -> BusConfig:
    """The ``BusConfig`` named by the flags of ``add_bus_arguments``; ``mode`` overrides --mode.
    With ``args.site`` (a site file or built-in name), its ``bus:`` section adds TLS and
    credentials; a site that does not load is left for the service to report."""
    return BusConfig(
        mode=mode if mode is not None else getattr(args, "mode", "peer"),
        connect=tuple(args.connect),
        listen=tuple(args.listen),
        multicast_scouting=args.multicast_scouting,
        shared_memory=args.shared_memory,
        zenoh_config_file=args.zenoh_config,
        security=_readable_site_security(getattr(args, "site", None)),
    )


def _readable_site_security(site: str | Path | None) -> Security | None:
    try:
        return site_security(site)
    except BusError:
        if site is not None and not _site_loads(site):
            return None  # not this module's error to report: the service says what is wrong with its site
        raise


def _site_loads(site: str | Path) -> bool:
    try:
        load_site_or_builtin(site)
    except SiteError:
        return False
    return True


def site_security(site: str | Path | None) -> Security | None:
    """The bus security of a site file (or built-in site name); None without a ``bus:`` section."""
    if site is None:
        return None
    try:
        section = load_site_or_builtin(site).bus
    except SiteError as exc:
        raise BusError(str(exc)) from None
    return Security.from_site(section)


# --- the key space -------------------------------------------------------------------------------
_CHUNK = re.compile(r"[A-Za-z0-9_.-]+")


def _chunk(value: str, what: str) -> str:
    if value == "*" or _CHUNK.fullmatch(value):
        return value
    raise ValueError(f"{what} {value!r} cannot be part of a bus key: use letters, digits, '_', '.', '-'")


@dataclass(frozen=True)
class Keys:
    """Where every message of one site goes. Pass ``"*"`` for a camera (or service, instance) to
    get the wildcard that matches all of them."""

    site: str
    prefix: str = "bevflow"

    def __post_init__(self) -> None:
        _chunk(self.site, "site id")

    @property
    def root(self) -> str:
        return f"{self.prefix}/{self.site}"

    def frame(self, camera: str) -> str:
        return f"{self.root}/cam/{_chunk(camera, 'camera id')}/frame"

    def detections(self, camera: str) -> str:
        return f"{self.root}/cam/{_chunk(camera, 'camera id')}/detections"

    def cylinders(self, camera: str) -> str:
        return f"{self.root}/cam/{_chunk(camera, 'camera id')}/cylinders"

    @property
    def tracks(self) -> str:
        return f"{self.root}/tracks"

    @property
    def occupancy(self) -> str:
        return f"{self.root}/occupancy"

    @property
    def events(self) -> str:
        return f"{self.root}/events"

    @property
    def open_alerts(self) -> str:
        """The ids of the alerts the tracker still has open (``OpenAlerts``), renewing them."""
        return f"{self.root}/alerts/open"

    @property
    def truth(self) -> str:
        """Ground truth from a simulated ingest (``SimulatedTruth``)."""
        return f"{self.root}/sim/truth"

    def metrics(self, service: str = "*", instance: str = "*") -> str:
        """Each service instance's own measurements (``schemas.ServiceMetrics``)."""
        return f"{self.root}/metrics/{_chunk(service, 'service name')}/{_chunk(instance, 'instance id')}"

    def alive(self, service: str = "*", instance: str = "*") -> str:
        return f"{self.root}/alive/{_chunk(service, 'service name')}/{_chunk(instance, 'instance id')}"

    def camera_of(self, key: str) -> str:
        """The camera id in a per-camera key; ``ValueError`` for any other key."""
        parts = str(key).split("/")
        if len(parts) != 5 or "/".join(parts[:2]) != self.root or parts[2] != "cam":
            raise ValueError(f"{key!r} is not a per-camera key of site {self.site!r}")
        return parts[3]

    def service_of(self, key: str) -> tuple[str, str]:
        """(service, instance) of a liveliness key; ``ValueError`` for any other key."""
        parts = str(key).split("/")
        if len(parts) != 5 or "/".join(parts[:2]) != self.root or parts[2] != "alive":
            raise ValueError(f"{key!r} is not a liveliness key of site {self.site!r}")
        return parts[3], parts[4]


# --- statistics ----------------------------------------------------------------------------------
class BusStats:
    """Counts of what subscriptions received, decoded, rejected (by reason) and dropped; safe to
    share between subscriptions and threads. Rejections are logged at most once per reason per
    ``log_every_s``, with how many were not logged since."""

    def __init__(self, log_every_s: float = 10.0) -> None:
        self.log_every_s = log_every_s
        self._lock = threading.Lock()
        self.received = 0
        self.decoded = 0
        self.dropped = 0
        self.handler_errors = 0
        self.rejected: collections.Counter[str] = collections.Counter()
        self._last_log: dict[str, tuple[float, int]] = {}

    def count(self, what: Literal["received", "decoded", "dropped", "handler_errors"], n: int = 1) -> None:
        with self._lock:
            setattr(self, what, getattr(self, what) + n)

    def reject(self, key: str, reason: str, detail: str) -> None:
        with self._lock:
            self.rejected[reason] += 1
            total = self.rejected[reason]
            last_t, last_total = self._last_log.get(reason, (-float("inf"), 0))
            now = time.monotonic()
            if now - last_t < self.log_every_s:
                return
            self._last_log[reason] = (now, total)
        quiet = total - last_total - 1
        more = f" ({quiet} more since the last report)" if quiet > 0 else ""
        log.warning("rejected a message on %s: %s: %s%s", key, reason, detail[:300], more)

    def snapshot(self) -> dict[str, Any]:
        """A JSON-ready copy, for health endpoints."""
        with self._lock:
            return {
                "received": self.received,
                "decoded": self.decoded,
                "rejected": dict(self.rejected),
                "dropped": self.dropped,
                "handler_errors": self.handler_errors,
            }


# --- codecs --------------------------------------------------------------------------------------
class Rejected(Exception):
    """A payload that cannot be decoded; ``reason`` is a short stable label for counters."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def _rejection(err: ValidationError) -> Rejected:
    errors = err.errors(include_url=False)
    detail = "; ".join(f"{'.'.join(map(str, e['loc'])) or 'message'}: {e['msg']}" for e in errors[:3])
    if any(e["type"] in ("json_invalid", "json_type") for e in errors):
        return Rejected("malformed", detail)
    versions = [e.get("input") for e in errors if e["loc"] and e["loc"][-1] == "schema_version"]
    if versions:
        return Rejected("schema_version", f"schema_version {versions[0]!r}; this release reads {SCHEMA_VERSION}")
    if all(e["type"] == "extra_forbidden" for e in errors):
        return Rejected("unknown_fields", detail)
    return Rejected("invalid", detail)


def _validate_json(adapter: TypeAdapter[M], raw: bytes) -> M:
    try:
        return adapter.validate_json(raw)
    except ValidationError as exc:
        raise _rejection(exc) from None


class Codec(Protocol[M]):
    """Turns one kind of message into (payload, attachment, encoding) and back."""

    name: str

    def encode(self, message: M) -> tuple[bytes, bytes | None, zenoh.Encoding]: ...

    def decode(self, payload: bytes, attachment: bytes | None) -> M:
        """The message, or ``Rejected``."""
        ...


class JsonCodec(Generic[M]):
    """A :mod:`bevflow.schemas` message (or a union such as ``schemas.Event``) as JSON. A union
    is not a class, so its codec names its type: ``JsonCodec[Event](Event, "Event")``."""

    @overload
    def __init__(self, message_type: type[M], name: str | None = None) -> None: ...
    @overload
    def __init__(self, message_type: Any, name: str) -> None: ...

    def __init__(self, message_type: Any, name: str | None = None) -> None:
        self.adapter: TypeAdapter[M] = TypeAdapter(message_type)
        self.name: str = name or str(getattr(message_type, "__name__", "message"))
        self.encoding = zenoh.Encoding.APPLICATION_JSON.with_schema(f"bevflow/{self.name}/v{SCHEMA_VERSION}")

    def encode(self, message: M) -> tuple[bytes, bytes | None, zenoh.Encoding]:
        # warnings="error": publishing the wrong type is a bug, not something to send half-encoded.
        return self.adapter.dump_json(message, warnings="error"), None, self.encoding

    def decode(self, payload: bytes, attachment: bytes | None) -> M:
        return _validate_json(self.adapter, payload)


@dataclass(frozen=True)
class Frame:
    """A camera image as it travels: ``image`` is HxWx3 (bgr8), HxW (gray8) or the 1-D bytes of a
    JPEG, uint8; ``header`` says which."""

    header: FrameHeader
    image: np.ndarray


_HEADER = TypeAdapter(FrameHeader)


def _pixel_shape(header: FrameHeader) -> tuple[int, ...] | None:
    return {"bgr8": (header.height, header.width, 3), "gray8": (header.height, header.width)}.get(header.encoding)


class FrameCodec:
    """Pixels as the payload, the ``FrameHeader`` as JSON in the attachment. The receiver gets a
    read-only array over its own copy of the bytes."""

    name = "Frame"

    def encode(self, frame: Frame) -> tuple[bytes, bytes, zenoh.Encoding]:
        header, image = frame.header, frame.image
        shape = _pixel_shape(header)
        fits = image.shape == shape if shape is not None else image.ndim == 1
        if image.dtype != np.uint8 or not fits:
            raise ValueError(f"image {image.dtype}{list(image.shape)} does not match its header "
                             f"({header.encoding} {header.width}x{header.height})")
        if header.encoding == "jpeg":
            encoding = zenoh.Encoding.IMAGE_JPEG
        else:
            schema = f"{header.encoding};{header.width}x{header.height}"
            encoding = zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema(schema)
        return np.ascontiguousarray(image).tobytes(), header.model_dump_json().encode(), encoding

    def decode(self, payload: bytes, attachment: bytes | None) -> Frame:
        if attachment is None:
            raise Rejected("no_header", "a frame arrived without its FrameHeader attachment")
        header = _validate_json(_HEADER, attachment)
        shape = _pixel_shape(header)
        # Python integers: a forged header's width x height must not wrap around in 64 bits.
        expected = math.prod(shape) if shape else None
        if (expected is not None and len(payload) != expected) or not payload:
            size = f"{header.encoding} {header.width}x{header.height}"
            raise Rejected("frame_size", f"{len(payload)} bytes for a {size} frame")
        image = np.frombuffer(payload, dtype=np.uint8)
        return Frame(header=header, image=image.reshape(shape) if shape else image)


FRAMES = FrameCodec()


def decode_sample(codec: Codec[M], sample: zenoh.Sample) -> M:
    """Decode one sample; raises ``Rejected`` for a bad payload."""
    attachment = sample.attachment
    return codec.decode(sample.payload.to_bytes(), attachment.to_bytes() if attachment is not None else None)


# --- publishing ----------------------------------------------------------------------------------
class Publication(Generic[M]):
    """A declared publisher of one kind of message on one key.

    ``block_when_congested`` makes ``put`` wait for a congested link instead of dropping the
    message: right for rare messages that must arrive (alerts), wrong for streams where a newer
    message replaces an older one (frames, tracks). Without it, the first large message that goes
    through shared memory on a new link is dropped while the link sets shared memory up, so a
    frame stream loses its first frame."""

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M], *,
                 block_when_congested: bool = False) -> None:
        self.key = key
        self._codec = codec
        congestion = zenoh.CongestionControl.BLOCK if block_when_congested else zenoh.CongestionControl.DROP
        self._publisher = session.declare_publisher(key, congestion_control=congestion)

    def put(self, message: M) -> None:
        payload, attachment, encoding = self._codec.encode(message)
        self._publisher.put(payload, attachment=attachment, encoding=encoding)

    def put_json(self, payload: bytes) -> None:
        """Publish a message that its maker already wrote as JSON (``schemas.Tracks.wire_json``);
        only for a ``JsonCodec`` publication, whose encoding it carries."""
        if not isinstance(self._codec, JsonCodec):
            raise TypeError(f"put_json needs a JsonCodec publication, not {type(self._codec).__name__}")
        self._publisher.put(payload, encoding=self._codec.encoding)

    def has_subscribers(self) -> bool:
        # zenoh's stubs say bool; at run time it is a MatchingStatus with ``matching``.
        return bool(self._publisher.matching_status.matching)  # type: ignore[attr-defined]

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Whether a matching subscriber appeared within ``timeout`` seconds (declarations take a
        moment to propagate, so the first messages after start-up may otherwise go nowhere)."""
        deadline = time.monotonic() + timeout
        while not self.has_subscribers():
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def close(self) -> None:
        _undeclare(self._publisher)

    def __enter__(self) -> Publication[M]:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def _undeclare(entity: Any) -> None:
    try:
        entity.undeclare()
    except zenoh.ZError:  # already gone with its session
        pass


class CachedPublication(Generic[M]):
    """A publisher that keeps its last ``cache`` messages, so a subscriber that joins late or
    restarts (a ``HistorySubscription``) receives what it missed; for rare messages that must not
    be lost (alerts). It blocks on a congested link instead of dropping, and sends a sequence-number
    heartbeat every ``heartbeat_s`` so subscribers also detect and fetch a lost last message.

    Built on Zenoh's advanced publisher (an API Zenoh marks unstable). Plain subscribers receive
    its messages like any other. Open the session with ``BusConfig(timestamping=True)``: cached
    replies carry their timestamps."""

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M], *, cache: int = 10_000,
                 heartbeat_s: float = 1.0) -> None:
        if cache < 1:
            raise ValueError("cache must hold at least 1 message")
        self.key = key
        self._codec = codec
        block = zenoh.CongestionControl.BLOCK
        self._publisher = zenoh.ext.declare_advanced_publisher(
            session, key, congestion_control=block,
            cache=zenoh.ext.CacheConfig(cache, replies_config=zenoh.ext.RepliesConfig(congestion_control=block)),
            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=heartbeat_s, sporadic_heartbeat=None),
            publisher_detection=True,
        )

    def put(self, message: M) -> None:
        payload, attachment, encoding = self._codec.encode(message)
        self._publisher.put(payload, attachment=attachment, encoding=encoding)

    def close(self) -> None:
        _undeclare(self._publisher)

    def __enter__(self) -> CachedPublication[M]:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


# --- subscribing ---------------------------------------------------------------------------------
class Subscription(Generic[M]):
    """A subscriber that decodes each sample with ``codec`` and passes it to ``on_message`` on a
    Zenoh thread. Bad payloads and handler exceptions are counted in ``stats``, never raised."""

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M],
                 on_message: Callable[[M], object] | None = None, *, stats: BusStats | None = None,
                 window: CaptureWindow | None = None) -> None:
        self.key = key
        self.codec = codec
        self.stats = stats if stats is not None else BusStats()
        self.window = window if window is not None else CaptureWindow.from_environment()
        self._on_message = on_message
        self._subscriber: zenoh.Subscriber[None] | zenoh.ext.AdvancedSubscriber[None]
        self._subscriber = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self.stats.count("received")
        self._accept(sample)

    def _accept(self, sample: zenoh.Sample) -> None:
        message = self._decode(sample)
        if message is None:
            return
        try:
            self._deliver(message)
        except Exception as exc:  # a handler bug must not end the subscription
            self.stats.count("handler_errors")
            log.exception("handler for %s failed: %s", self.key, exc)

    def _decode(self, sample: zenoh.Sample) -> M | None:
        key = str(sample.key_expr)
        try:
            message = decode_sample(self.codec, sample)
        except Rejected as exc:
            self.stats.reject(key, exc.reason, exc.detail)
            return None
        except Exception as exc:  # a codec bug: count it, keep the stream
            self.stats.reject(key, "decoder_error", repr(exc))
            return None
        too_new = self.window.first_too_new(message, time.time_ns())
        if too_new is not None:
            name, value = too_new
            self.stats.reject(key, "future_time", f"{_source(message)}{name}={value} is more than "
                              f"{self.window.future_s:g} s ahead of this host's clock")
            return None
        self.stats.count("decoded")
        return message

    def _deliver(self, message: M) -> None:
        if self._on_message is not None:
            self._on_message(message)

    def close(self) -> None:
        _undeclare(self._subscriber)

    def __enter__(self) -> Subscription[M]:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()


def _source(message: Any) -> str:
    """Who a message says it comes from, for a log line: its camera, site or alert id."""
    model = getattr(message, "header", message)
    for field_name in ("camera", "site", "id"):
        value = getattr(model, field_name, None)
        if isinstance(value, str):
            return f"{field_name} {value[:40]!r}: "
    return ""


def subscribe(session: zenoh.Session, key: str, codec: Codec[M], on_message: Callable[[M], object],
              *, stats: BusStats | None = None, window: CaptureWindow | None = None) -> Subscription[M]:
    """Call ``on_message`` (on a Zenoh thread) with each decoded message published on ``key``."""
    return Subscription(session, key, codec, on_message, stats=stats, window=window)


class AsyncSubscription(Subscription[M]):
    """Decoded messages for an asyncio consumer: ``await sub.get()`` or ``async for``.

    The queue holds at most ``maxsize`` messages; when it is full the oldest one is dropped (and
    counted in ``stats.dropped``), so a consumer that falls behind resumes with recent data.
    Create it on the event loop's thread, or pass ``loop``."""

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M], *, maxsize: int = 64,
                 loop: asyncio.AbstractEventLoop | None = None, stats: BusStats | None = None,
                 window: CaptureWindow | None = None) -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be at least 1")
        self._loop = loop or asyncio.get_running_loop()
        self.queue: asyncio.Queue[M] = asyncio.Queue(maxsize)
        super().__init__(session, key, codec, stats=stats, window=window)

    def _deliver(self, message: M) -> None:  # on a Zenoh thread
        try:
            self._loop.call_soon_threadsafe(self._enqueue, message)
        except RuntimeError:  # the loop is closed: nobody will read it
            self.stats.count("dropped")

    def _enqueue(self, message: M) -> None:  # on the loop's thread
        if self.queue.full():
            self.queue.get_nowait()
            self.stats.count("dropped")
        self.queue.put_nowait(message)

    async def get(self) -> M:
        return await self.queue.get()

    def __aiter__(self) -> AsyncSubscription[M]:
        return self

    async def __anext__(self) -> M:
        return await self.queue.get()


class LatestSubscription(Subscription[M]):
    """For a worker thread slower than its input: ``take()`` returns the newest message and
    older ones are dropped unread (counted in ``stats.dropped``). Decoding happens in ``take``, so
    frames that are overwritten cost nothing but their transfer."""

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M], *, keep: int = 1,
                 stats: BusStats | None = None, window: CaptureWindow | None = None) -> None:
        self._samples: collections.deque[zenoh.Sample] = collections.deque(maxlen=keep)
        self._ready = threading.Condition()
        super().__init__(session, key, codec, stats=stats, window=window)

    def _accept(self, sample: zenoh.Sample) -> None:
        with self._ready:
            if len(self._samples) == self._samples.maxlen:
                self.stats.count("dropped")
            self._samples.append(sample)
            self._ready.notify()

    def take(self, timeout: float | None = None) -> M | None:
        """The oldest kept message (the newest one with ``keep=1``), waiting up to ``timeout``
        seconds (forever if None); None when nothing valid arrived in time."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._ready:
                while not self._samples:
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0:
                        return None
                    self._ready.wait(left)
                sample = self._samples.popleft()
            message = self._decode(sample)
            if message is not None:
                return message


class HistorySubscription(Subscription[M]):
    """A callback subscription that also receives what ``CachedPublication`` publishers still
    cache: everything they kept when it starts (and when a publisher starts later), and any message
    it missed while running (found by sequence numbers and heartbeats, then fetched again). So a
    message can arrive twice; consumers must be idempotent (update by id). Messages from plain
    publishers arrive too, without that recovery. ``on_message`` runs on a Zenoh thread.

    Zenoh's advanced subscriber alone can lose a publisher's cache: when it learns of a publisher
    only after its first history query (the link came up late), a live message that overtakes the
    cache's reply is delivered first, and the older cached messages are then discarded as stale.
    So each publisher that appears is asked for its whole cache once more, here, off Zenoh's thread.
    """

    def __init__(self, session: zenoh.Session, key: str, codec: Codec[M], on_message: Callable[[M], object],
                 *, stats: BusStats | None = None, fetch_timeout_s: float = 10.0,
                 window: CaptureWindow | None = None) -> None:
        self.key = key
        self.codec = codec
        self.stats = stats if stats is not None else BusStats()
        self.window = window if window is not None else CaptureWindow.from_environment()
        self._on_message = on_message
        self._session = session
        self._fetch_timeout_s = fetch_timeout_s
        self._fetches = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"history-{key}")
        advanced = zenoh.ext.declare_advanced_subscriber(
            session, key, self._on_sample,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
            recovery=zenoh.ext.RecoveryConfig(heartbeat=True, periodic_queries=None),
        )
        self._subscriber = advanced
        # Each publisher's liveliness token is also the key its cache answers on.
        self._publishers = advanced.detect_publishers(self._on_publisher, history=True)

    def _on_publisher(self, sample: zenoh.Sample) -> None:  # on a Zenoh thread
        if sample.kind == zenoh.SampleKind.PUT:
            try:
                self._fetches.submit(self._fetch_cache, str(sample.key_expr))
            except RuntimeError:  # closing
                pass

    def _fetch_cache(self, publisher_key: str) -> None:
        try:
            # Every reply has the publication's key: the default consolidation would keep only the last.
            replies = self._session.get(publisher_key, accept_replies=zenoh.ReplyKeyExpr.ANY,
                                        consolidation=zenoh.ConsolidationMode.NONE, target=zenoh.QueryTarget.ALL,
                                        timeout=self._fetch_timeout_s)
            for reply in replies:
                if reply.ok is not None:
                    self.stats.count("received")
                    self._accept(reply.ok)
        except zenoh.ZError as exc:  # the session closed under the query
            log.debug("fetching the cache of %s failed: %s", publisher_key, exc)

    def close(self) -> None:
        _undeclare(self._publishers)
        self._fetches.shutdown(wait=False, cancel_futures=True)
        super().close()


# --- liveliness ----------------------------------------------------------------------------------
def default_instance_id() -> str:
    """``<host>-<pid>``, made safe for a key."""
    return re.sub(r"[^A-Za-z0-9_.-]", "-", f"{socket.gethostname()}-{os.getpid()}")


def announce(session: zenoh.Session, keys: Keys, service: str, instance_id: str | None = None) -> zenoh.LivelinessToken:
    """Declare that this process runs ``service``. Keep the returned token: the service counts as
    up until it is undeclared, its session closes, or its process dies."""
    return session.liveliness().declare_token(keys.alive(service, instance_id or default_instance_id()))


@dataclass(frozen=True, order=True)
class LiveService:
    service: str
    instance: str


@dataclass
class LiveServices:
    """The site's services that are up now, from their liveliness tokens (those already up when
    this starts included). ``on_change(service, alive)`` runs on a Zenoh thread."""

    session: zenoh.Session
    keys: Keys
    on_change: Callable[[LiveService, bool], object] | None = None
    _live: set[LiveService] = field(default_factory=set, init=False)
    _changed: threading.Condition = field(default_factory=threading.Condition, init=False)

    def __post_init__(self) -> None:
        liveliness = self.session.liveliness()
        self._subscriber = liveliness.declare_subscriber(self.keys.alive(), self._on_sample, history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            live = LiveService(*self.keys.service_of(str(sample.key_expr)))
        except ValueError:
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._changed:
            (self._live.add if alive else self._live.discard)(live)
            self._changed.notify_all()
        if self.on_change is not None:
            try:
                self.on_change(live, alive)
            except Exception:
                log.exception("liveliness handler failed")

    def current(self) -> list[LiveService]:
        with self._changed:
            return sorted(self._live)

    def wait_until(self, predicate: Callable[[set[LiveService]], bool], timeout: float) -> bool:
        """Block until ``predicate(live services)`` holds; False after ``timeout`` seconds."""
        with self._changed:
            return self._changed.wait_for(lambda: predicate(set(self._live)), timeout)

    def close(self) -> None:
        _undeclare(self._subscriber)


def all_alive(services: Iterable[str]) -> Callable[[set[LiveService]], bool]:
    """A ``wait_until`` predicate: every named service has at least one live instance."""
    wanted = set(services)
    return lambda live: wanted <= {s.service for s in live}
