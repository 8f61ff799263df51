"""The dashboard: static pages served by the gateway (no build step)."""
