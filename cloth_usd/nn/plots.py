"""Training curves as PNG."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from .runs import EpochRecord

__all__ = ["plot_history"]


def plot_history(history: Sequence[EpochRecord], path: str | Path, title: str = "", *,
                 loss_label: str = "loss (MSE / output scale^2)", mm_label: str = "validation error [mm]",
                 log_loss: bool = True) -> Path:
    """Training and validation loss (log scale) and the validation error [mm] per epoch, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    epochs = [r.epoch for r in history]
    fig = Figure(figsize=(9, 3.5))
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(epochs, [r.train_loss for r in history], "o-", label="train", ms=3)
    ax1.plot(epochs, [r.val_loss for r in history], "s-", label="validation", ms=3)
    if log_loss:
        ax1.set_yscale("log")
    ax1.set_xlabel("epoch")
    ax1.set_ylabel(loss_label)
    ax1.legend()
    ax2.plot(epochs, [r.val_mm for r in history], "s-", color="C1", ms=3)
    ax2.set_xlabel("epoch")
    ax2.set_ylabel(mm_label)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(str(path), dpi=100)
    return Path(path)
