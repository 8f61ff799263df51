"""Benchmarks of whole services (the core library has its own under scripts/)."""
