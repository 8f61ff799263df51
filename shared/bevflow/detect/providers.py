"""Which ONNX Runtime execution providers the detector runs on.

A site names an ordered list (``detector_providers`` in the site file, ``bevflow serve detector
--providers``), most wanted first: ``tensorrt``, ``cuda``, ``openvino``, ``cpu``. The ones the
installed ONNX Runtime build offers are used in that order, and the CPU always comes last, so a
detector host without its accelerator (a driver missing, the CPU build of onnxruntime installed)
still runs, more slowly, and says so in its log instead of failing. The builds are separate
packages that each install the ``onnxruntime`` module, one per host (the ``cpu``, ``gpu`` and
``openvino`` extras: ``onnxruntime``, ``onnxruntime-gpu`` for CUDA and TensorRT,
``onnxruntime-openvino``; INSTALL.md).

>>> plan = plan_providers(["cuda", "cpu"], ["AzureExecutionProvider", "CPUExecutionProvider"])
>>> plan.use, plan.unavailable
(['CPUExecutionProvider'], ['cuda'])

A build can offer a provider that then fails to load (``onnxruntime-gpu`` on a host without the
driver or CUDA's libraries): ONNX Runtime falls back to the CPU on its own, and ``not_loaded``
names what the session went without.

>>> plan = plan_providers(["cuda"], ["CUDAExecutionProvider", "CPUExecutionProvider"])
>>> plan.not_loaded(["CPUExecutionProvider"])
['cuda']
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

PROVIDERS = {
    "tensorrt": "TensorrtExecutionProvider",
    "cuda": "CUDAExecutionProvider",
    "openvino": "OpenVINOExecutionProvider",
    "cpu": "CPUExecutionProvider",
}
DEFAULT_PROVIDERS = ("cpu",)


@dataclass(frozen=True)
class ProviderPlan:
    """``use``: ONNX Runtime provider names to pass to the session, in order, the CPU last;
    ``unavailable``: the requested names this build of ONNX Runtime does not offer."""

    use: list[str]
    unavailable: list[str]

    def not_loaded(self, loaded: Sequence[str]) -> list[str]:
        """The short names of the providers planned but missing from a session's ``loaded`` ones."""
        short = {full: name for name, full in PROVIDERS.items()}
        return [short[full] for full in self.use if full not in loaded]

    def needs_cuda(self) -> bool:
        """Whether a planned provider loads CUDA's libraries (CUDA, TensorRT)."""
        return any(PROVIDERS[name] in self.use for name in ("cuda", "tensorrt"))

    def describe(self) -> str:
        """One log line: what runs, and what was asked for but is missing."""
        line = f"detector runs on {', '.join(self.use)}"
        if self.unavailable:
            line += f"; not available in this onnxruntime build: {', '.join(self.unavailable)} (falling back)"
        return line


def check_providers(names: Sequence[str]) -> list[str]:
    """``names`` lower-cased, refused with a message naming the choices if one is unknown or the
    list is empty."""
    wanted = [n.strip().lower() for n in names if n.strip()]
    unknown = [n for n in wanted if n not in PROVIDERS]
    if unknown or not wanted:
        raise ValueError(f"unknown detector provider {', '.join(unknown) or '(none given)'}; "
                         f"choose from {', '.join(PROVIDERS)}, most wanted first")
    return wanted


def plan_providers(requested: Sequence[str], available: Sequence[str]) -> ProviderPlan:
    """The providers to use for ``requested`` (short names, see ``PROVIDERS``) given those the
    installed ONNX Runtime offers (``onnxruntime.get_available_providers()``)."""
    wanted = check_providers(requested)
    offered = set(available)
    use = [PROVIDERS[n] for n in wanted if PROVIDERS[n] in offered and n != "cpu"]
    unavailable = [n for n in wanted if PROVIDERS[n] not in offered]
    return ProviderPlan(use + [PROVIDERS["cpu"]], unavailable)
