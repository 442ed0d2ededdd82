"""Figures in a style fit for a paper: PNG (200 dpi) and PDF side by side.

Lives here: :func:`save_figure`, the shared colours and reference lines (:data:`COLORS`,
:data:`REFERENCE_STYLE`, :func:`reference_lines`) and :func:`learning_curves`, the
comparison's figure. Not here: the report's figures (:mod:`uavris.experiments.study.report.figures`)
and the curves of individual runs (:mod:`.run_curves`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import io

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from uavris.io import atomic_write_bytes  # noqa: E402

COLORS = {"ddpg": "#1f77b4", "ppo": "#ff7f0e", "sac": "#2ca02c", "td3": "#d62728"}
plt.rcParams.update({"font.size": 9, "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": 100,
                     "savefig.bbox": "tight", "pdf.fonttype": 42})


def save_figure(fig: plt.Figure, stem: Path) -> list[Path]:
    """Write ``stem.png`` and ``stem.pdf`` atomically (the suffixes appended: a dot in the stem's
    name is kept); returns both paths."""
    out = []
    for ext, kw in (("png", {"dpi": 200}), ("pdf", {})):
        buf = io.BytesIO()
        fig.savefig(buf, format=ext, **kw)
        path = stem.parent / f"{stem.name}.{ext}"
        atomic_write_bytes(path, buf.getvalue())
        out.append(path)
    plt.close(fig)
    return out


REFERENCE_STYLE = {"zero-action": ("0.35", "--"), "hover-optimizer": ("#9467bd", "-."), "oracle": ("k", ":")}


def reference_lines(ax: plt.Axes, references: Mapping[str, tuple[str, float]]) -> None:
    """Horizontal lines at reference scores, ``references[key] = (label, value)``."""
    for key, (label, value) in references.items():
        color, ls = REFERENCE_STYLE.get(key, ("0.5", "--"))
        ax.axhline(value, color=color, ls=ls, lw=1.0, label=f"{label} ({value:.1f})")


def learning_curves(curves: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
                    stem: Path, title: str, paper_values: Mapping[str, float] | None = None,
                    references: Mapping[str, tuple[str, float]] | None = None) -> list[Path]:
    """Average sum rate vs training episodes: the mean over seeds, and a band that is the 95%
    Student-t interval of that mean over the seeds, its lower edge clipped at 0.

    The band is a spread over a handful of seeds (t's quantile at 2 seeds is 12.7), so its raw
    lower edge can fall below 0, which no sum rate can: it is drawn from 0. ``curves[name] =
    (episodes, mean, low, high)``; optional dotted lines at the paper's converged values and
    horizontal lines at reference scores (:func:`reference_lines`). The legend sits below the
    axes, where it covers no curve.
    """
    fig, ax = plt.subplots(figsize=(4.8, 3.6))
    reference_lines(ax, references or {})
    for name, (x, mean, lo, hi) in curves.items():
        color = COLORS.get(name)
        ax.plot(x, mean, label=name.upper(), color=color, lw=1.4)
        ax.fill_between(x, np.maximum(lo, 0.0), hi, color=color, alpha=0.2, lw=0)
        if paper_values and name in paper_values:
            ax.axhline(paper_values[name], color=color, ls=":", lw=0.9)
    if paper_values:  # one legend entry for the dotted lines (each in its algorithm's colour)
        ax.plot([], [], color="0.4", ls=":", lw=0.9, label="paper's converged value")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # episodes are whole: no tick at 1.5
    ax.set_xlabel("training episode")
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=3, fontsize=7, frameon=False)
    return save_figure(fig, stem)
