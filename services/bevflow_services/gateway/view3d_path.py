"""Where the gateway serves the 3D view: its page under ``PATH/`` and its websocket at ``PATH``."""

PATH = "/view3d"
