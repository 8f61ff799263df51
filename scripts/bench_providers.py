"""The detector on other ONNX Runtime execution providers against the CPU's, alternately in one
process; run it in an install with the openvino or gpu extra (docs/INSTALL.md).

    python scripts/bench_providers.py openvino,cpu
    python scripts/bench_providers.py tensorrt,cuda,cpu cuda,cpu --threads 2

The benchmark lives in ``bevflow_services.benchmarks.providers``.
"""

from bevflow_services.benchmarks.providers import main

if __name__ == "__main__":
    main()
