"""Settings a model file keeps for ``bevflow.detect.runtime.Detector`` (its ``metadata_props``):
written into the file, the other keys it holds left as they are.

``set_score_threshold`` keeps a model's reporting threshold (``SCORE_THRESHOLD_METADATA_KEY``),
chosen as the best-F1 score on rendered frames of its cameras (``bevflow evaluate --detector``
prints it), so that a site reports people with the confidence that suits that network.
``set_score_map`` keeps the map of its scores onto the general model's (``bevflow.detect.confidence``);
the threshold is then on the mapped scale.
"""

from __future__ import annotations

import math
from pathlib import Path

from bevflow.detect.confidence import SCORE_MAP_METADATA_KEY, ScoreMap
from bevflow.detect.runtime import SCORE_THRESHOLD_METADATA_KEY


def set_metadata(path: Path, key: str, value: str) -> None:
    """Write ``key`` = ``value`` into the ONNX file at ``path``, keeping its other keys."""
    import onnx

    proto = onnx.load(str(path))
    props = {p.key: p.value for p in proto.metadata_props}
    props[key] = value
    onnx.helper.set_model_props(proto, props)
    onnx.save(proto, str(path))


def set_score_threshold(path: Path, threshold: float) -> None:
    """Keep ``threshold`` (0 to 1) in the model file as its reporting threshold."""
    if not (math.isfinite(threshold) and 0.0 < threshold < 1.0):
        raise ValueError(f"a score threshold lies between 0 and 1, got {threshold}")
    set_metadata(path, SCORE_THRESHOLD_METADATA_KEY, f"{threshold:g}")


def set_score_map(path: Path, score_map: ScoreMap) -> None:
    """Keep ``score_map`` in the model file: the detector reports its scores mapped by it."""
    set_metadata(path, SCORE_MAP_METADATA_KEY, score_map.to_text())
