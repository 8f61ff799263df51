"""The ingest service: cameras (streams, files, the simulator) onto the bus."""
