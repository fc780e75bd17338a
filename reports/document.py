"""The PDF document every report is built on (reportlab platypus).

* Fonts: DejaVu Sans (full Latin coverage: Núñez, Gómez, ‰, ±, °, ≤), embedded as subsets.
  The TTFs are the ones matplotlib ships (``mpl-data/fonts/ttf``), so a fresh machine needs no
  font package; matplotlib draws the plots with the same face.
* Every page: the clinic's name (and logo) and the report's title at the top; at the bottom the
  generation time (from an injected clock), the product version and "page N of M" (a canvas
  that holds the pages until the total is known).
* Reproducible: reportlab's invariant mode plus the PDF creation date set to the generation
  time, so the same inputs and the same clock give the same bytes.
* Nothing is lost: the PDF is written to a temporary file next to the output and renamed; an
  existing output is refused unless ``force``.
"""
from __future__ import annotations

import io
import math
import os
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import matplotlib
from reportlab.lib import colors
from reportlab.lib.enums import TA_CENTER
from reportlab.lib.pagesizes import A4, LETTER
from reportlab.lib.styles import ParagraphStyle
from reportlab.lib.units import mm
from reportlab.pdfbase import pdfmetrics
from reportlab.pdfbase.ttfonts import TTFont
from reportlab.pdfgen import canvas as rl_canvas
from reportlab.platypus import (
    BaseDocTemplate,
    Flowable,
    Frame,
    Image,
    PageTemplate,
    Paragraph,
    Table,
    TableStyle,
)

from reports.settings import PageSize, ReportSettings
from rt.errors import InputError

matplotlib.use("Agg")

FONT = "DejaVuSans"
FONT_BOLD = "DejaVuSans-Bold"
FONT_ITALIC = "DejaVuSans-Oblique"
_FONT_FILES = {FONT: "DejaVuSans.ttf", FONT_BOLD: "DejaVuSans-Bold.ttf",
               FONT_ITALIC: "DejaVuSans-Oblique.ttf",
               "DejaVuSans-BoldOblique": "DejaVuSans-BoldOblique.ttf"}
#: Plots are embedded as PNG at this resolution (dots per inch).
PLOT_DPI = 200
MARGIN = 16 * mm
HEADER_H = 20 * mm
FOOTER_H = 10 * mm

#: Colours with meaning (the GUI's: green running/pass, amber warning, red stop/fail).
GREEN = colors.HexColor("#1b7f3b")
AMBER = colors.HexColor("#b36b00")
RED = colors.HexColor("#b3261e")
GREY = colors.HexColor("#5f6368")
LIGHT = colors.HexColor("#eef1f4")

Clock = Callable[[], datetime]


def utc_now() -> datetime:
    """The default clock: now, in UTC."""
    return datetime.now(UTC)


class ReportError(InputError):
    """A report cannot be written (existing output, unwritable folder ...)."""


def register_fonts() -> None:
    """Register DejaVu Sans (regular, bold, oblique) with reportlab, once."""
    if FONT in pdfmetrics.getRegisteredFontNames():
        return
    folder = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    for name, file in _FONT_FILES.items():
        pdfmetrics.registerFont(TTFont(name, str(folder / file)))
    pdfmetrics.registerFontFamily(FONT, normal=FONT, bold=FONT_BOLD, italic=FONT_ITALIC,
                                  boldItalic="DejaVuSans-BoldOblique")


def _style(name: str, size: float, font: str = FONT, leading: float | None = None,
           **kw: Any) -> ParagraphStyle:
    return ParagraphStyle(name, fontName=font, fontSize=size, bulletFontName=font,
                          leading=leading or size * 1.25, **kw)


class Styles:
    """The paragraph styles of every report (sizes in points)."""

    def __init__(self) -> None:
        register_fonts()
        self.title = _style("title", 16, FONT_BOLD, spaceAfter=2 * mm)
        self.h1 = _style("h1", 12.5, FONT_BOLD, spaceBefore=4 * mm, spaceAfter=1.5 * mm)
        self.h2 = _style("h2", 10.5, FONT_BOLD, spaceBefore=2.5 * mm, spaceAfter=1 * mm)
        self.body = _style("body", 9.5)
        self.small = _style("small", 8, textColor=GREY)
        self.cell = _style("cell", 8.5)
        self.cell_bold = _style("cell_bold", 8.5, FONT_BOLD)
        self.note = _style("note", 9, textColor=AMBER, leftIndent=3 * mm)
        self.banner = _style("banner", 15, FONT_BOLD, alignment=TA_CENTER,
                             textColor=colors.white, leading=20)


def p(text: str, style: ParagraphStyle) -> Paragraph:
    """A paragraph of plain text (escaped: names with < or & print as written)."""
    return Paragraph(escape(text), style)


def pm(markup: str, style: ParagraphStyle) -> Paragraph:
    """A paragraph of reportlab markup (``<b>``, ``<font color=...>``); escape data yourself."""
    return Paragraph(markup, style)


@dataclass(frozen=True)
class ReportContext:
    """What every page shows besides its content."""

    title: str
    settings: ReportSettings
    generated_at: datetime
    software_version: str
    #: Right side of the header (e.g. the patient's code or the certificate's id).
    subject: str = ""
    extra_footer: str = ""

    @property
    def pagesize(self) -> tuple[float, float]:
        return LETTER if self.settings.page_size == PageSize.LETTER else A4

    @property
    def generated_text(self) -> str:
        return format_time(self.generated_at)


def format_time(t: datetime) -> str:
    """``2026-11-23 17:00 UTC``: one unambiguous form in every report."""
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return t.astimezone(UTC).strftime("%Y-%m-%d %H:%M UTC")


def _numbered_canvas(ctx: ReportContext) -> type[rl_canvas.Canvas]:
    """A canvas class that draws header and footer once the page count is known."""
    stamp = ctx.generated_at.astimezone(UTC).strftime("D:%Y%m%d%H%M%S+00'00'")

    class NumberedCanvas(rl_canvas.Canvas):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            kwargs["invariant"] = 1
            # Without this the canvas declares Helvetica, a font a PDF does not embed.
            kwargs["initialFontName"] = FONT
            super().__init__(*args, **kwargs)
            self.setDateFormatter(lambda *_: stamp)
            self.setAuthor(ctx.settings.clinic_name)
            self.setTitle(ctx.title)
            self.setCreator(f"talus {ctx.software_version}")
            self._saved: list[dict[str, Any]] = []

        def showPage(self) -> None:
            self._saved.append(dict(self.__dict__))
            self._startPage()

        def save(self) -> None:
            total = len(self._saved)
            for state in self._saved:
                self.__dict__.update(state)
                _draw_frame(self, ctx, self.getPageNumber(), total)
                super().showPage()
            super().save()

    return NumberedCanvas


def _draw_frame(c: rl_canvas.Canvas, ctx: ReportContext, page: int, total: int) -> None:
    w, h = ctx.pagesize
    s = ctx.settings
    c.saveState()
    top = h - MARGIN
    x = MARGIN
    if s.logo_path is not None:
        logo_h = 12 * mm
        c.drawImage(str(s.logo_path), x, top - logo_h, width=30 * mm, height=logo_h,
                    preserveAspectRatio=True, anchor="w", mask="auto")
        x += 33 * mm
    c.setFont(FONT_BOLD, 11)
    c.drawString(x, top - 4.5 * mm, s.clinic_name)
    c.setFont(FONT, 7.5)
    c.setFillColor(GREY)
    for i, line in enumerate(s.clinic_address.splitlines()[:2]):
        c.drawString(x, top - 8.5 * mm - i * 3.3 * mm, line)
    c.setFillColor(colors.black)
    c.setFont(FONT_BOLD, 10)
    c.drawRightString(w - MARGIN, top - 4.5 * mm, ctx.title)
    if ctx.subject:
        c.setFont(FONT, 9)
        c.drawRightString(w - MARGIN, top - 9 * mm, ctx.subject)
    c.setStrokeColor(GREY)
    c.setLineWidth(0.5)
    c.line(MARGIN, top - HEADER_H + 4 * mm, w - MARGIN, top - HEADER_H + 4 * mm)
    c.line(MARGIN, MARGIN + FOOTER_H - 3 * mm, w - MARGIN, MARGIN + FOOTER_H - 3 * mm)
    c.setFont(FONT, 7.5)
    c.setFillColor(GREY)
    left = f"Generated {ctx.generated_text} · talus {ctx.software_version}"
    if ctx.extra_footer:
        left += f" · {ctx.extra_footer}"
    c.drawString(MARGIN, MARGIN + 2 * mm, left)
    c.drawRightString(w - MARGIN, MARGIN + 2 * mm, f"page {page} of {total}")
    c.restoreState()


def frame_width(ctx: ReportContext) -> float:
    """Usable width of the page body (points)."""
    return ctx.pagesize[0] - 2 * MARGIN


def write_pdf(out: str | os.PathLike[str], story: Sequence[Flowable], ctx: ReportContext,
              force: bool = False) -> int:
    """Render ``story`` to ``out``; returns the page count.

    Refuses an existing ``out`` unless ``force``; writes a temporary file in the same folder
    and renames it, so a failed render leaves nothing behind and never a half file.
    """
    out_path = Path(out)
    if out_path.exists() and not force:
        raise ReportError(f"{out_path}: already exists (use --force to replace it)")
    if not out_path.parent.is_dir():
        raise ReportError(f"{out_path}: folder {out_path.parent} does not exist")
    register_fonts()
    w, h = ctx.pagesize
    frame = Frame(MARGIN, MARGIN + FOOTER_H, w - 2 * MARGIN, h - 2 * MARGIN - FOOTER_H - HEADER_H,
                  leftPadding=0, rightPadding=0, topPadding=0, bottomPadding=0, id="body")
    fd, tmp = tempfile.mkstemp(prefix=f".{out_path.name}.", suffix=".tmp", dir=out_path.parent)
    os.close(fd)
    try:
        doc = BaseDocTemplate(tmp, pagesize=ctx.pagesize, title=ctx.title,
                              author=ctx.settings.clinic_name, creator="talus",
                              subject=ctx.subject, invariant=1,
                              pageTemplates=[PageTemplate("page", [frame])])
        doc.build(list(story), canvasmaker=_numbered_canvas(ctx))
        pages = int(doc.page)
        if force:
            os.replace(tmp, out_path)
        else:
            os.link(tmp, out_path)         # fails if ``out`` appeared during the render
    except FileExistsError:
        raise ReportError(f"{out_path}: appeared while the report was rendered; left as it "
                          "is (use --force to replace it)") from None
    except OSError as exc:
        raise ReportError(f"{out_path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return pages


# ------------------------------------------------------------------------------ flowables

def figure_image(fig: Any, width: float) -> Image:
    """A matplotlib figure as a PNG flowable ``width`` points wide (aspect kept)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    # No "Software" key: the PNG bytes then depend only on the figure (reproducible reports).
    fig.savefig(buf, format="png", dpi=PLOT_DPI, metadata={"Software": None})
    w_in, h_in = fig.get_size_inches()
    plt.close(fig)
    buf.seek(0)
    return Image(buf, width=width, height=width * h_in / w_in)


@dataclass
class TableSpec:
    """A table: header row, body rows (strings or flowables), column widths (fractions)."""

    header: list[str]
    rows: list[list[Any]]
    widths: list[float] | None = None
    #: (row index in body, colour) pairs for a text colour per row.
    row_colours: list[tuple[int, Any]] = field(default_factory=list)


def table(spec: TableSpec, styles: Styles, width: float) -> Table:
    """A report table: bold header on a light band, thin rules, text wrapping in cells."""
    def cell(v: Any, bold: bool = False) -> Any:
        if isinstance(v, Flowable):
            return v
        return p(str(v), styles.cell_bold if bold else styles.cell)

    data = [[cell(h, True) for h in spec.header]] + [[cell(v) for v in r] for r in spec.rows]
    widths = None if spec.widths is None else [f * width for f in spec.widths]
    t = Table(data, colWidths=widths, repeatRows=1, hAlign="LEFT")
    style = [("FONTNAME", (0, 0), (-1, -1), FONT),
             ("BACKGROUND", (0, 0), (-1, 0), LIGHT),
             ("LINEBELOW", (0, 0), (-1, 0), 0.6, GREY),
             ("LINEBELOW", (0, 1), (-1, -1), 0.25, colors.HexColor("#d0d4d8")),
             ("VALIGN", (0, 0), (-1, -1), "TOP"),
             ("TOPPADDING", (0, 0), (-1, -1), 1.5),
             ("BOTTOMPADDING", (0, 0), (-1, -1), 1.5),
             ("LEFTPADDING", (0, 0), (-1, -1), 2.5),
             ("RIGHTPADDING", (0, 0), (-1, -1), 2.5)]
    t.setStyle(TableStyle(style))
    return t


def key_values(pairs: Sequence[tuple[str, str]], styles: Styles, width: float,
               key_fraction: float = 0.32) -> Table:
    """Two columns, label and value, no header (identity blocks)."""
    data = [[p(k, styles.cell_bold), p(v, styles.cell)] for k, v in pairs]
    t = Table(data, colWidths=[key_fraction * width, (1 - key_fraction) * width],
              hAlign="LEFT")
    t.setStyle(TableStyle([("FONTNAME", (0, 0), (-1, -1), FONT),
                           ("VALIGN", (0, 0), (-1, -1), "TOP"),
                           ("TOPPADDING", (0, 0), (-1, -1), 1),
                           ("BOTTOMPADDING", (0, 0), (-1, -1), 1),
                           ("LINEBELOW", (0, 0), (-1, -1), 0.25, colors.HexColor("#e0e3e6"))]))
    return t


def banner(text: str, colour: Any, styles: Styles, width: float) -> Table:
    """A coloured band with one message in large white letters (verdicts, outcomes)."""
    t = Table([[p(text, styles.banner)]], colWidths=[width], hAlign="LEFT")
    t.setStyle(TableStyle([("FONTNAME", (0, 0), (-1, -1), FONT),
                           ("BACKGROUND", (0, 0), (-1, -1), colour),
                           ("TOPPADDING", (0, 0), (-1, -1), 4),
                           ("BOTTOMPADDING", (0, 0), (-1, -1), 6)]))
    return t


def fmt(value: Any, digits: int = 1, unit: str = "", missing: str = "—") -> str:
    """A number for a report: fixed decimals, the unit after a thin space; ``missing`` for
    None/NaN. The same function formats the text layer everywhere (tests look for it)."""
    if value is None:
        return missing
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(x):
        return missing
    s = f"{x:.{digits}f}"
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return f"{s} {unit}" if unit else s
