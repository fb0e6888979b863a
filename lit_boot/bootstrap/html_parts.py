"""Building blocks of the self-contained HTML reports: images inlined as base64 PNG, colour-bar
legends, tables, the page frame. Nothing is loaded from the network or another file.

Every text given to these helpers is escaped here, but :class:`Markup` (a link, an image).
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence

import cv2
import numpy as np
from matplotlib import colormaps

__all__ = ["Markup", "png_data_uri", "img", "link", "colour_bar", "swatches", "table", "page", "esc"]


class Markup(str):
    """Trusted markup (built by these helpers): :func:`esc` leaves it as it is."""


def esc(text: str) -> str:
    """``text`` with HTML's special characters escaped, unless it is :class:`Markup`."""
    return text if isinstance(text, Markup) else html.escape(text)


def link(href: str, text: str) -> Markup:
    """``<a href=...>text</a>``, both escaped."""
    return Markup(f'<a href="{html.escape(href)}">{html.escape(text)}</a>')

_CSS = """
body { font: 15px/1.45 system-ui, sans-serif; margin: 24px; color: #222; background: #fff; max-width: 1500px; }
h1 { font-size: 22px; margin: 0 0 4px; } h2 { font-size: 18px; margin: 28px 0 8px; border-bottom: 1px solid #ddd; }
h3 { font-size: 15px; margin: 18px 0 6px; } .meta { color: #555; margin: 0 0 12px; }
.verdict p { background: #f4f7fb; border-left: 4px solid #4a78c2; padding: 8px 12px; margin: 8px 0; max-width: 1100px; }
table { border-collapse: collapse; margin: 6px 0; font-size: 14px; }
th, td { border: 1px solid #ddd; padding: 3px 8px; text-align: right; } th { background: #f2f2f2; }
td { white-space: nowrap; } td.l, th.l { text-align: left; white-space: normal; }
td.better { color: #1a6b2a; font-weight: 600; } td.worse { color: #b3261e; font-weight: 600; }
.row { display: flex; flex-wrap: wrap; gap: 10px; margin: 4px 0 10px; }
figure { margin: 0; } figcaption { font-size: 13px; color: #333; max-width: 340px; }
figure img { display: block; image-rendering: pixelated; border: 1px solid #ccc; }
img.plot { max-width: 100%; height: auto; }
.bar { display: flex; align-items: center; gap: 6px; font-size: 12px; color: #444; margin-top: 2px; }
.bar span.g { display: inline-block; width: 140px; height: 10px; border: 1px solid #999; }
.sw { display: inline-block; width: 12px; height: 12px; border: 1px solid #777; vertical-align: middle;
      margin: 0 3px 0 8px; }
.note { color: #555; font-size: 13px; max-width: 1100px; }
"""


def png_data_uri(image: np.ndarray) -> str:
    """An HWC uint8 RGB image as a ``data:image/png;base64,...`` URI."""
    ok, encoded = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError("png_data_uri: OpenCV could not encode the image as PNG")
    return "data:image/png;base64," + base64.b64encode(encoded.tobytes()).decode("ascii")


def img(image: np.ndarray, alt: str, cls: str = "", zoom: int = 1) -> str:
    """An ``<img>`` with ``image`` inlined, shown at ``zoom`` times its pixel size, with ``alt``
    text and class."""
    h, w = image.shape[:2]
    klass = f' class="{esc(cls)}"' if cls else ""
    return f'<img{klass} src="{png_data_uri(image)}" width="{w * zoom}" height="{h * zoom}" alt="{esc(alt)}">'


def _gradient(cmap: str, stops: int = 11) -> str:
    rgb = colormaps[cmap](np.linspace(0, 1, stops), bytes=True)[:, :3]
    return "linear-gradient(to right, " + ", ".join(f"rgb({r},{g},{b})" for r, g, b in rgb) + ")"


def colour_bar(cmap: str, low: str, high: str, note: str = "") -> str:
    """A small legend: ``low`` | the colour map ``cmap`` as a gradient | ``high``, then ``note``."""
    extra = f"<span>{esc(note)}</span>" if note else ""
    return (f'<div class="bar"><span>{esc(low)}</span><span class="g" style="background: {_gradient(cmap)}"></span>'
            f"<span>{esc(high)}</span>{extra}</div>")  # fmt: skip


def swatches(items: Sequence[tuple[tuple[int, int, int], str]]) -> str:
    """A legend of colour swatches: (RGB, label) each."""
    parts = [f'<span class="sw" style="background: rgb{tuple(int(c) for c in rgb)}"></span>{esc(label)}'
             for rgb, label in items]  # fmt: skip
    return '<div class="bar">' + "".join(parts) + "</div>"


def table(header: Sequence[str], rows: Sequence[Sequence[tuple[str, str]]], left: Sequence[int] = (0,)) -> str:
    """An HTML table: ``header`` texts; each row's cells as (text, css class); the columns
    ``left`` left-aligned (the others right-aligned)."""
    head = "".join(f'<th class="{"l" if i in left else ""}">{esc(h)}</th>' for i, h in enumerate(header))
    body = []
    for row in rows:
        cells = []
        for i, (text, cls) in enumerate(row):
            classes = " ".join(c for c in (cls, "l" if i in left else "") if c)
            cells.append(f'<td class="{classes}">{esc(text)}</td>' if classes else f"<td>{esc(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def page(title: str, body: str) -> str:
    """A complete HTML document: ``title`` and the ``body`` markup, with the reports' style."""
    return (f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>'
            f"<style>{_CSS}</style></head>\n<body>\n{body}\n</body></html>\n")  # fmt: skip
