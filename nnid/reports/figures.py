"""Figures as self-contained data URIs, so a report is one file readable without a server."""

from __future__ import annotations

import base64
import io

import matplotlib

matplotlib.use("Agg")  # reports are written headless
import matplotlib.pyplot as plt


def figure_uri(fig) -> str:
    """PNG data URI of a matplotlib figure (the figure is closed)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def new_figure(rows: int = 1, cols: int = 1, width: float = 9.0, height: float = 3.0):
    return plt.subplots(rows, cols, figsize=(width, height * rows), squeeze=False)
