import threading

import pytest

from bevflow_services.detector.schedule import ReadyCameras


@pytest.mark.parametrize(
    ("steps", "claimed"),
    [
        # arrived X / claim / release X, and what each claim got
        (["+b", "+a", "claim", "claim", "claim"], ["b", "a", None]),  # the longest-waiting first
        (["+a", "+b", "+a", "claim", "claim"], ["a", "b"]),  # a newer frame keeps its camera's place
        (["+a", "claim", "+a", "claim"], ["a", None]),  # one worker at a time on a camera
        (["+a", "claim", "+a", "-a", "claim"], ["a", "a"]),  # ... its next frame once released
        (["+a", "+b", "claim", "+a", "claim", "-a", "claim"], ["a", "b", "a"]),
        (["claim", "-a", "claim"], [None, None]),  # releasing an idle camera is harmless
    ],
)
def test_cameras_are_handed_out_longest_waiting_first_one_worker_each(steps: list[str], claimed: list[str | None]) -> None:
    ready, got = ReadyCameras(), []
    for step in steps:
        if step == "claim":
            got.append(ready.claim(timeout=0))
        elif step.startswith("+"):
            ready.arrived(step[1:])
        else:
            ready.release(step[1:])
    assert got == claimed


def test_a_waiting_worker_gets_the_camera_whose_frame_arrives() -> None:
    ready, got = ReadyCameras(), []
    worker = threading.Thread(target=lambda: got.append(ready.claim(timeout=10)))
    worker.start()
    ready.arrived("a")
    worker.join(10)
    assert got == ["a"]


def test_a_released_camera_with_a_new_frame_wakes_a_waiting_worker() -> None:
    ready, got = ReadyCameras(), []
    ready.arrived("a")
    assert ready.claim(timeout=0) == "a"
    ready.arrived("a")  # while the first worker still has it
    worker = threading.Thread(target=lambda: got.append(ready.claim(timeout=10)))
    worker.start()
    ready.release("a")
    worker.join(10)
    assert got == ["a"]
