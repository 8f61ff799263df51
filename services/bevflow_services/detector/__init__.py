"""The detector service: people in camera frames, as 2D boxes per camera."""
