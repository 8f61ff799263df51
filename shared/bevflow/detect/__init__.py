"""Person detection on ceiling fisheye frames: ONNX Runtime inference with height-adaptive scaling
and decoders for the project's own model and common YOLO-family exports."""
