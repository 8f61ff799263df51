"""What the bus feeds the calibration routes."""

from __future__ import annotations

from bevflow.detections import Cylinders
from bevflow.schemas import CameraCylinders

from bevflow_services.gateway.calibration_inputs import CalibrationInputs


def test_calibration_inputs_keep_only_the_latest_ticks() -> None:
    inputs = CalibrationInputs(period_ns=100, max_ticks=3)
    for k in range(5):
        inputs.put_cylinders(CameraCylinders.from_cylinders("gate", k, 100 * k + 10, Cylinders(xy=[[float(k), 0.0]])))
    assert [t["gate"].xy[0, 0] for t in inputs.ticks()] == [2.0, 3.0, 4.0]
