"""A recording of a detector's boxes played back as the cameras' live detections.

    bevflow serve ingest --site site.yaml --detections DIR --fps 4 [--loop]

``DIR/<camera id>.txt`` holds each camera's MOTChallenge rows (``bevflow.datasets.mot``, the
files ``bevflow evaluate --detections`` scores). Every frame number from the first to the last
is published in real time, ``--fps`` a second, as one ``Detections2D`` per camera on the
camera's detections key, the stage the detector fills live, so no detector runs. A camera with
no box in a frame still reports (an empty message), so the tracker does not wait for it.
"""

from __future__ import annotations

import argparse
import threading
import time

from bevflow.datasets.mot import DetectionRecording, RecordingError, check_no_long_gap, read_detections
from bevflow.schemas import Detections2D
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.runtime import UserError


def load_recording(args: argparse.Namespace, site: Site, cameras: list[str]) -> DetectionRecording:
    if args.fps is None or not args.fps > 0:
        raise UserError("--detections needs --fps F, the frames per second of the recording (F > 0)")
    if not args.min_confidence >= 0:
        raise UserError(f"--min-confidence must be a number >= 0, got {args.min_confidence}")
    sizes = {c.id: c.image_size for c in site.cameras if c.id in cameras}
    try:
        recording = read_detections(args.detections, sizes)
        check_no_long_gap(recording.frames_by_file(), args.fps)
    except RecordingError as exc:
        raise UserError(str(exc)) from None
    if not recording.frame_numbers:
        raise UserError(f"{args.detections}: the cameras' files hold no boxes")
    return recording


def replay(session, keys: bus.Keys, recording: DetectionRecording, args: argparse.Namespace,
           stop: threading.Event) -> None:
    """Publish the recording in real time, once or (``args.loop``) over and over; sequence
    numbers keep counting up across rounds."""
    codec = bus.JsonCodec(Detections2D)
    publications = {c: bus.Publication(session, keys.detections(c), codec) for c in recording.camera_ids}
    first, last = recording.frame_numbers[0], recording.frame_numbers[-1]
    print(f"bevflow ingest: replaying frames {first}..{last} of {len(publications)} cameras from {args.detections} "
          f"at {args.fps:g} fps{' in a loop' if args.loop else ''}", flush=True)
    period_ns = 1e9 / args.fps
    start_ns = time.time_ns()
    seq = 0
    try:
        while True:
            for frame in range(first, last + 1):
                if stop.wait(max(0.0, (start_ns + seq * period_ns - time.time_ns()) / 1e9)):
                    return
                capture_ns = time.time_ns()
                for camera in recording.cameras:
                    boxes = camera.boxes(frame, args.min_confidence)
                    publications[camera.camera_id].put(Detections2D.from_boxes(camera.camera_id, seq, capture_ns, boxes))
                seq += 1
            if not args.loop:
                print("bevflow ingest: the recording has ended", flush=True)
                return
    finally:
        for publication in publications.values():
            publication.close()
