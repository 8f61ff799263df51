"""One router per resource: occupancy, intervals, tracks, alerts, cameras, health, site, streams."""
