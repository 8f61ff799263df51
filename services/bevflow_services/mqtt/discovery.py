"""Home Assistant MQTT discovery: one occupancy sensor for the site and one per zone, announced
as retained config messages, so Home Assistant lists them without any configuration of its own.

https://www.home-assistant.io/integrations/mqtt/#mqtt-discovery: ``PREFIX/sensor/NODE/OBJECT/config``.
"""

from __future__ import annotations

import json
import re

from bevflow.site import Site


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", text)


def discovery_messages(site: Site, site_id: str, topic_prefix: str, discovery_prefix: str) -> list[tuple[str, bytes]]:
    """(topic, payload) of every sensor's config, for ``topic_prefix``'s occupancy topics."""
    node = f"bevflow_{_safe(site_id)}"
    device = {"identifiers": [node], "name": f"bevflow {site_id}", "manufacturer": "bevflow"}
    # (id, name, state topic, value template: None for a plain number)
    sensors: list[tuple[str, str, str, str | None]] = [
        ("site", f"{site_id} occupancy", f"{topic_prefix}/{site_id}/occupancy", "{{ value_json.total }}")
    ]
    sensors += [(zone.id, f"{zone.name or zone.id} occupancy", f"{topic_prefix}/{site_id}/zones/{zone.id}/occupancy", None)
                for zone in site.zones]
    messages = []
    for key, name, state_topic, template in sensors:
        config = {"name": name, "unique_id": f"{node}_{_safe(key)}_occupancy", "state_topic": state_topic,
                  "unit_of_measurement": "people", "state_class": "measurement", "device": device}
        if template is not None:
            config["value_template"] = template
        messages.append((f"{discovery_prefix}/sensor/{node}/{_safe(key)}_occupancy/config", json.dumps(config).encode()))
    return messages
