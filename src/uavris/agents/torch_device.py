"""The torch device a command trains or acts on (``--device``).

Lives here: :func:`resolve_device`, used by the SB3 experts and the Decision Transformer
alike. Not here: thread settings (:func:`uavris.experiments.engine.process.configure_threads`).
CPU is the default and what the test suite runs; results on a GPU are not bit-identical
to the CPU's (different kernels), so a study that must reproduce exactly stays on the CPU.
"""

from __future__ import annotations

from typing import Literal, get_args

from uavris.errors import ConfigError

Device = Literal["cpu", "cuda", "auto"]  # what --device accepts
DEVICES: tuple[str, ...] = get_args(Device)


def resolve_device(name: str) -> str:
    """``"cpu"`` or ``"cuda"`` for ``name`` in :data:`DEVICES`; ``auto`` takes CUDA when torch sees it."""
    if name not in DEVICES:
        raise ConfigError(f"unknown device {name!r}; choose one of {', '.join(DEVICES)}")
    if name == "cpu":
        return "cpu"
    import torch

    if torch.cuda.is_available():
        return "cuda"
    if name == "auto":
        return "cpu"
    build = f"a CUDA {torch.version.cuda} build" if torch.version.cuda else "a CPU-only build"
    raise ConfigError(f"--device cuda: torch {torch.__version__} ({build}) sees no CUDA device; use --device cpu, "
                      "or install a CUDA build of torch (README, 'GPU')")
