"""Collection settings for the whole tree: pytest reads this file before it collects the core
library's modules for their examples."""

import importlib.util

# The training modules import torch, which only the train extra installs.
_NEED_TORCH = [f"shared/bevflow/training/{name}.py" for name in ("export", "fastestdet", "model", "tile_train", "train")]
collect_ignore_glob = [] if importlib.util.find_spec("torch") else _NEED_TORCH
