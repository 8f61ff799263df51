"""What the gateway's websockets share: who may open them, and forwarding a subscription to a client."""
