"""bevflow's processes: thin adapters that move the core library's messages over Zenoh and HTTP."""
