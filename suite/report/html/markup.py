"""Small HTML builders: escaped text, tables from (headers, rows), inline markdown, embedded PNGs."""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

esc = html.escape


def inline_md(text: str) -> str:
    """Escaped text with the summaries' inline markdown: `code` and **bold**; blank lines start paragraphs."""
    out = esc(text)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", out)
    return "".join(f"<p>{p.strip()}</p>" for p in re.split(r"\n\s*\n", out) if p.strip())


def _is_number(cell: Any) -> bool:
    if isinstance(cell, bool):
        return False
    if isinstance(cell, (int, float)):
        return True
    return bool(re.fullmatch(r"-?[\d.]+(e[-+]?\d+)?( \[.*\])?|n/a|-|", str(cell)))


_SUCCESS = re.compile(r"(\S+) \((\d+%) (\[[^\]]*\])\)")
_MEDIAN_IQR = re.compile(r"(\S+) (\[[^\]]*\])")


def _stacked(cell: str) -> str:
    """"74/100 (74% [65, 82])" or "0.3 [0.1, 0.8]": the value, its interval in small type below it."""
    m = _SUCCESS.fullmatch(cell)
    if m:
        return f'{esc(m[1])} ({esc(m[2])})<span class="cell-q">{esc(m[3])}</span>'
    m = _MEDIAN_IQR.fullmatch(cell)
    if m:
        return f'{esc(m[1])}<span class="cell-q">{esc(m[2])}</span>'
    return esc(cell)


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]], *, cls: str = "", caption: str = "",
          stacked: bool = False) -> str:
    """A <table>: every cell escaped; numeric columns right-aligned; the first column as row headers.

    `stacked`: a cell "value [low, high]" shows its interval in small type under the value (narrower)."""
    numeric = [all(_is_number(r[i]) for r in rows) if rows else False for i in range(len(headers))]
    head = "".join(f'<th{" class=num" if numeric[i] else ""}>{esc(str(h))}</th>' for i, h in enumerate(headers))
    body = []
    for row in rows:
        cells = []
        for i, c in enumerate(row):
            tag = "th" if i == 0 else "td"
            text = _stacked(str(c)) if stacked else esc(str(c))
            cells.append(f'<{tag}{" class=num" if numeric[i] else ""}>{text}</{tag}>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    return (f'<div class="tablewrap"><table class="{esc(cls)}">{cap}<thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>')


def png_img(path: Path, *, alt: str) -> str:
    """The PNG inlined as a data URI (the page needs no file beside it)."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{esc(alt)}">'
