"""What a long run shows while it runs: a progress bar on the terminal, TensorBoard logs on disk.

Lives here: :func:`progress_bar` (every bar of uavris: training, rollouts, the study) and
:func:`tb_writer` (the TensorBoard writer of a run directory's ``tb/``). Not here: what is
counted or logged (the training and evaluation code that calls them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tqdm.auto import tqdm


def progress_bar(total: float, desc: str, unit: str, enabled: bool, initial: float = 0, **kwargs: Any) -> Any:
    """A tqdm bar (usable as a context manager); a disabled one, whose calls do nothing, when
    progress output is off. ``kwargs`` go to tqdm (``leave``, ``bar_format``)."""
    return tqdm(total=total, initial=initial, unit=unit, desc=desc, dynamic_ncols=True, disable=not enabled,
                **kwargs)


def tb_writer(run_dir: Path, start: int) -> Any:
    """TensorBoard's writer for ``run_dir/tb``; resuming at step ``start`` > 0 drops the events
    an interrupted session logged after its last checkpoint, so none is counted twice."""
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(str(run_dir / "tb"), purge_step=start if start > 0 else None)
