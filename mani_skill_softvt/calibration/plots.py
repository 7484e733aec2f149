"""Figures of the calibration: per asset (peak D vs closure) and a summary of all ten."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..fileio import atomic_write
from .cards import CalibrationCard


def _draw(ax, card: CalibrationCard) -> None:
    recs = card.records
    g = np.array([r["closure"] for r in recs])
    d = 100 * np.array([r["peak_deformation"] for r in recs])
    held = np.array([r["held"] for r in recs])
    ax.axvspan(card.g_min, card.g_max, color="tab:green", alpha=0.12, label="envelope [g_min, g_max]")
    ax.scatter(g[held], d[held], s=14, c="tab:green", label="held")
    ax.scatter(g[~held], d[~held], s=18, c="tab:red", marker="x", label="slipped / dropped")
    ax.axhline(100 * card.tau_o, color="k", ls="--", lw=1, label=f"tau_o (p{card.percentile:.0f})")
    ax.set_title(f"{card.asset_id}\nspan {card.span_mm:.1f} mm, tau_o {100 * card.tau_o:.2f} %", fontsize=8)
    ax.set_xlabel("closure g", fontsize=8)
    ax.set_ylabel("peak D (% of bbox diagonal)", fontsize=8)
    ax.tick_params(labelsize=7)


def plot_card(card: CalibrationCard, out: Path) -> None:
    fig = Figure(figsize=(4.5, 3.4))
    ax = fig.subplots()
    _draw(ax, card)
    ax.legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, dpi=120))


def plot_summary(cards: list[CalibrationCard], out: Path) -> None:
    cols = 5
    rows = max(1, int(np.ceil(len(cards) / cols)))
    fig = Figure(figsize=(3.2 * cols, 2.9 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel()[len(cards):]:
        ax.axis("off")
    for ax, card in zip(axes.ravel(), cards):
        _draw(ax, card)
    axes.ravel()[0].legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    atomic_write(out, lambda p: fig.savefig(p, dpi=110))
