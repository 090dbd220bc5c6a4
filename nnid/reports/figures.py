"""Figures as self-contained data URIs and the page head of the HTML reports, so a report is
one file readable without a server."""

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


PAGE_HEAD = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;
text-align:right}}th{{background:#eee}}td:first-child{{text-align:left}}img{{max-width:100%}}
</style></head><body>
<h1>{title}</h1>
"""


def page_head(title: str) -> str:
    """The start of a self-contained report page: doctype, style and the title heading."""
    import html

    return PAGE_HEAD.format(title=html.escape(title))
