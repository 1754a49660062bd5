"""The PDF of a report, laid out by Typst (the `typst` wheel: no system libraries) as PDF/A-3a.

One content, two layouts: the report's HTML (the Jinja template formats the document object,
`report.build.Report` or the fleet report) is read here into a tree of plain data and handed to
Typst as JSON through ``sys.inputs``; `templates/report.typ` lays it out (running header, page
X of Y, contents, numbered tables whose header rows repeat, figures, the watermarks on every
page). Every string of the report, the operator's included, reaches Typst as a JSON string and
is placed as text, never read as markup. The machine-readable files (the report's JSON, the
trial CSV, the plan) are attached to the PDF as PDF/A-3 associated files.
"""

import base64
import json
import re
from dataclasses import dataclass, field
from datetime import datetime
from html.parser import HTMLParser
from importlib.resources import files
from importlib.util import find_spec
from pathlib import Path
from typing import Final

from gyrostand.report.errors import ReportError

PDF_STANDARD: Final = "a-3a"  # ISO 19005-3, level A: tagged (Typst writes the structure tree)
TEMPLATE = files("gyrostand.report") / "templates" / "report.typ"
LONG_RUN = re.compile(r"\S{24,}")
"""A run of characters with no break opportunity: a hash, a path, or hostile text."""
CHUNK = 12
LINE = 120  # characters: the longest line of the header and the footer
ZWSP = "\u200b"  # a break opportunity that prints nothing
VOID = frozenset({"br", "img", "col", "meta", "link", "hr", "input"})
SKIPPED = frozenset({"head", "style", "script", "title"})
BLOCKS = frozenset(
    {"html", "body", "section", "header", "nav", "table", "thead", "tbody", "tr", "ul", "ol"}
    | {"figure", "colgroup"}
)
"""Elements whose whitespace-only text between children is layout, not content."""
INLINE = frozenset({"b", "strong", "i", "em", "span", "a", "sub", "sup"})
Json = dict[str, object]


def breakable(text: str) -> str:
    """`text` with a zero-width break opportunity every `CHUNK` characters of each long unbroken
    run: Typst lets an unbreakable word overflow its column; a 100 kB name wraps instead."""
    return LONG_RUN.sub(
        lambda m: ZWSP.join(m[0][i : i + CHUNK] for i in range(0, len(m[0]), CHUNK)), text
    )


@dataclass
class Element:
    """One element of the parsed HTML: its tag, class list, the attributes the layout uses
    (``id``, ``rowspan``, ``colspan``, ``target`` of a contents entry, ``svg`` of a figure,
    ``w``: a column's width in %) and its children (text as strings)."""

    tag: str
    cls: str = ""
    attrs: Json = field(default_factory=dict)
    kids: list["Element | str"] = field(default_factory=list)

    def has(self, cls: str) -> bool:
        return cls in self.cls.split()

    def elements(self, tag: str | None = None) -> list["Element"]:
        """The child elements (of one tag)."""
        return [k for k in self.kids if isinstance(k, Element) and tag in (None, k.tag)]

    def find(self, cls: str) -> "Element | None":
        """The first element below this one whose class list holds `cls`."""
        for kid in self.elements():
            found = kid if kid.has(cls) else kid.find(cls)
            if found is not None:
                return found
        return None

    def text(self) -> str:
        """The element's text, a <br> as a newline."""
        if self.tag == "br":
            return "\n"
        return "".join(k if isinstance(k, str) else k.text() for k in self.kids)


class _Tree(HTMLParser):
    """HTML -> a tree of `Element`s; the <title> text aside."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.root = Element("root")
        self.stack = [self.root]
        self.title = ""
        self.skipping = 0
        self.in_title = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag in SKIPPED:
            self.skipping += tag not in VOID
            self.in_title = tag == "title"
            return
        if self.skipping:
            return
        a = {k: v or "" for k, v in attrs}
        node = Element(tag, a.get("class", ""))
        if "id" in a:
            node.attrs["id"] = a["id"]
        for span in ("rowspan", "colspan"):
            if span in a:
                node.attrs[span] = int(a[span])
        if tag == "a" and a.get("href", "").startswith("#") and self.within("nav"):
            node.attrs["target"] = a["href"][1:]  # a contents entry: its page comes from layout
        if tag == "img":
            node.attrs["svg"] = _svg(a.get("src", ""))
        if tag == "col":
            width = re.search(r"width:\s*([\d.]+)%", a.get("style", ""))
            node.attrs["w"] = float(width[1]) if width else None
        self.stack[-1].kids.append(node)
        if tag not in VOID:
            self.stack.append(node)

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.handle_starttag(tag, attrs)
        if tag not in VOID and not (self.skipping or tag in SKIPPED):
            self.stack.pop()

    def handle_endtag(self, tag: str) -> None:
        if tag in SKIPPED:
            self.skipping -= tag not in VOID
            self.in_title = False
            return
        tags = [n.tag for n in self.stack]
        if not self.skipping and tag in tags[1:]:  # close it and whatever it left open
            del self.stack[len(tags) - 1 - tags[::-1].index(tag) :]

    def handle_data(self, data: str) -> None:
        if self.in_title:
            self.title += data
        if self.skipping:
            return
        parent = self.stack[-1]
        if not self.within("pre"):
            data = re.sub(r"\s+", " ", data)
            if data == " " and parent.tag in BLOCKS:
                return
        if parent.kids and isinstance(parent.kids[-1], str):
            parent.kids[-1] += data
        else:
            parent.kids.append(data)

    def within(self, tag: str) -> bool:
        return any(n.tag == tag for n in self.stack)


def _svg(src: str) -> str:
    """The SVG text of a figure's data URI (the report's figures are all inline SVG)."""
    head, _, data = src.partition(",")
    if head != "data:image/svg+xml;base64":
        raise ReportError(f"a report figure is not an inline SVG image ({head[:40]!r})")
    return base64.b64decode(data).decode("utf-8")


def _trim(kids: list[Element | str]) -> list[Element | str]:
    """A block's children without the spaces at its start, its end and after a <br>."""
    kids = list(kids)
    for i, kid in enumerate(kids):
        before = kids[i - 1] if i else None
        if isinstance(kid, str) and (i == 0 or isinstance(before, Element) and before.tag == "br"):
            kids[i] = kid.lstrip()
    if kids and isinstance(kids[-1], str):
        kids[-1] = kids[-1].rstrip()
    return [k for k in kids if k != ""]


def _json(node: Element | str) -> Json | str:
    """The template's input for one node: long runs of text made breakable, tables shaped
    (columns, widths, caption, header and body rows: Typst wants them counted)."""
    if isinstance(node, str):
        return breakable(node)
    if node.tag == "pre":
        return {"t": "pre", "c": node.cls, "k": [node.text()]}
    if node.tag == "table":
        return _table(node)
    out: Json = {"t": node.tag, "c": node.cls, **node.attrs}
    if node.tag == "figure":  # PDF/A-3a: every image has a text alternative
        out["alt"] = " ".join(node.text().split()) or "figure"
    if node.tag == "section" and "id" in node.attrs:  # the contents point at its heading
        for h2 in node.elements("h2")[:1]:
            h2.attrs.setdefault("id", node.attrs["id"])
    out["k"] = [_json(k) for k in (node.kids if node.tag in INLINE else _trim(node.kids))]
    return out


def _table(table: Element) -> Json:
    def rows(parent: Element) -> list[Json]:
        return [
            {"c": tr.cls, "k": [_json(cell) for cell in tr.elements()]}
            for tr in parent.elements("tr")
        ]

    head = [r for part in table.elements("thead") for r in rows(part)]
    body = rows(table) + [r for part in table.elements("tbody") for r in rows(part)]
    widths = [
        col.attrs["w"] for group in table.elements("colgroup") for col in group.elements("col")
    ]
    first = (head or body or [{"k": []}])[0]["k"]
    assert isinstance(first, list)
    columns = sum(int(cell.get("colspan", 1)) for cell in first)
    caption = table.elements("caption")
    return {
        "t": "table",
        "c": table.cls,
        "columns": max(columns, 1),
        "widths": widths if len(widths) == columns and None not in widths else None,
        "caption": [_json(k) for k in _trim(caption[0].kids)] if caption else [],
        "head": head,
        "body": body,
    }


def _line(text: str, most: int = LINE) -> str:
    """One line of the page's furniture (title, running header and footer): cut at `most`
    characters, so that hostile text cannot fill a page's margins."""
    line = " ".join(text.split())
    return line if len(line) <= most else line[: most - 1] + "\u2026"


def document(html: str) -> Json:
    """The report's HTML as the Typst template's input: ``meta`` (title, the identification
    line of the footer, the simulation banner of the header, the watermark's lines) and
    ``body``."""
    tree = _Tree()
    tree.feed(html)
    tree.close()
    body = tree.root
    for tag in ("html", "body"):
        body = next(iter(body.elements(tag)), body)
    mark, doc_id, sim = (body.find(c) for c in ("watermark", "doc-id", "sim-banner"))
    return {
        "meta": {
            "title": _line(tree.title),
            "doc_id": "" if doc_id is None else _line(doc_id.text()),
            "banner": "" if sim is None else _line(sim.text()),
            "watermark": [] if mark is None else mark.text().split("\n"),
        },
        "body": [_json(k) for k in _trim(body.kids)],
    }


@dataclass(frozen=True)
class Attachment:
    """A file carried inside the PDF (a PDF/A-3 associated file)."""

    name: str
    text: str
    mime: str
    description: str


def _fonts() -> str:
    """The folder of DejaVu Sans as the figures have it (matplotlib's copy: no system fonts)."""
    spec = find_spec("matplotlib")
    assert spec is not None and spec.origin is not None  # a dependency of the project
    return str(Path(spec.origin).parent / "mpl-data" / "fonts" / "ttf")


def _timestamp(generated_at: str | None) -> datetime | None:
    """The PDF's creation date: the report's own generation time (deterministic output)."""
    try:
        stamp = datetime.fromisoformat(generated_at or "")
    except ValueError:
        return None
    return stamp if stamp.tzinfo is not None else None


def write_pdf(
    html: str,
    path: Path,
    attachments: tuple[Attachment, ...] = (),
    generated_at: str | None = None,
) -> Path:
    """Lay out the report's HTML as a PDF/A-3a file carrying `attachments`."""
    try:
        import typst  # imported only when a PDF is asked for
    except ImportError as error:
        raise ReportError(
            f"PDF output needs Typst: pip install 'gyrostand[pdf]' ({error})"
        ) from None

    doc = document(html)
    doc["attachments"] = [
        {"name": a.name, "mime": a.mime, "description": a.description} for a in attachments
    ]
    inputs = {"document": json.dumps(doc, ensure_ascii=False)}
    inputs.update({f"file:{a.name}": a.text for a in attachments})
    try:
        pdf = typst.compile(
            TEMPLATE.read_bytes(),
            format="pdf",
            font_paths=typst.Fonts(include_system_fonts=False, font_paths=[_fonts()]),
            ignore_system_fonts=True,
            sys_inputs=inputs,
            pdf_standards=[PDF_STANDARD],
            timestamp=_timestamp(generated_at),
        )
    except typst.TypstError as error:  # a defect of the template, not of the user's data
        raise ReportError(f"the PDF layout failed: {error.message}") from None
    path.write_bytes(pdf)
    return path
