"""What the tracks mean: distance violations, occupancy, crowded intervals, contacts."""
