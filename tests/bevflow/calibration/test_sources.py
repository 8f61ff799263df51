"""Sources of frames for the consistency check: messages grouped into ticks, simulation, dataset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bevflow.calibration.sources import dataset_source, message_source, simulated_source
from bevflow.datasets.wildtrack import load_wildtrack
from bevflow.detections import Cylinders
from bevflow.schemas import CameraCylinders
from bevflow.sim.presets import preset
from tests.bevflow.datasets.test_wildtrack import write_fake_wildtrack

SITE = preset("seq1").site  # cameras cam1, cam2


def message(camera: str, capture_ms: int, xs: list[float]) -> CameraCylinders:
    cylinders = Cylinders(xy=[[x, 3.0] for x in xs], height=[1.7] * len(xs), radius=[0.25] * len(xs))
    return CameraCylinders.from_cylinders(camera, 0, capture_ms * 1_000_000, cylinders)


def test_messages_within_one_tick_form_one_frame() -> None:
    messages = [message("cam1", 1000, [6.0]), message("cam2", 1030, [6.1]), message("cam1", 1100, [6.5, 7.0]), message("cam1", 1120, [8.0])]
    source = message_source(SITE, messages)
    frames = list(source.frames)
    assert source.camera_ids == ["cam1", "cam2"] and len(frames) == 2
    assert sorted(frames[0]) == [0, 1] and len(frames[1][0]) == 3  # two messages of cam1 in one tick merge
    np.testing.assert_allclose(frames[0][1].xy, [[6.1, 3.0]])
    assert (frames[0][1].camera == 1).all()
    assert len(list(message_source(SITE, messages, frames=1).frames)) == 1


def test_messages_of_unknown_cameras_are_refused() -> None:
    with pytest.raises(ValueError, match="camera.s. gate, which the site does not have"):
        message_source(SITE, [message("gate", 0, [1.0])])


def test_simulation_projects_with_the_site_under_test() -> None:
    exact = simulated_source("seq1", frames=3)
    frames = list(exact.frames)
    assert exact.camera_ids == ["cam1", "cam2"] and len(frames) == 3
    assert exact.cameras[0].center[2] == pytest.approx(3.3)
    lower = SITE.model_copy(update={"cameras": [c.model_copy(update={"pose": c.pose.model_copy(update={"position": (*c.pose.position[:2], 3.0)})}) for c in SITE.cameras]})
    assert simulated_source("seq1", lower, frames=1).cameras[0].center[2] == pytest.approx(3.0)
    with pytest.raises(ValueError, match="no camera cam2 .the simulated cameras are cam1, cam2"):
        simulated_source("seq1", preset("seq6").site, frames=1)


def test_dataset_source(tmp_path: Path) -> None:
    dataset = load_wildtrack(write_fake_wildtrack(tmp_path / "wildtrack"))
    source = dataset_source(dataset, frames=2)
    frames = list(source.frames)
    assert len(frames) == 2 and sorted(frames[0]) == list(range(len(source.camera_ids)))
    with pytest.raises(ValueError, match="the site has no camera"):
        dataset_source(dataset, SITE)
