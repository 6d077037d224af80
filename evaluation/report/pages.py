"""The report's pages below ``index.html``: one per sequence, one per pictured event.

A sequence page holds the run's timeline of that sequence, its thumbnails and the list of its
events (at most :data:`MAX_LISTED` rows, so pages stay small on long sequences); an event page
the frame at full size with the frames before and after it, captions and the legend, linked to
the sequence page and to the previous and next pictured events.
"""

from __future__ import annotations

from pathlib import Path

from unitrack_env.io import atomic_write_text

from .html import esc, page, table
from .pictures import Item, Picture
from .thumbs import GT_COLOUR, OTHER_COLOUR, PREVIOUS_COLOUR, TRACK_COLOUR

#: Rows of a sequence page's event list (the rest: ``unitrack events --format csv``).
MAX_LISTED = 300

PAGE_CSS = ("<style>.frames{display:flex;gap:8px;flex-wrap:wrap}.frames figure{margin:0}"
            ".full img{max-width:100%;border:1px solid #999}nav a{margin-right:1.2em}"
            ".frames img{border:1px solid #999}</style>")


def _swatch(colour: tuple[int, int, int], thick: bool, faded: bool = False) -> str:
    rgb = "rgb({},{},{})".format(*colour)
    style = (f"border:{3 if thick else 1}px solid {rgb};background:none;"
             f"opacity:{0.55 if faded else 1}")
    return f'<span style="{style}"></span>'


def legend() -> str:
    """What the colours and widths of every picture mean (boxes, joints and masks)."""
    entries = [(_swatch(GT_COLOUR, True), "the event's ground truth (gt id)"),
               (_swatch(TRACK_COLOUR, True), "the track at the event (SOT: the prediction; "
                "VOS: the object's result mask, filled)"),
               (_swatch(PREVIOUS_COLOUR, True), "the track the ground truth had before an ID "
                "switch"),
               (_swatch(GT_COLOUR, False, True), "other ground truth"),
               (_swatch(OTHER_COLOUR, False), "other tracks (grey)")]
    return ('<p class="legend">Pictures: ' + "".join(f"{s}{esc(t)}" for s, t in entries)
            + ". Numbers are ids; joints are circles. Points: the true position a green dot "
            "and the predicted one a red dot, joined by a grey line; a hollow ring is a point "
            "occluded (in the truth, or as predicted).</p>")


def figure(picture: Picture, clip: Path | None = None) -> str:
    """A thumbnail linking to its event page (and to the clip `unitrack render` made)."""
    item = picture.item
    link = ""
    if clip is not None and picture.seconds is not None:
        link = f' · <a href="{esc(clip.resolve().as_uri())}#t={picture.seconds:.2f}">clip</a>'
    return (f'<figure><a href="{esc(picture.page)}"><img loading="lazy" class="thumb '
            f'{item.kind}" data-kind="{item.kind}" data-frame="{item.frame}" '
            f'src="{esc(picture.thumb)}" alt="{esc(item.caption)}"></a><figcaption>'
            f"{esc(item.caption)}{link}</figcaption></figure>")


def _write(path: Path, title: str, body: list[str]) -> None:
    atomic_write_text(path, page(title, [PAGE_CSS, *body]))  # renamed in place, never via a link


def event_pages(out: Path, pictures: list[Picture], sequence_page: str, title: str) -> None:
    """Write each picture's page (beside its images), chained to its neighbours."""
    for i, pic in enumerate(pictures):
        here = Path(pic.page).name
        nav = ['<a href="../index.html">report</a>',
               f'<a class="sequence-page" href="../{esc(sequence_page)}">{esc(title)}</a>']
        if i > 0:
            nav.append(f'<a class="prev-event" href="{esc(Path(pictures[i - 1].page).name)}">'
                       "← previous event</a>")
        if i + 1 < len(pictures):
            nav.append(f'<a class="next-event" href="{esc(Path(pictures[i + 1].page).name)}">'
                       "next event →</a>")
        frame = pic.item.frame
        near = "".join(
            f'<figure class="{cls}"><img src="{esc(Path(src).name)}" alt="frame {n}">'
            f"<figcaption>frame {n} ({word})</figcaption></figure>"
            for cls, src, n, word in (("prev", pic.prev, frame - 1, "before"),
                                      ("next", pic.next, frame + 1, "after")) if src)
        body = [f"<nav>{''.join(nav)}</nav>", f"<h1>{esc(pic.item.caption)}</h1>",
                f"<p>{esc(title)}, frame {frame}.</p>", legend(),
                f'<figure class="full"><img id="event-frame" src="{esc(Path(pic.full).name)}" '
                f'alt="{esc(pic.item.caption)}"><figcaption>frame {frame}: '
                f"{esc(pic.item.caption)}</figcaption></figure>",
                f'<div class="frames">{near or "<p>No neighbouring frame on disk.</p>"}</div>']
        _write(out / Path(pic.page).parent / here, pic.item.caption, body)


def _event_rows(items: list[Item], pictured: dict[Item, str]) -> list[str]:
    rows = []
    for item in items[:MAX_LISTED]:
        link = pictured.get(item)
        shown = f'<a href="{esc(link)}">picture</a>' if link else ""
        rows.append(f'<tr><td class="text">{esc(item.kind)}</td><td data-value="{item.frame}">'
                    f'{item.frame}</td><td class="text">{esc(item.caption)}</td>'
                    f'<td class="text">{shown}</td></tr>')
    return rows


def sequence_page(out: Path, name: str, title: str, timeline: str, figures: list[str],
                  items: list[Item], pictures: list[Picture], hint: str) -> str:
    """Write ``out/<name>`` (timeline, thumbnails, event list); return its name."""
    pictured = {p.item: p.page for p in pictures}
    listed = ""
    if items:
        more = (f"<p>The first {MAX_LISTED} of {len(items)}; {esc(hint)} lists them all.</p>"
                if len(items) > MAX_LISTED else f"<p>Every row: {esc(hint)}.</p>")
        listed = ('<h2 id="event-list">Events</h2>'
                  + table(["kind", "frame", "event", ""], _event_rows(items, pictured),
                          table_id="event-list-table") + more)
    body = ['<nav><a href="index.html">← report</a></nav>', f"<h1>{esc(title)}</h1>",
            timeline, legend(), '<div class="thumbs">' + "".join(figures) + "</div>", listed]
    _write(out / name, title, body)
    return name
