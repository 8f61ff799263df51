"""The recorder service: writes the tracker's occupancy, alerts and trajectories to the history
database (``bevflow serve recorder --db URL``)."""
