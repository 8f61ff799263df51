from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from bevflow.training.model import CenterNetSmall, DetectorExport, parameter_count  # noqa: E402
from bevflow.training.train import TrainConfig, build_targets, detection_loss, train  # noqa: E402


def test_model_is_small_and_fully_convolutional() -> None:
    model = CenterNetSmall().eval()
    assert 300_000 < parameter_count(model) < 800_000
    with torch.no_grad():
        heat, size, offset = model(torch.zeros(2, 3, 96, 160))
    assert heat.shape == (2, 1, 24, 40) and size.shape == (2, 2, 24, 40) and offset.shape == (2, 2, 24, 40)


def test_export_wrapper_keeps_only_peaks() -> None:
    wrapper = DetectorExport(CenterNetSmall().eval()).eval()
    with torch.no_grad():
        heat, size, _ = wrapper(torch.rand(1, 3, 64, 64) * 255)
    h = heat[0, 0]
    peaks = torch.nn.functional.max_pool2d(h[None, None], 3, 1, 1)[0, 0]
    assert bool(((h == 0) | (h == peaks)).all())
    assert bool((size > 0).all())


def test_targets_put_a_peak_at_the_box_centre() -> None:
    t = build_targets(np.array([[10.5, 20.5, 30.5, 28.5]]), np.array([False]), 64)
    cx, cy = (20.5 + 0.5) / 4, (24.5 + 0.5) / 4
    assert t["heat"][0, int(cy), int(cx)] == pytest.approx(1.0)
    assert t["index"][0] == int(cy) * 16 + int(cx)
    np.testing.assert_allclose(t["offset"][0], [cx - int(cx), cy - int(cy)], atol=1e-6)
    np.testing.assert_allclose(np.exp(t["log_size"][0]) * 16, [20.0, 8.0], rtol=1e-5)
    assert t["valid"].sum() == 1


def test_ignored_boxes_mask_negatives_and_add_no_positive() -> None:
    t = build_targets(np.array([[10.5, 20.5, 30.5, 28.5]]), np.array([True]), 64)
    assert t["heat"].max() == 0 and t["valid"].sum() == 0
    assert t["neg_mask"][0, 6, 5] == 0 and t["neg_mask"][0, 0, 0] == 1


def test_loss_falls_when_the_model_fits_one_batch() -> None:
    torch.manual_seed(0)
    model = CenterNetSmall()
    t = build_targets(np.array([[10.5, 20.5, 30.5, 38.5]]), np.array([False]), 64)
    targets = {k: torch.from_numpy(v[None]) for k, v in t.items()}
    x = torch.zeros(1, 3, 64, 64)
    x[:, :, 20:39, 10:31] = 2.0
    opt = torch.optim.Adam(model.parameters(), 3e-3)
    first = None
    for _ in range(30):
        loss, _ = detection_loss(model(x), targets)
        first = first if first is not None else float(loss)
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss) < 0.5 * first


def test_training_resumes_from_its_checkpoint(tmp_path: Path) -> None:
    from bevflow.training.dataset import render_dataset

    render_dataset(tmp_path / "data", 4, seed=3, shard_size=2)
    config = TrainConfig(steps=2, batch=2, crop=64, warmup=1, log_every=1)
    lines: list[str] = []
    train(tmp_path / "data", tmp_path / "run", config, log=lines.append)
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    assert state["step"] == 2
    train(tmp_path / "data", tmp_path / "run", TrainConfig(steps=3, batch=2, crop=64, warmup=1, log_every=1), log=lines.append)
    assert any("resumed at step 2" in line for line in lines)
    assert torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)["step"] == 3


def test_an_exported_model_reads_back_into_the_same_network(tmp_path: Path) -> None:
    import onnxruntime as ort

    from bevflow.detect.runtime import DEFAULT_MODEL
    from bevflow.training.export import model_from_onnx
    from bevflow.training.model import normalise

    image = np.random.default_rng(0).uniform(0, 255, (2, 3, 96, 128)).astype(np.float32)
    model = model_from_onnx(DEFAULT_MODEL, normalise(torch.from_numpy(image)))
    with torch.no_grad():
        ours = [t.numpy() for t in DetectorExport(model).eval()(torch.from_numpy(image))]
        model.train()
        train_heat = torch.sigmoid(model(normalise(torch.from_numpy(image)))[0]).numpy()
    shipped = ort.InferenceSession(str(DEFAULT_MODEL), providers=["CPUExecutionProvider"]).run(None, {"image": image})
    for name, a, b in zip(("heatmap", "size", "offset"), ours, shipped, strict=True):
        assert np.abs(a - b).max() < 1e-3 * max(1.0, float(np.abs(b).max())), name
    # On its calibration batch, train mode's batch statistics are the running ones.
    peaks = shipped[0] > 0
    assert np.abs(train_heat[peaks] - shipped[0][peaks]).max() < 1e-3


def test_training_can_start_from_an_exported_model(tmp_path: Path) -> None:
    from bevflow.detect.runtime import DEFAULT_MODEL
    from bevflow.training.dataset import render_dataset

    render_dataset(tmp_path / "data", 2, seed=3, shard_size=2)
    lines: list[str] = []
    train(tmp_path / "data", tmp_path / "run", TrainConfig(steps=1, batch=2, crop=64, warmup=1, log_every=1), log=lines.append, init=DEFAULT_MODEL)
    assert any("starting from the weights of" in line for line in lines)
    state = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)["model"]
    assert float(state["stem.0.1.running_var"].min()) != 1.0  # calibrated, not the fresh model's


def test_the_exported_file_carries_the_scale_it_was_trained_at(tmp_path: Path) -> None:
    from bevflow.detect.runtime import Detector
    from bevflow.training.dataset import render_dataset
    from bevflow.training.export import export_onnx, load_checkpoint

    render_dataset(tmp_path / "data", 2, seed=3, shard_size=2, zoom=1.2)
    config = TrainConfig(steps=1, batch=2, crop=64, warmup=1, log_every=1, zoom=1.2)
    model, zoom = load_checkpoint(train(tmp_path / "data", tmp_path / "run", config, log=lambda _m: None))
    assert zoom == 1.2
    detector = Detector(export_onnx(model, tmp_path / "zoomed.onnx", zoom=zoom), threads=1)
    assert detector.zoom == 1.2
    assert detector.scale_for(3.3, 300.0) == pytest.approx(1.2 * 40 * 1.9 / 300.0)
