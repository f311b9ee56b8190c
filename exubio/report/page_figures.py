"""The drawing machinery of the trial report's pages: A4 figures re-used per page layout (a
process draws one report at a time), titles pinned, plotted curves thinned to their envelope, and
text that wraps by bisection inside its box. exubio.report.trial_report draws the pages with them."""
from __future__ import annotations

import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import matplotlib as mpl
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.ticker import NullLocator
from matplotlib.transforms import Bbox


PDF_COMPRESSION = 1
"""zlib level of the reports' PDF streams. matplotlib's default (6) cost about 6 % more of a trial
report's CPU for files 12-21 % smaller (benchmarks/README.md, "The curves thinned, the PDFs at zlib
level 1, ..."); the content drawn is the same."""


@contextmanager
def pdf_pages(path: Path) -> Iterator[PdfPages]:
    """matplotlib's PdfPages at ``path``, its pages compressed at ``PDF_COMPRESSION``."""
    with mpl.rc_context({"pdf.compression": PDF_COMPRESSION}), PdfPages(path) as pdf:
        yield pdf


def _figure(size=(11.69, 8.27)) -> Figure:
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    return fig


def _figure_with_axes(*rects) -> Figure:
    """A new A4 figure with axes at ``rects`` (figure fractions), for pages that place them later."""
    fig = _figure()
    for rect in rects:
        fig.add_axes(rect)
    return fig


# --------------------------------------------------------------------------------------------
# Figures of the plot pages, drawn again for the next trial of the process
# --------------------------------------------------------------------------------------------
# Creating the axes and, at the first drawing, their tick marks and labels (matplotlib makes
# each tick of new axes from a few Line2D and Text objects) is about a third of a report's time.
# The plot pages of a trial have the same axes as the previous trial's: after a report is written
# its plot pages wait here, emptied of their data, and the next report draws into them. A page
# is taken from here only by one report at a time (threads of one process each take their own).
_FREE_PAGES: dict[tuple, list[Figure]] = {}
_FREE_PAGES_LOCK = threading.Lock()
_FREE_PAGES_MAX = 2  # figures kept per page layout (a process draws one report at a time)
_PAGE_KEY = "_exubio_page_key"


def _page_figure(key: tuple, make) -> tuple[Figure, bool]:
    """(figure, reused): a free figure of layout ``key`` emptied of its content (see
    :func:`_empty`), else ``make()`` (a new figure with that layout's axes)."""
    with _FREE_PAGES_LOCK:
        free = _FREE_PAGES.get(key)
        fig = free.pop() if free else None
    if fig is None:
        fig = make()
        reused = False
    else:
        _empty(fig)
        reused = True
    setattr(fig, _PAGE_KEY, key)
    return fig, reused


def _release(fig: Figure) -> None:
    """A plot page whose report is written: kept for the next report of this process."""
    key = getattr(fig, _PAGE_KEY, None)
    if key is None:
        return
    with _FREE_PAGES_LOCK:
        free = _FREE_PAGES.setdefault(key, [])
        if len(free) < _FREE_PAGES_MAX and all(f is not fig for f in free):
            free.append(fig)


def _empty(fig: Figure) -> None:
    """Take out of a drawn plot page what its page function puts in, so that drawing into it again
    gives what a new figure gives: the data artists, legends, the figure's texts but its suptitle, containers, property cycles, data
    limits (the view limits follow the data again: every axes of a layout gets data, see the page
    keys), the facecolor and the automatic title placement. The axes, their sharing, and their
    tick objects stay (the layout, labels, titles and tick settings are set again by the page)."""
    for legend in list(fig.legends):
        legend.remove()
    for text in list(fig.texts):  # the page's own text blocks; its suptitle stays, set again by the page
        if text is not getattr(fig, "_suptitle", None):
            text.remove()
    for ax in fig.axes:
        for container in list(ax.containers):
            container.remove()
        if ax.legend_ is not None:
            ax.legend_.remove()
        for artist in [*ax.lines, *ax.collections, *ax.patches, *ax.texts, *ax.images, *ax.tables, *ax.artists]:
            artist.remove()
        ax.set_prop_cycle(None)
        ax.dataLim = Bbox.null()
        ax.ignore_existing_data_limits = True
        ax.set_facecolor(mpl.rcParams["axes.facecolor"])
        ax._autotitlepos = mpl.rcParams["axes.titley"] is None  # as Axes.clear() sets it


def _pin_titles(fig: Figure) -> Figure:
    """Fix each axes title where matplotlib's automatic placement would put it anyway (y = 1,
    ``titlepad`` above the axes), so that drawing does not place it again: the automatic placement
    measures the x and y axes' ticks and labels of every titled axes once more (a third of the time
    of drawing the ISB page). It moves a title only above x tick labels or an x label at the top,
    or off a y-axis offset text ("1e-5", "+1.2e2") it overlaps; axes with any of those, or with
    inset axes, keep the automatic placement. Call once the page's data and layout are final."""
    for ax in fig.axes:
        if not ax.get_title() or ax.get_title(loc="left") or ax.get_title(loc="right") or ax.child_axes:
            continue
        if _x_labels_at_top(ax):
            continue
        y = ax.yaxis
        if y.get_visible() and y.offsetText.get_visible():
            y.get_major_formatter().format_ticks(y.get_majorticklocs())  # what drawing formats
            if y.get_major_formatter().get_offset():
                continue
        ax.set_title(ax.get_title(), fontsize=ax.title.get_fontsize(), y=1.0)
    return fig


def _x_labels_at_top(ax) -> bool:
    """Whether the x axis has its label or tick labels at the top (inner axes of a shared x axis,
    whose tick labels are hidden, have none)."""
    xa = ax.xaxis
    if xa.get_label_position() == "top":
        return True
    if xa.get_ticks_position() not in ("top", "unknown"):
        return False
    ticks = list(xa.get_major_ticks(1))
    if not isinstance(xa.get_minor_locator(), NullLocator):
        ticks += list(xa.get_minor_ticks(1))
    return any(t.label2.get_visible() for t in ticks)


PLOT_POINTS = 800
"""Time series are drawn with at most about this many points per curve (an A4 panel is ~1000 px
wide, so 400 bins of min and max): each bin keeps its minimum and maximum, so spikes stay visible."""


def _envelope(t: np.ndarray, *ys: np.ndarray, keep: int = 1, points: int = PLOT_POINTS) -> tuple[np.ndarray, ...]:
    """(t, y...) reduced to the samples holding each bin's minimum and maximum of each of the first
    ``keep`` ys (``points`` // 2 bins of consecutive samples), and the samples on both sides of each
    of their gaps (NaN), so that a gap is drawn where it is, however short."""
    n = len(t)
    if n <= points:
        return (t, *ys)
    k = int(np.ceil(n / max(points // 2, 1)))
    m = (n // k) * k
    base = np.arange(m // k) * k
    parts = [np.arange(m, n)]
    for y in ys[:keep]:
        y = np.asarray(y, dtype=float)
        finite = np.isfinite(y)
        blocks, inside = y[:m].reshape(-1, k), finite[:m].reshape(-1, k)
        parts += [base + np.argmin(np.where(inside, blocks, np.inf), axis=1),  # 0 in a block with no value
                  base + np.argmax(np.where(inside, blocks, -np.inf), axis=1)]
        edges = np.flatnonzero(finite[1:] != finite[:-1])
        parts += [edges, edges + 1]
    idx = np.unique(np.concatenate(parts))
    return (t[idx], *(np.asarray(y)[idx] for y in ys))


class _BisectWrapText(Text):
    """A Text with ``wrap=True`` that breaks its lines where matplotlib's greedy wrapping does
    (each line takes words while its rendered width stays within the figure), finding each break
    by bisection instead of measuring every longer prefix in turn (which took a third of the time
    of drawing the verdict page): a line's width grows with every word it takes. Text with "$"
    (mathtext, whose width does not grow word by word) is wrapped by matplotlib itself.

    The lines and the widths measured are kept (see :func:`_metrics_key`): a text is wrapped when
    it is measured on the page, again when the PDF draws it and once more for the PNG, and the same
    texts (the notes, most reasons) come again in every trial's report."""

    def _get_wrapped_text(self) -> str:
        text = self.get_text()
        if not self.get_wrap() or self.get_usetex() or "$" in text:
            return super()._get_wrapped_text()
        line_width = self._get_wrap_line_width()
        key = (_metrics_key(self), text, line_width)
        done = _WRAPS.get(key)
        if done is None:
            done = self._bisect_lines(text, line_width, key[0])
            _remember(_WRAPS, key, done)
        return done

    def _bisect_lines(self, text: str, line_width: float, metrics: tuple) -> str:
        def width(s: str) -> float:
            k = (metrics, s)
            w = _WIDTHS.get(k)
            if w is None:
                w = self._get_rendered_text_width(s)
                _remember(_WIDTHS, k, w)
            return w

        wrapped = []
        for unwrapped in text.split("\n"):
            words = unwrapped.split(" ")
            while words:
                if len(words) == 1:
                    wrapped.append(words.pop(0))
                    continue
                lo, hi = 2, len(words) + 1  # the first i in [2, len] whose words[:i] are too wide
                while lo < hi:
                    mid = (lo + hi) // 2
                    if width(" ".join(words[:mid])) > line_width:
                        hi = mid
                    else:
                        lo = mid + 1
                if lo <= len(words):
                    wrapped.append(" ".join(words[:lo - 1]))
                    words = words[lo - 1:]
                else:
                    wrapped.append(" ".join(words))
                    words = []
        return "\n".join(wrapped)


_WRAPS: dict[tuple, str] = {}
_WIDTHS: dict[tuple, float] = {}
_CACHED_MAX = 20000  # entries per cache (a report adds a few hundred); emptied when full
_METRIC_RCPARAMS = ("text.hinting", "text.hinting_factor", "text.kerning_factor", "pdf.use14corefonts", "ps.useafm",
                    "font.family", "font.sans-serif", "font.serif", "font.monospace", "font.cursive", "font.fantasy")


def _metrics_key(text: Text) -> tuple:
    """What a plain text's rendered width depends on besides its string: the renderer's kind and
    resolution (Agg measures with hinting at its dpi, the PDF without hinting in points), the
    figure's dpi, the font properties and the settings that pick and measure the font. Two texts
    with the same key measure any string alike (matplotlib's own cache of text metrics is kept per
    renderer, and the PDF has a new renderer per page)."""
    renderer = text._renderer
    rc = tuple(tuple(v) if isinstance(v, list) else v for v in (mpl.rcParams[k] for k in _METRIC_RCPARAMS))
    return (type(renderer), getattr(renderer, "dpi", None), text.get_figure(root=True).dpi, rc,
            text.get_fontproperties().copy())


def _remember(cache: dict, key: tuple, value) -> None:
    if len(cache) >= _CACHED_MAX:
        cache.clear()
    cache[key] = value


def _bisect_wrap(text: Text) -> Text:
    """``text`` (from ``Figure.text``, so it sits among the figure's texts) wrapped by bisection."""
    text.__class__ = _BisectWrapText
    return text
