"""Test videos made with PyAV: frames of known colours, encoded as a camera would send them."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np

# Per codec, the encoders that may be in the PyAV wheel, preferred first.
ENCODERS = {"h264": ("libx264", "libopenh264"), "hevc": ("libx265",), "mpeg4": ("mpeg4",)}
SIZE = (160, 120)  # width, height


def encoder_for(codec: str) -> str | None:
    """The first encoder of ``codec`` this FFmpeg build has, or None."""
    return next((name for name in ENCODERS[codec] if name in av.codec.codecs_available), None)


def colour_of(index: int) -> tuple[int, int, int]:
    """Frame ``index``'s BGR colour: red-ish, its blue channel counting up so frames differ."""
    return (20 + 15 * (index % 14), 60, 200)


def picture(index: int, size: tuple[int, int] = SIZE) -> np.ndarray:
    return np.full((size[1], size[0], 3), colour_of(index), np.uint8)


def add_video(container: av.container.OutputContainer, encoder: str, fps: int,
              size: tuple[int, int] = SIZE, keyframe_every: int = 10) -> av.VideoStream:
    """A low-latency video stream, as a camera's: no B-frames, a keyframe every ``keyframe_every``."""
    stream = container.add_stream(encoder, rate=fps)
    stream.width, stream.height, stream.pix_fmt = size[0], size[1], "yuv420p"
    stream.time_base = Fraction(1, fps)
    stream.codec_context.gop_size = keyframe_every
    stream.codec_context.max_b_frames = 0
    if encoder == "libx264":
        stream.options = {"preset": "ultrafast", "tune": "zerolatency"}
    elif encoder == "libx265":
        stream.options = {"preset": "ultrafast", "tune": "zerolatency", "x265-params": "log-level=error"}
    return stream


def encode(container: av.container.OutputContainer, stream: av.VideoStream, image: np.ndarray | None,
           index: int = 0) -> None:
    """Encode frame ``index`` (None: flush the encoder) and write its packets."""
    frame = None
    if image is not None:
        frame = av.VideoFrame.from_ndarray(image, format="bgr24")
        frame.pts = index
    container.mux(stream.encode(frame))


def write_video(path: Path, encoder: str, frames: int, fps: int = 25) -> None:
    with av.open(str(path), "w") as container:
        stream = add_video(container, encoder, fps)
        for i in range(frames):
            encode(container, stream, picture(i), i)
        encode(container, stream, None)
