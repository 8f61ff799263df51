"""The Zenoh router: links client-mode services and other hosts (``bevflow serve router``)."""
