"""Whether this CPU multiplies 8-bit integers fast enough for a quantised model to pay.

ONNX Runtime's integer convolutions are fast on CPUs with 8-bit dot-product instructions (x86
VNNI or AMX, Arm's dot product and matrix-multiply extensions); without them an INT8 model is
slower than its float original. Measured with ``bevflow bench`` (``detector_int8_speedup_5_5m_
2_threads``, the general model at 5.5 m on 2 threads): 1.91–1.93 on an AMD EPYC with AVX-512
VNNI (docs/BENCHMARKS.md), 0.88–0.89 on one with AVX2 only (25.5 against 22.6 ms).

>>> int8_dot_product("flags\\t\\t: fpu sse2 avx2 avx512f avx512_vnni")
True
>>> int8_dot_product("flags\\t\\t: fpu sse2 avx2 fma")
False
>>> int8_dot_product("Features\\t: fp asimd asimddp")
True
"""

from __future__ import annotations

from pathlib import Path

CPUINFO = Path("/proc/cpuinfo")
# /proc/cpuinfo's names: x86 ``flags`` (AVX-512 VNNI, AVX-VNNI, AMX), Arm ``Features`` (SDOT/UDOT, I8MM).
INT8_DOT_PRODUCT_FLAGS = frozenset({"avx512_vnni", "avx_vnni", "amx_int8", "asimddp", "i8mm"})


def int8_dot_product(cpuinfo: str | None = None) -> bool:
    """Whether the CPU (``cpuinfo``: the text of /proc/cpuinfo, read when None) has 8-bit
    dot-product instructions; False where that cannot be told (no /proc/cpuinfo)."""
    if cpuinfo is None:
        try:
            cpuinfo = CPUINFO.read_text(errors="replace")
        except OSError:
            return False
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("flags", "Features") and INT8_DOT_PRODUCT_FLAGS.intersection(value.split()):
            return True
    return False
