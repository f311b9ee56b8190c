"""A test helper for report pages: every text block and axes on the page and apart."""
from __future__ import annotations


def laid_out_apart(fig) -> list[tuple[str, object]]:
    """Every text block and axes of ``fig`` with its box (figure fraction), asserted on the page
    and apart from every other."""
    renderer = fig.canvas.get_renderer()
    inv = fig.transFigure.inverted()
    boxes = [(t.get_text(), t.get_window_extent(renderer).transformed(inv)) for t in fig.texts if t.get_text()]
    boxes += [("axes", ax.get_tightbbox(renderer).transformed(inv)) for ax in fig.axes]
    for i, (a, ba) in enumerate(boxes):
        assert ba.x0 >= -1e-3 and ba.x1 <= 1.0 + 1e-3 and ba.y0 >= -1e-3 and ba.y1 <= 1.0 + 1e-3, a[:60]
        for b, bb in boxes[i + 1:]:
            assert not ba.overlaps(bb), (a[:60], b[:60])
    return boxes
