"""bevflow core library: camera models, 3D cylinder projection, fusion, tracking and analytics.

Pure and typed. It never imports zenoh, fastapi or viser; the services in ``bevflow_services``
adapt it to the network.
"""

__version__ = "0.1.0"
