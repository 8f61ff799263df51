"""``bevflow calibrate``: from pictures and marked points to a site file that holds the right camera."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.camera import rotation_from_ypr
from bevflow.site import dump_site, load_site, parse_site
from bevflow.sim.presets import preset
from bevflow_services.cli import main
from tests.bevflow.calibration.boards import FISHEYE, rendered_images

SITE = """\
# Test hall: one camera over the door, one over the till.
site: test-hall
cameras:
  - id: door          # over the main door
    model: fisheye
    image_size: [640, 640]
    intrinsics: {fx: 200.0, fy: 200.0, cx: 320.0, cy: 320.0}   # datasheet values
    distortion: [0.0, 0.0, 0.0, 0.0]
    pose: {position: [2.0, 3.0, 3.3]}
  - id: till
    image_size: [640, 640]
    intrinsics: {fx: 200.0, fy: 200.0, cx: 320.0, cy: 320.0}
    pose: {position: [8.0, 3.0, 3.3]}
"""
DOOR_POSITION = np.array([2.0, 3.0, 3.3])
DOOR_YPR = (20.0, 1.0, 0.0)


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("shots")
    for k, (image, _) in enumerate(rendered_images(FISHEYE, 10, seed=7)):
        cv2.imwrite(str(folder / f"shot{k:02d}.png"), image)
    cv2.imwrite(str(folder / "empty.png"), np.full((640, 640), 128, np.uint8))
    (folder / "notes.txt").write_text("not a picture")
    return folder


@pytest.fixture(scope="module")
def few_shots(shots: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("few")
    for path in sorted(shots.glob("shot*.png"))[:3]:
        (folder / path.name).write_bytes(path.read_bytes())
    return folder


@pytest.fixture
def site_file(tmp_path: Path) -> Path:
    path = tmp_path / "site.yaml"
    path.write_text(SITE)
    return path


def points_file(path: Path, noise_px: float = 0.3, wrong: str | None = None) -> Path:
    R = rotation_from_ypr(*DOOR_YPR)
    camera = FISHEYE.with_pose(R, -R @ DOOR_POSITION)
    rng = np.random.default_rng(0)
    world = [(x, y, 0.0) for x in (-1.0, 1.0, 3.5, 5.0) for y in (0.5, 3.0, 5.5)]
    with path.open("w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(["name", "u", "v", "x", "y", "z"])
        for k, (x, y, z) in enumerate(world):
            u, v = camera.project(np.array([[x, y, z]]))[0] + rng.normal(0, noise_px, 2)
            name = f"mark{k}"
            writer.writerow([name, f"{u:.2f}", f"{v:.2f}", x + (0.5 if name == wrong else 0.0), y, z])
    return path


def test_intrinsics_writes_the_lens_and_keeps_the_file(shots: Path, site_file: Path, capsys: pytest.CaptureFixture) -> None:
    rc = main(["calibrate", "intrinsics", "--images", str(shots), "--board", "9x6", "--square", "0.03", "--camera", "door", "--site", str(site_file)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "empty.png" in out and "no board" in out and "RMS" in out and "next:" in out and "calibrate extrinsics" in out
    site = load_site(site_file)
    door = site.cameras[0]
    np.testing.assert_allclose([door.intrinsics.fx, door.intrinsics.fy], [205.0, 204.0], rtol=0.005)
    np.testing.assert_allclose([door.intrinsics.cx, door.intrinsics.cy], [322.3, 318.1], atol=1.5)
    assert door.distortion != [0.0, 0.0, 0.0, 0.0]
    text = site_file.read_text()
    assert "# over the main door" in text and "# Test hall" in text and "pose: {position: [2.0, 3.0, 3.3]}" in text
    assert site.cameras[1] == parse_site(SITE).cameras[1]
    assert (site_file.parent / "site.yaml.bak").read_text() == SITE


def test_intrinsics_from_a_video(shots: Path, site_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    video = tmp_path / "board.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, (640, 640))
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write MJPG video")
    for path in sorted(shots.glob("shot*.png")):
        writer.write(cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), cv2.COLOR_GRAY2BGR))
    writer.release()
    rc = main(["calibrate", "intrinsics", "--video", str(video), "--board", "9x6", "--square", "0.03", "--camera", "door",
               "--site", str(site_file), "--dry-run"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "frame 0" in out and "--dry-run" in out
    assert site_file.read_text() == SITE


def test_extrinsics_writes_the_pose(site_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lens_only = SITE.replace("intrinsics: {fx: 200.0, fy: 200.0, cx: 320.0, cy: 320.0}   # datasheet values",
                             "intrinsics: {fx: 205.0, fy: 204.0, cx: 322.3, cy: 318.1}")
    site_file.write_text(lens_only.replace("distortion: [0.0, 0.0, 0.0, 0.0]", "distortion: [0.03, -0.01, 0.002, -0.0003]"))
    rc = main(["calibrate", "extrinsics", "--camera", "door", "--points", str(points_file(tmp_path / "p.csv")), "--site", str(site_file)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "mark11" in out and "camera centre (2.0" in out
    assert "next: 1 camera(s) still hang at their planned pose (till)" in out and "extrinsics --camera till" in out
    site = load_site(site_file)
    door = site.cameras[0]
    assert door.pose is None and door.extrinsics is not None
    np.testing.assert_allclose(site.camera("door").center, DOOR_POSITION, atol=0.05)
    assert "# over the main door" in site_file.read_text()


def test_extrinsics_refuses_a_wrong_point_and_leaves_the_file(site_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    before = site_file.read_text()
    rc = main(["calibrate", "extrinsics", "--camera", "door", "--points", str(points_file(tmp_path / "p.csv", wrong="mark4")),
               "--site", str(site_file)])
    assert rc == 2
    captured = capsys.readouterr()
    assert "mark4" in captured.err and "refused" in captured.err and captured.err.count("\n") == 1
    assert "mark4" in captured.out  # the table is shown before the refusal
    assert site_file.read_text() == before


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["intrinsics", "--images", "{shots}", "--board", "9by6", "--square", "0.03", "--camera", "door"], "COLSxROWS"),
        (["intrinsics", "--images", "{shots}", "--board", "9x6", "--square", "0.03", "--camera", "hall"], "no camera 'hall'; its cameras are door, till"),
        (["intrinsics", "--images", "{missing}", "--board", "9x6", "--square", "0.03", "--camera", "door"], "no such folder"),
        (["intrinsics", "--video", "{missing}", "--board", "9x6", "--square", "0.03", "--camera", "door"], "not a readable video"),
        (["intrinsics", "--images", "{few}", "--board", "7x5", "--square", "0.03", "--camera", "door"], "only 0 usable board views"),
        (["extrinsics", "--camera", "door", "--points", "{missing}"], "cannot read the points file"),
        (["check", "--dataset", "wildtrack"], "--root"),
        (["check", "--sim", "nowhere"], "unknown preset"),
    ],
)
def test_user_errors_are_one_line(argv: list[str], message: str, shots: Path, few_shots: Path, site_file: Path,
                                  tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = [a.format(shots=shots, few=few_shots, missing=tmp_path / "missing") for a in argv]
    rc = main(["calibrate", *argv, "--site", str(site_file)])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1
    assert site_file.read_text() == SITE


def test_a_missing_site_file_is_a_user_error(shots: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    rc = main(["calibrate", "intrinsics", "--images", str(shots), "--board", "9x6", "--square", "0.03", "--camera", "door",
               "--site", str(tmp_path / "none.yaml")])
    assert rc == 2 and "bevflow plan" in capsys.readouterr().err


def test_check_on_a_simulation_finds_a_misplaced_camera(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """seq1's two cameras, with cam2 written 0.6 m east of where it hangs: the pair is flagged."""
    site = preset("seq1").site
    moved = site.cameras[1].model_copy(update={"pose": site.cameras[1].pose.model_copy(update={"position": (10.5, 3.5, 3.3)})})
    path = tmp_path / "seq1.yaml"
    path.write_text(dump_site(site.model_copy(update={"cameras": [site.cameras[0], moved]})))
    rc = main(["calibrate", "check", "--sim", "seq1", "--site", str(path), "--frames", "300", "--gate", "1.5", "--min-samples", "5"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "cam1 / cam2" in out and "disagree" in out and "calibrate extrinsics --camera" in out


def test_check_passes_the_preset_as_it_is(capsys: pytest.CaptureFixture) -> None:
    assert main(["calibrate", "check", "--sim", "seq1", "--frames", "300", "--min-samples", "5"]) == 0
    out = capsys.readouterr().out
    assert "cam1 / cam2" in out and "every pair agrees" in out


def test_check_on_annotated_recordings(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from tests.bevflow.datasets.test_wildtrack import write_fake_wildtrack

    root = write_fake_wildtrack(tmp_path / "wildtrack")
    assert main(["calibrate", "check", "--dataset", "wildtrack", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "CVLab1 / CVLab2" in out and "median offset" in out


def test_check_listens_to_a_running_system(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A stand-in projector publishes two cameras' cylinders on loopback; the check hears them,
    keeps them with --save, and a second check reads the saved file the same way."""
    import socket
    import threading

    from bevflow.detections import Cylinders
    from bevflow.schemas import CameraCylinders
    from bevflow_services import bus

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    site_path = tmp_path / "site.yaml"
    site_path.write_text(SITE)
    publisher_session = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    stop = threading.Event()

    def projector() -> None:
        keys = bus.Keys("test-hall")
        outs = {c: bus.Publication(publisher_session, keys.cylinders(c), bus.JsonCodec(CameraCylinders)) for c in ("door", "till")}
        rng = np.random.default_rng(0)
        seq = 0
        while not stop.is_set():
            person = np.array([[5.0 + rng.uniform(-0.5, 0.5), 3.0 + rng.uniform(-2, 2)]])
            for camera, shift in (("door", 0.0), ("till", 0.2)):
                cylinders = Cylinders(xy=person + [shift, 0.0], height=[1.7], radius=[0.25])
                outs[camera].put(CameraCylinders.from_cylinders(camera, seq, 10**18 + seq * 10**8, cylinders))
            seq += 1
            stop.wait(0.02)

    thread = threading.Thread(target=projector, daemon=True)
    thread.start()
    saved = tmp_path / "heard.jsonl"
    try:
        rc = main(["calibrate", "check", "--site", str(site_path), "--live", "1.5", "--save", str(saved), "--connect", endpoint])
    finally:
        stop.set()
        thread.join()
        publisher_session.close()
    assert rc == 0
    out = capsys.readouterr().out
    assert "door / till" in out and "(-0.20, +0.00)" in out and "saved the recording" in out
    assert main(["calibrate", "check", "--site", str(site_path), "--cylinders", str(saved)]) == 0
    assert "(-0.20, +0.00)" in capsys.readouterr().out


def test_check_does_not_judge_pairs_with_few_samples(capsys: pytest.CaptureFixture) -> None:
    assert main(["calibrate", "check", "--sim", "seq1", "--frames", "300", "--min-samples", "1000"]) == 0
    out = capsys.readouterr().out
    assert "too few samples to judge" in out and "no pair has enough samples" in out


EXTRINSICS = "extrinsics: {rvec: [3.14159, 0, 0], tvec: [-2, 3, 3.3]}"


@pytest.mark.parametrize(
    ("till_pose", "cameras", "expected"),
    [
        ("pose: {position: [8.0, 3.0, 3.3]}", 2, ["1 camera(s) still hang at their planned pose (till)", "intrinsics --camera till",
                                                 "extrinsics --camera till"]),
        (EXTRINSICS, 2, ["every camera is calibrated", "bevflow calibrate check --site SITE --live 120"]),
        (EXTRINSICS, 1, ["start the system with this site", "step 6"]),
    ],
    ids=["one-left", "all-done", "single-camera"],
)
def test_the_step_after_a_pose(till_pose: str, cameras: int, expected: list[str]) -> None:
    from bevflow.site import parse_site

    from bevflow_services.cli.calibrate import _next_after_extrinsics

    text = SITE.replace("pose: {position: [8.0, 3.0, 3.3]}", till_pose)
    if cameras == 1:
        text = text[: text.index("  - id: till")]
    message = _next_after_extrinsics(parse_site(text), "door", Path("SITE"))
    assert message.startswith("next: ")
    for part in expected:
        assert part in message
