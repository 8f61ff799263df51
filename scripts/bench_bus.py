"""Latency of the bus between two processes on one host (frames and small JSON messages).

    python scripts/bench_bus.py                      # peer to peer, shared memory on
    python scripts/bench_bus.py --no-shared-memory
    python scripts/bench_bus.py --via-router         # both processes as clients of a router
    python scripts/bench_bus.py --consumer async     # through AsyncSubscription to an event loop

The benchmark lives in ``bevflow_services.benchmarks.bus``; ``bevflow bench`` runs it with every
other benchmark.
"""

from bevflow_services.benchmarks.bus import main

if __name__ == "__main__":
    main()
