"""Time the cylinder fit against its reference, and measure the feet error of each method.

    python scripts/bench_cylinder.py [--camera fisheye-5.5] [--boxes 10 50 200] [--accuracy] [--json OUT]

The benchmark lives in ``bevflow_services.benchmarks.cylinder``; ``bevflow bench`` runs its speed
part with every other benchmark.
"""

from bevflow_services.benchmarks.cylinder import main

if __name__ == "__main__":
    main()
