"""End-to-end evaluation runs: datasets and simulated suites through the whole pipeline."""
