"""The tracker service: fusion, the one site tracker and the analytics."""
