"""The gateway service: REST and websocket access to one site's live and recent state, the
dashboard, and the 3D view. ``create_app`` builds the FastAPI app over a ``GatewayState``;
``main`` feeds that state from the bus."""

from bevflow_services.gateway.app import create_app
from bevflow_services.gateway.state import GatewayState

__all__ = ["GatewayState", "create_app"]
