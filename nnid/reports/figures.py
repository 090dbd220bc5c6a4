"""Figures as self-contained data URIs and the page head of the HTML reports, so a report is
one file readable without a server.

Figures are :class:`matplotlib.figure.Figure` objects rendered straight to PNG: no pyplot
state machine and no backend switch, so writing a report leaves the user's matplotlib setup
(and any figure they have open) untouched. Matplotlib is imported by the functions that draw,
not with this module: a report without figures (``nnid train`` of any model but a hybrid)
imports this module for its tables, and matplotlib's import took 0.6 s of CPU (2026-11-30).
"""

from __future__ import annotations

import base64
import html
import io
import re
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import numpy as np
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

UNITS = {"u": "m/s", "v": "m/s", "w": "m/s", "p": "rad/s", "q": "rad/s", "r": "rad/s"}
FORCE_UNITS = {"X": "N", "Y": "N", "Z": "N", "K": "N m", "M": "N m", "N": "N m"}


def figure_uri(fig: Figure) -> str:
    """PNG data URI of a figure (cropped to what it draws, unless its margins are fixed)."""
    buf = io.BytesIO()
    tight = "tight" if fig.get_layout_engine() is not None else None
    # zlib level 3, not PIL's 6: 35-45 % less encoding time, for a file 6 % smaller (the
    # hybrid's 24 scatter panels) or 0.4 % larger (six panels of lines), 2026-11-30
    pil = {"compress_level": 3}
    fig.savefig(buf, format="png", dpi=110, bbox_inches=tight, pil_kwargs=pil)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


#: inches kept around the panels of a ``fixed`` figure: tick labels and an axis label on the
#: left and below, a title above
FIXED_MARGINS_IN = dict(left=0.85, right=0.2, top=0.35, bottom=0.5)
#: gaps between the panels of a ``fixed`` figure, fractions of a panel's height and width
FIXED_GAPS = dict(hspace=0.35, wspace=0.15)
#: inches left of ``fixed`` panels whose y tick labels are not bounded like a correlation's
#: (a velocity, a force): room for the y label and eight characters (``−0.00050``, a DOF barely
#: moving) with one to spare (tests hold the labels inside for amplitudes 1e-4 to 1e6)
LONG_TICKS_LEFT_IN = 1.2


def new_figure(
    rows: int = 1,
    cols: int = 1,
    width: float = 9.0,
    height: float = 3.0,
    fixed: bool = False,
    left: float | None = None,
    right: float | None = None,
    hspace: float | None = None,
    wspace: float | None = None,
    sharey: bool | str = False,
) -> tuple[Figure, np.ndarray]:
    """A figure and its axes grid ``[rows, cols]`` (``height`` per row), laid out so tick
    labels of one panel never run into the next. ``fixed``: :data:`FIXED_MARGINS_IN` instead of
    matplotlib's constrained layout, for a grid of small panels whose labels are known to
    fit; it draws once, in about half the time or less (the constrained layout measures every
    label, then the crop draws the figure again). ``left``, ``right``: other margins [in] of
    a ``fixed`` figure (:data:`LONG_TICKS_LEFT_IN`); ``hspace``, ``wspace``: other gaps than
    :data:`FIXED_GAPS`. ``sharey``: as :meth:`matplotlib.figure.Figure.subplots` (``"row"``:
    one y axis per row, its tick labels on the first panel only)."""
    from matplotlib.figure import Figure

    if fixed:
        fig = Figure(figsize=(width, height * rows))
        asked = {"left": left, "right": right, "hspace": hspace, "wspace": wspace}
        m = {**FIXED_MARGINS_IN, **FIXED_GAPS, **{k: v for k, v in asked.items() if v is not None}}
        fig.subplots_adjust(
            left=m["left"] / width,
            right=1.0 - m["right"] / width,
            top=1.0 - m["top"] / (height * rows),
            bottom=m["bottom"] / (height * rows),
            hspace=m["hspace"],
            wspace=m["wspace"],
        )
    else:
        fig = Figure(figsize=(width, height * rows), layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False, sharey=sharey)


#: inches between a ``fixed`` panel's y offset text and a legend above the panel
LEGEND_GAP_IN = 0.05


def legend_outside(
    ax: Axes, ncols: int, fontsize: float, side: Literal["above", "below"] = "above"
) -> None:
    """A legend of ``ax``'s lines outside it, in a ``fixed`` figure: ``"above"`` the panel
    (where a title would be) or ``"below"`` its x tick labels and x label (the bottom margin
    of :data:`FIXED_MARGINS_IN`). That margin is made to hold it, measured rather than guessed
    (its rows go with the number of lines, its width with their names, the user's), and the
    figure grows or shrinks by as much, so that its panels keep their size whatever the
    legend; in fewer columns where ``ncols`` would run past the figure's right edge. A measure
    of one legend, not a layout of the whole figure."""
    if side not in ("above", "below"):
        raise ValueError(f"legend side must be 'above' or 'below', not {side!r}")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.transforms import ScaledTranslation

    fig = ax.get_figure()
    renderer = FigureCanvasAgg(fig).get_renderer()
    if side == "above":
        # clear of the y axis's offset text (``1e6`` over the panel's top left corner, when
        # its tick labels are scaled): one line of its font, above matplotlib's pad
        offset = ax.yaxis.offsetText.get_fontproperties()
        _, h, descent = renderer.get_text_width_height_descent("1e6", offset, ismath=False)
        gap_in = ax.yaxis.OFFSETTEXTPAD / 72 + (h - descent) / fig.dpi + LEGEND_GAP_IN
    else:  # below the x tick labels and the x label
        gap_in = -FIXED_MARGINS_IN["bottom"]
    # anchored in inches from the panel, so that it stays there when the margin changes
    y = 1.0 if side == "above" else 0.0
    anchor = ax.transAxes + ScaledTranslation(0.0, gap_in, fig.dpi_scale_trans)
    loc = "lower left" if side == "above" else "upper left"
    for n in range(ncols, 0, -1):
        legend = ax.legend(
            ncols=n, fontsize=fontsize, loc=loc, bbox_to_anchor=(0.0, y), bbox_transform=anchor
        )
        box = legend.get_window_extent(renderer)
        if box.x1 <= fig.bbox.x1 or n == 1:
            break
    # the legend, its gap to the panel and 0.1 inch to the figure's edge
    margin_in = box.height / fig.dpi + abs(gap_in) + 0.1
    height, par = fig.get_figheight(), fig.subplotpars
    top_in, bottom_in = (1.0 - par.top) * height, par.bottom * height
    panels_in = height - top_in - bottom_in
    if side == "above":
        top_in = margin_in
    else:
        bottom_in = margin_in
    height = panels_in + top_in + bottom_in
    fig.set_figheight(height)
    fig.subplots_adjust(top=1.0 - top_in / height, bottom=bottom_in / height)


PAGE_HEAD = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;
text-align:right}}th{{background:#eee}}td:first-child{{text-align:left}}img{{max-width:100%}}
dl.columns dt{{font-weight:bold;float:left;clear:left;width:12em}}dl.columns dd{{margin-left:13em}}
</style></head><body>
<h1>{title}</h1>
"""

IMAGES_CHECK = """<script>
window.addEventListener("load", function () {
  var ok = Array.prototype.every.call(document.images, function (i) {
    return i.complete && i.naturalWidth > 0; });
  document.body.setAttribute("data-images-ok", ok ? "yes" : "no");
});
</script>
"""
"""Sets ``data-images-ok`` on the body once every embedded figure decoded (checked by the
report tests in headless Chromium)."""


def page_head(title: str) -> str:
    """The start of a self-contained report page: doctype, style and the title heading."""
    return PAGE_HEAD.format(title=html.escape(title))


def _cell(text: str) -> str:
    """A table cell's text, escaped, with the Markdown code spans the shared (Markdown and
    HTML) tables write (`` `X:u*abs(u)` ``) as ``<code>``: escaped, their backticks showed."""
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", html.escape(text))


def html_table(head: list[str], rows: list[list[str]]) -> str:
    """An HTML table of text cells (escaped; Markdown code spans as ``<code>``)."""
    h = "".join(f"<th>{_cell(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


def markdown_cell(text: str) -> str:
    """A Markdown table cell's text with its pipes escaped: a model name with '|' (a config
    label may hold one) split its cell and shifted every column after it."""
    return text.replace("|", r"\|")


def markdown_table(head: list[str], rows: list[list[str]]) -> list[str]:
    """The same table in Markdown, one line per row (cells through :func:`markdown_cell`)."""

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(markdown_cell(c) for c in cells) + " |"

    return [line(head), "|" + "---|" * len(head), *(line(r) for r in rows)]


def plot_label(name: str) -> str:
    """A name as a matplotlib legend label draws it: '$' escaped (an even number of them was
    parsed as mathtext, and a bad one raised in savefig after every fit) and a leading '_'
    guarded by a space (matplotlib leaves a label starting with '_' out of the legend)."""
    text = name.replace("$", r"\$")
    return " " + text if text.startswith("_") else text


def said_list(items: list[str], title: str = "Warnings") -> str:
    """What a run said of its data or its results (its warnings, its notes), as a headed
    HTML list; empty where it said nothing."""
    if not items:
        return ""
    lines = "".join(f"<li>{html.escape(w)}</li>" for w in items)
    return f"<h2>{html.escape(title)}</h2><ul>{lines}</ul>"


def definitions(terms: dict[str, str]) -> str:
    """An HTML definition list of table columns."""
    items = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(v)}</dd>" for k, v in terms.items())
    return f'<dl class="columns">{items}</dl>'
