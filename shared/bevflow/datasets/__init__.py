"""Readers for public multi-camera datasets, giving cameras, boxes and ground truth in metres."""
