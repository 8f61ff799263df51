"""Calibration: a camera's lens (intrinsics), where it hangs (extrinsics), whether overlapping
cameras agree (consistency), and noticing live when one of them has moved (drift)."""
