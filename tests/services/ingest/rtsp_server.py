"""A camera stand-in that speaks RTSP: H.264 over RTP, interleaved on the RTSP connection (TCP).

Just enough of RFC 2326 (OPTIONS, DESCRIBE, SETUP, PLAY; any other request is answered 200, as a
keep-alive is) and of RFC 6184 (single NAL unit and FU-A packets) for FFmpeg's RTSP client. Each
client gets its own stream from the first frame, in real time. Credentials in the URL are not
checked. ``stall()`` makes every stream go silent with its connection open, as a hung camera does;
``resume()`` lets streams opened after it play again.
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from fractions import Fraction

import av

from tests.services.ingest.media import SIZE, encoder_for, picture

MAX_PAYLOAD = 1400
CLOCK_HZ = 90_000  # RTP's video clock
SDP = ("v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=bevflow test camera\r\nc=IN IP4 0.0.0.0\r\nt=0 0\r\n"
       "m=video 0 RTP/AVP 96\r\na=rtpmap:96 H264/90000\r\na=fmtp:96 packetization-mode=1\r\na=control:track1\r\n")


class RtspCamera:
    def __init__(self, fps: int = 25) -> None:
        self.fps = fps
        self.transports: list[str] = []  # the Transport header of every SETUP
        self.stalled = threading.Event()
        self._closed = threading.Event()
        self._server = socket.create_server(("127.0.0.1", 0))
        self.port = self._server.getsockname()[1]
        threading.Thread(target=self._accept, daemon=True).start()

    def url(self, credentials: str = "") -> str:
        return f"rtsp://{credentials}127.0.0.1:{self.port}/stream1"

    def stall(self) -> None:
        self.stalled.set()

    def resume(self) -> None:
        """Streams opened from now on are live again."""
        self.stalled.clear()

    def close(self) -> None:
        self._closed.set()
        self._server.close()

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                connection, _ = self._server.accept()
            except OSError:
                return
            threading.Thread(target=self._session, args=(connection,), daemon=True).start()

    def _session(self, connection: socket.socket) -> None:
        lock = threading.Lock()  # answers and media share the connection
        try:
            with connection, connection.makefile("rb") as requests:
                while not self._closed.is_set() and (request := _read_request(requests)) is not None:
                    method, url, headers = request
                    extra, body = self._answer(method, url, headers)
                    reply = f"RTSP/1.0 200 OK\r\nCSeq: {headers.get('cseq', '0')}\r\n{extra}"
                    reply += f"Content-Length: {len(body)}\r\n\r\n{body}"
                    with lock:
                        connection.sendall(reply.encode())
                    if method == "PLAY":
                        threading.Thread(target=self._send_media, args=(connection, lock), daemon=True).start()
        except OSError:  # the client hung up
            pass

    def _answer(self, method: str, url: str, headers: dict[str, str]) -> tuple[str, str]:
        if method == "OPTIONS":
            return "Public: OPTIONS, DESCRIBE, SETUP, PLAY, TEARDOWN, GET_PARAMETER\r\n", ""
        if method == "DESCRIBE":
            return f"Content-Base: {url}/\r\nContent-Type: application/sdp\r\n", SDP
        if method == "SETUP":
            self.transports.append(headers.get("transport", ""))
            return "Transport: RTP/AVP/TCP;unicast;interleaved=0-1\r\nSession: 1;timeout=60\r\n", ""
        return "Session: 1\r\n", ""

    def _send_media(self, connection: socket.socket, lock: threading.Lock) -> None:
        encoder = av.CodecContext.create(encoder_for("h264") or "libx264", "w")
        encoder.width, encoder.height, encoder.pix_fmt = SIZE[0], SIZE[1], "yuv420p"
        encoder.time_base, encoder.framerate = Fraction(1, self.fps), Fraction(self.fps)
        encoder.gop_size, encoder.max_b_frames = 10, 0
        encoder.options = {"preset": "ultrafast", "tune": "zerolatency"}
        began, sequence = time.monotonic(), 0
        for index in range(self.fps * 60):
            if self._closed.is_set() or self.stalled.is_set():
                return
            frame = av.VideoFrame.from_ndarray(picture(index), format="bgr24")
            frame.pts = index
            for packet in encoder.encode(frame):
                for rtp in _rtp_packets(bytes(packet), index * CLOCK_HZ // self.fps, sequence):
                    try:
                        with lock:
                            connection.sendall(b"$\x00" + struct.pack(">H", len(rtp)) + rtp)
                    except OSError:
                        return
                    sequence += 1
            time.sleep(max(0.0, began + (index + 1) / self.fps - time.monotonic()))


def _read_request(requests) -> tuple[str, str, dict[str, str]] | None:  # noqa: ANN001
    """The next request (method, URL, headers by lower-case name); None once the client is gone."""
    line = requests.readline()
    while line in (b"\r\n", b"\n"):
        line = requests.readline()
    if not line:
        return None
    method, url, _ = line.decode().split(" ", 2)
    headers = {}
    for raw in iter(requests.readline, b"\r\n"):
        if not raw:
            return None
        name, _, value = raw.decode().partition(":")
        headers[name.strip().lower()] = value.strip()
    requests.read(int(headers.get("content-length", "0")))
    return method, url, headers


def _nal_units(annex_b: bytes) -> list[bytes]:
    return [unit.strip(b"\x00") for unit in annex_b.split(b"\x00\x00\x01") if unit.strip(b"\x00")]


def _rtp_packets(annex_b: bytes, timestamp: int, first_sequence: int) -> list[bytes]:
    """One encoded frame as RTP packets (RFC 6184): small NAL units whole, large ones in FU-A
    fragments; the marker bit on the frame's last packet."""
    payloads = []
    for unit in _nal_units(annex_b):
        if len(unit) <= MAX_PAYLOAD:
            payloads.append(unit)
            continue
        indicator, kind = (unit[0] & 0xE0) | 28, unit[0] & 0x1F
        chunks = [unit[i:i + MAX_PAYLOAD] for i in range(1, len(unit), MAX_PAYLOAD)]
        for i, chunk in enumerate(chunks):
            start_end = (0x80 if i == 0 else 0) | (0x40 if i == len(chunks) - 1 else 0)
            payloads.append(bytes([indicator, start_end | kind]) + chunk)
    packets = []
    for i, payload in enumerate(payloads):
        marker = 0x80 if i == len(payloads) - 1 else 0
        header = struct.pack(">BBHII", 0x80, marker | 96, (first_sequence + i) & 0xFFFF, timestamp & 0xFFFFFFFF, 0xBEF10)
        packets.append(header + payload)
    return packets
