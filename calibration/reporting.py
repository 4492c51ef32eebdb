"""Self-contained HTML reports for every warpdem job (calibration, experiment, diagnosis, pump).

A report reads top-down: the **verdict** first (met / not met, with its numbers), then
sections of paragraphs, tables and figures, then **what to do next**.  The output is a
single HTML file: figures are embedded as base64 PNG data URIs, the style sheet is inline,
nothing is fetched from elsewhere, so the file can be mailed or archived as is.

Plain data in, one string out::

    report = Report(
        title="Calibration of gravel",
        verdict=Verdict(met=True, headline="Both targets matched within 1 deg",
                        numbers=[("static angle error", "0.4 deg")]),
        sections=[Section("Comparison", [Table(["observable", "measured", "simulated"],
                                                [["static angle (deg)", 34.1, 33.7]])])],
        next_steps=["Validate on the hollow cylinder."],
    )
    report.write("results/report.html")
"""

from __future__ import annotations

import base64
import html
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence, Union

__all__ = ["Cell", "Table", "Figure", "Section", "Verdict", "Report", "format_value"]

_TONES = ("good", "bad", "warn", "")


def format_value(value: Any, digits: int = 3) -> str:
    """Text of one table cell: floats with ``digits`` significant digits, None/NaN as an en dash."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float) or (hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0):
        v = float(value)
        if math.isnan(v):
            return "–"
        if math.isinf(v):
            return "∞" if v > 0 else "−∞"
        if v == 0.0:
            return "0"
        if 1e-3 <= abs(v) < 1e5:
            decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(v)))))
            return f"{v:.{decimals}f}"
        return f"{v:.{digits - 1}e}"
    return str(value)


@dataclass(frozen=True)
class Cell:
    """A table cell with a tone: ``"good"`` (green), ``"bad"`` (red), ``"warn"`` (amber) or ``""``."""

    value: Any
    tone: str = ""

    def __post_init__(self) -> None:
        if self.tone not in _TONES:
            raise ValueError(f"Cell tone must be one of {_TONES}, got {self.tone!r}")


@dataclass(frozen=True)
class Table:
    """A table: ``columns`` (header texts) and ``rows`` (values or :class:`Cell`), with a caption."""

    columns: Sequence[str]
    rows: Sequence[Sequence[Any]]
    caption: str = ""

    def __post_init__(self) -> None:
        if len(self.columns) == 0:
            raise ValueError("Table needs at least one column")
        for i, row in enumerate(self.rows):
            if len(row) != len(self.columns):
                raise ValueError(
                    f"Table row {i} has {len(row)} cells but the table has {len(self.columns)} columns "
                    f"({', '.join(map(str, self.columns))})"
                )


@dataclass(frozen=True)
class Figure:
    """A PNG image embedded in the report, with a caption written for the reader."""

    png: bytes
    caption: str = ""
    alt: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.png, (bytes, bytearray)) or not bytes(self.png[:8]) == b"\x89PNG\r\n\x1a\n":
            raise ValueError("Figure.png must be the bytes of a PNG file (signature \\x89PNG missing)")

    @classmethod
    def from_path(cls, path: str | os.PathLike, caption: str = "", alt: str = "") -> "Figure":
        """Read a PNG file."""
        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"figure file not found: {p}")
        return cls(p.read_bytes(), caption, alt or p.stem)

    @classmethod
    def from_matplotlib(cls, fig: Any, caption: str = "", alt: str = "", dpi: int = 110) -> "Figure":
        """Render a matplotlib Figure to PNG bytes."""
        import io

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        return cls(buf.getvalue(), caption, alt)

    def data_uri(self) -> str:
        return "data:image/png;base64," + base64.b64encode(bytes(self.png)).decode("ascii")


Block = Union[str, Table, Figure]


@dataclass(frozen=True)
class Section:
    """A titled section: ``blocks`` in reading order; a ``str`` block is one paragraph."""

    title: str
    blocks: Sequence[Block] = ()

    def __post_init__(self) -> None:
        if not str(self.title).strip():
            raise ValueError("Section title must not be empty")
        for b in self.blocks:
            if not isinstance(b, (str, Table, Figure)):
                raise TypeError(f"Section {self.title!r}: blocks must be str, Table or Figure, got {type(b).__name__}")


@dataclass(frozen=True)
class Verdict:
    """The answer the reader came for: ``met`` True / False / None (no target), a headline,
    optional detail sentences and ``numbers`` as (label, value text) pairs.

    ``caveats`` are the reasons the basis of the answer is weak (a surrogate that predicts poorly,
    a validation beyond its criterion, data that cannot tell): a verdict with caveats is never
    green, it turns amber unless it is already red, and they are listed first, marked, under the
    headline (a detail equal to a caveat is not listed twice). ``status`` replaces the label above
    the headline ("Met", "Not met", "Met on a weak basis", ...)."""

    met: bool | None
    headline: str
    details: Sequence[str] = ()
    numbers: Sequence[tuple[str, Any]] = ()
    caveats: Sequence[str] = ()
    status: str = ""

    def __post_init__(self) -> None:
        if self.met not in (True, False, None):
            raise ValueError(f"Verdict.met must be True, False or None, got {self.met!r}")
        if not str(self.headline).strip():
            raise ValueError("Verdict headline must not be empty")
        if isinstance(self.caveats, str):
            raise TypeError("Verdict.caveats must be a sequence of sentences, not one string")

    @property
    def tone(self) -> str:
        """``"met"`` (green), ``"weak"`` (amber: met or no target, with caveats), ``"notmet"`` (red) or
        ``""`` (neutral: no target, no caveats)."""
        if self.met is False:
            return "notmet"
        if self.caveats:
            return "weak"
        return "met" if self.met else ""

    @property
    def status_text(self) -> str:
        """The label above the headline."""
        if self.status:
            return self.status
        return {"met": "Met", "notmet": "Not met", "weak": "Met on a weak basis" if self.met else "Weak basis",
                "": "Result"}[self.tone]


_CSS = """
:root { --ink:#1d2330; --muted:#5b6475; --line:#d9dee7; --bg:#ffffff; --soft:#f5f7fa;
        --good:#1a7f37; --good-bg:#e7f5ea; --bad:#b42318; --bad-bg:#fdecea; --warn:#9a6700; --warn-bg:#fff4d6; }
* { box-sizing: border-box; }
body { margin:0; background:var(--soft); color:var(--ink);
       font:15px/1.5 -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
main { max-width: 1080px; margin: 0 auto; padding: 28px 32px 48px; background: var(--bg); min-height: 100vh; }
h1 { font-size: 26px; margin: 0 0 4px; }
.subtitle { color: var(--muted); margin: 0 0 20px; }
h2 { font-size: 19px; margin: 34px 0 10px; padding-bottom: 4px; border-bottom: 2px solid var(--line); }
.verdict { border-radius: 8px; padding: 16px 20px; margin: 8px 0 18px; border-left: 8px solid var(--muted); background: var(--soft); }
.verdict.met { border-color: var(--good); background: var(--good-bg); }
.verdict.notmet { border-color: var(--bad); background: var(--bad-bg); }
.verdict .status { font-weight: 700; letter-spacing: .04em; text-transform: uppercase; font-size: 13px; }
.verdict.weak { border-color: var(--warn); background: var(--warn-bg); }
.verdict.met .status { color: var(--good); } .verdict.notmet .status { color: var(--bad); }
.verdict.weak .status { color: var(--warn); }
.verdict li.caveat::marker { color: var(--warn); } .verdict .caveat-label { font-weight: 600; color: var(--warn); }
.verdict .headline { font-size: 20px; font-weight: 600; margin: 4px 0 8px; }
.verdict ul { margin: 6px 0 8px 18px; padding: 0; }
.numbers { display: flex; flex-wrap: wrap; gap: 10px; margin-top: 10px; }
.number { background: #fff; border: 1px solid var(--line); border-radius: 6px; padding: 6px 12px; }
.number .label { color: var(--muted); font-size: 12px; } .number .value { font-size: 17px; font-weight: 600; }
table { border-collapse: collapse; margin: 10px 0 4px; font-size: 14px; width: 100%; }
th, td { border: 1px solid var(--line); padding: 5px 9px; text-align: left; vertical-align: top; }
th { background: var(--soft); font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.good { background: var(--good-bg); color: var(--good); } td.bad { background: var(--bad-bg); color: var(--bad); }
td.warn { background: var(--warn-bg); color: var(--warn); }
caption { caption-side: top; text-align: left; color: var(--muted); padding: 2px 0 6px; }
figure { margin: 14px 0 20px; } figure img { max-width: 100%; height: auto; border: 1px solid var(--line); border-radius: 4px; }
figcaption { color: var(--muted); font-size: 13px; margin-top: 4px; }
ol.next { background: var(--soft); border: 1px solid var(--line); border-radius: 8px; padding: 12px 12px 12px 36px; }
ol.next li { margin: 4px 0; }
footer { margin-top: 36px; color: var(--muted); font-size: 12px; }
"""


def _esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


def _is_number(v: Any) -> bool:
    if isinstance(v, bool):
        return False
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return not isinstance(v, str)


@dataclass(frozen=True)
class Report:
    """A whole report; :meth:`to_html` renders it, :meth:`write` saves it."""

    title: str
    verdict: Verdict
    sections: Sequence[Section] = ()
    next_steps: Sequence[str] = ()
    subtitle: str = ""
    footer: str = ""

    def __post_init__(self) -> None:
        if not str(self.title).strip():
            raise ValueError("Report title must not be empty")
        if not isinstance(self.verdict, Verdict):
            raise TypeError(f"Report.verdict must be a Verdict, got {type(self.verdict).__name__}")
        for s in self.sections:
            if not isinstance(s, Section):
                raise TypeError(f"Report.sections must hold Section objects, got {type(s).__name__}")

    # ------------------------------------------------------------------ rendering
    def _verdict_html(self) -> str:
        v = self.verdict
        out = [f'<section class="verdict {v.tone}" id="verdict">', f'<div class="status">{_esc(v.status_text)}</div>',
               f'<div class="headline">{_esc(v.headline)}</div>']
        caveats = list(dict.fromkeys(v.caveats))
        items = [f'<li class="caveat"><span class="caveat-label">Weak basis:</span> {_esc(c)}</li>' for c in caveats]
        items += [f"<li>{_esc(d)}</li>" for d in v.details if d not in caveats]
        if items:
            out.append("<ul>" + "".join(items) + "</ul>")
        if v.numbers:
            out.append('<div class="numbers">')
            for label, value in v.numbers:
                out.append(f'<div class="number"><div class="label">{_esc(label)}</div>'
                           f'<div class="value">{_esc(format_value(value))}</div></div>')
            out.append("</div>")
        out.append("</section>")
        return "\n".join(out)

    @staticmethod
    def _table_html(t: Table) -> str:
        out = ["<table>"]
        if t.caption:
            out.append(f"<caption>{_esc(t.caption)}</caption>")
        out.append("<thead><tr>" + "".join(f"<th>{_esc(c)}</th>" for c in t.columns) + "</tr></thead><tbody>")
        for row in t.rows:
            cells = []
            for c in row:
                tone, value = (c.tone, c.value) if isinstance(c, Cell) else ("", c)
                classes = " ".join(x for x in (("num" if _is_number(value) else ""), tone) if x)
                attr = f' class="{classes}"' if classes else ""
                cells.append(f"<td{attr}>{_esc(format_value(value))}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</tbody></table>")
        return "\n".join(out)

    @staticmethod
    def _figure_html(f: Figure) -> str:
        cap = f"<figcaption>{_esc(f.caption)}</figcaption>" if f.caption else ""
        return f'<figure><img src="{f.data_uri()}" alt="{_esc(f.alt or f.caption)}">{cap}</figure>'

    def to_html(self) -> str:
        """The whole report as one self-contained HTML document."""
        parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
                 '<meta name="viewport" content="width=device-width, initial-scale=1">',
                 f"<title>{_esc(self.title)}</title>", f"<style>{_CSS}</style></head><body><main>",
                 f"<h1>{_esc(self.title)}</h1>"]
        if self.subtitle:
            parts.append(f'<p class="subtitle">{_esc(self.subtitle)}</p>')
        parts.append(self._verdict_html())
        for s in self.sections:
            parts.append(f"<section><h2>{_esc(s.title)}</h2>")
            for b in s.blocks:
                if isinstance(b, Table):
                    parts.append(self._table_html(b))
                elif isinstance(b, Figure):
                    parts.append(self._figure_html(b))
                else:
                    parts.append(f"<p>{_esc(b)}</p>")
            parts.append("</section>")
        if self.next_steps:
            parts.append('<section id="next"><h2>What to do next</h2><ol class="next">'
                         + "".join(f"<li>{_esc(s)}</li>" for s in self.next_steps) + "</ol></section>")
        if self.footer:
            parts.append(f"<footer>{_esc(self.footer)}</footer>")
        parts.append("</main></body></html>")
        return "\n".join(parts)

    def write(self, path: str | os.PathLike) -> Path:
        """Write the HTML file (parent folders are created); returns its path."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        from warpdem.config_io import write_atomic

        write_atomic(p, self.to_html())
        return p
