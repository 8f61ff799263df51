"""``bevflow serve mqtt``: the site's alerts and occupancy, published to an MQTT broker."""
