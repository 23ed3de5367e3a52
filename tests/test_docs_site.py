"""The site as a reader gets it: built the way CI builds it (``mkdocs build --strict``, once for the
module) and read on the rendered HTML. No Sphinx role left raw, no private name as a default, no
repeated entry in a page's contents or the navigation, every ``servobus`` command with its usage line
and its options, and the four sections with the pages the issue names."""

from __future__ import annotations

import html
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path

import click
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

from servobus_griffe import ROLE  # noqa: E402 (the extension's own pattern: what it must leave none of)

#: A Sphinx role as it reads once Markdown has rendered it (``:meth:<code>cycle</code>`` → ``:meth:cycle``).
RAW_ROLE = re.compile(r":(?:py:)?(?:class|meth|func|attr|data|mod|exc|obj|const|ref):\S")
#: A private name given as a default: ``x=_DEFAULT`` in a signature, ``default: _DEFAULT`` in a list.
PRIVATE_DEFAULT = re.compile(r"(?:=|default:)\s*_[A-Za-z]\w*")
#: Rich markup that would leak into the CLI page from a help text (``[bold]``, ``[/]``).
RICH_MARKUP = re.compile(
    r"\[/?(?:bold|dim|italic|underline|red|green|yellow|blue|cyan|magenta|b|i|u|link)\b[^\]]*\]|\[/\]"
)


# ---- a small DOM (the standard library has a parser, not a tree) ----

_VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


@dataclass
class Node:
    tag: str
    attrs: dict[str, str]
    children: list[Node | str] = field(default_factory=list)

    @property
    def classes(self) -> set[str]:
        return set(self.attrs.get("class", "").split())

    def find_all(self, tag: str, cls: str | None = None) -> Iterator[Node]:
        for child in self.children:
            if isinstance(child, Node):
                if child.tag == tag and (cls is None or cls in child.classes):
                    yield child
                yield from child.find_all(tag, cls)

    def find(self, tag: str, cls: str | None = None) -> Node | None:
        return next(self.find_all(tag, cls), None)

    def kids(self, tag: str) -> list[Node]:
        return [c for c in self.children if isinstance(c, Node) and c.tag == tag]

    def text(self, skip: str | None = None) -> str:
        """The text inside, whitespace collapsed (without elements of class ``skip``: a symbol badge)."""
        parts = [
            c if isinstance(c, str) else c.text(skip)
            for c in self.children
            if isinstance(c, str) or skip not in c.classes
        ]
        return " ".join(" ".join(parts).split())


class _Builder(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.root = Node("#root", {})
        self.stack = [self.root]

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        node = Node(tag, {k: v or "" for k, v in attrs})
        self.stack[-1].children.append(node)
        if tag not in _VOID:
            self.stack.append(node)

    def handle_endtag(self, tag: str) -> None:
        for depth in range(len(self.stack) - 1, 0, -1):  # (close what was left open inside it)
            if self.stack[depth].tag == tag:
                del self.stack[depth:]
                return

    def handle_data(self, data: str) -> None:
        self.stack[-1].children.append(data)


def parse(text: str) -> Node:
    builder = _Builder()
    builder.feed(text)
    return builder.root


# ---- the site, built once ----


@dataclass
class Site:
    root: Path
    seconds: float
    pages: dict[str, str]  # site path ("api/servobus/") -> its HTML

    def dom(self, page: str) -> Node:
        return parse(self.pages[page])


@pytest.fixture(scope="module")
def site(built_site: tuple[Path, float]) -> Site:
    """The site built as CI builds it (.ci/run: ``mkdocs build --strict``, a warning fails it)."""
    out, seconds = built_site
    pages = {}
    for path in out.rglob("index.html"):
        where = path.parent.relative_to(out).as_posix()
        pages["" if where == "." else where + "/"] = path.read_text(encoding="utf-8")
    return Site(out, seconds, pages)


def _prose(page_html: str) -> str:
    """A page's text outside code listings and scripts (a listing may quote a docstring verbatim)."""
    text = re.sub(r"<(pre|script|style)\b.*?</\1>", " ", page_html, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", "", text))


def test_the_site_builds_strict_with_every_page(site: Site) -> None:
    print(f"mkdocs build --strict: {site.seconds:.1f} s, {len(site.pages)} pages")
    assert len(site.pages) >= 25


# ---- docstrings that render ----


def test_the_extension_converts_every_role_form() -> None:
    import griffe
    from servobus_griffe import convert

    package = griffe.load("servobus", search_paths=[str(ROOT / "src")], resolve_aliases=False)
    bus = package["bus.core.Bus"]
    cases = {
        ":meth:`cycle`": ('identifier="servobus.bus.core.Bus.cycle"', "<code>cycle()</code>"),
        ":class:`~servobus.frame.Frame`": ('identifier="servobus.frame.Frame"', "<code>Frame</code>"),
        ":py:class:`servobus.Frame`": ('identifier="servobus.frame.Frame"', "<code>servobus.Frame</code>"),
        ":func:`Plant.grid <servobus.sim.plant.Plant.grid>`": (
            'identifier="servobus.sim.plant.Plant.grid"',
            "<code>Plant.grid</code>",
        ),
        ":mod:`servobus.signals`": ('identifier="servobus.signals"', "<code>servobus.signals</code>"),
        ":exc:`TransportError`": (
            'identifier="servobus.errors.TransportError"',
            "<code>TransportError</code>",
        ),
        ":ref:`the loop <pipelined-servobusloop>`": (
            'identifier="pipelined-servobusloop"',
            "<code>the loop</code>",
        ),
    }
    for role, (identifier, shown) in cases.items():
        out = convert(role, bus, package)  # type: ignore[arg-type]
        assert identifier in out and shown in out and " optional>" in out, (role, out)
        assert not ROLE.search(out), out
    # in code (indented after a blank line, or fenced) a role is the text it shows, never HTML
    text = "Options:\n\n    late_hold_s: see :meth:`~servobus.rtt.RoundTrip.late_s`\n\nAnd :meth:`cycle`."
    out = convert(text, bus, package)  # type: ignore[arg-type]
    assert "    late_hold_s: see late_s()\n" in out and out.count("<autoref") == 1, out
    fenced = convert("```\nbus.cycle()  # :meth:`cycle`\n```", bus, package)  # type: ignore[arg-type]
    assert fenced == "```\nbus.cycle()  # cycle()\n```", fenced
    section = convert("Args:\n    items: as :meth:`cycle` takes", bus, package)  # type: ignore[arg-type]
    assert "<autoref" in section, section  # (a Google section's entries are not code)


def test_the_extension_makes_private_defaults_readable() -> None:
    import griffe
    from servobus_griffe import ServobusDocstrings

    extensions = griffe.load_extensions("dataclasses", ServobusDocstrings())
    package = griffe.load("servobus", search_paths=[str(ROOT / "src")], extensions=extensions)

    def parameter(path: str, name: str) -> griffe.Parameter:
        function = package[path]
        return function.parameters[name]  # type: ignore[no-any-return]

    stale = parameter("bus.core.Bus.__init__", "stale_after_s")  # (a sentinel: "the link's own")
    assert (str(stale.default), str(stale.annotation)) == ("...", "float | None")
    high_water = parameter("transports.rs485.SerialTransport.__init__", "high_water_bytes")
    assert str(high_water.default) == "64"  # (a private constant bound to a literal: its value)
    ops = parameter("protocols.cli.CliFamily", "ops")  # (a dataclass field's private default_factory)
    assert str(ops.default) == "..."


def test_no_raw_sphinx_role_on_any_page(site: Site) -> None:
    raw = {
        page: sorted(set(RAW_ROLE.findall(_prose(text))))
        for page, text in site.pages.items()
        if RAW_ROLE.search(_prose(text))
    }
    assert not raw, raw
    # (nor a converted one shown as text: a role in a docstring's code block, where Markdown escapes
    # the cross-reference's HTML)
    leaked = [page for page, text in site.pages.items() if "&lt;autoref" in text]
    assert not leaked, leaked


def test_every_docstring_section_parsed(site: Site) -> None:
    """A Google section griffe did not take as one shows as a paragraph "Raises: WireError (...)"."""
    unparsed = {
        page: found
        for page, text in site.pages.items()
        if page.startswith("api/")
        and (found := re.findall(r"<p>(?:Args|Arguments|Returns|Raises|Yields|Attributes):", text))
    }
    assert not unparsed, unparsed


def test_roles_became_links(site: Site) -> None:
    """``:meth:`cycle``` in Bus's docstring links to Bus.cycle on the same page."""
    page = site.pages["api/servobus/"]
    assert re.search(
        r'<a class="autorefs autorefs-internal"[^>]*href="#servobus\.(?:bus\.)?Bus\.cycle"', page
    )


def test_no_private_name_as_a_default(site: Site) -> None:
    found: dict[str, list[str]] = {}
    for page, text in site.pages.items():
        signatures = " ".join(
            html.unescape(re.sub(r"<[^>]+>", "", s))
            for s in re.findall(r'<div class="doc-signature[^"]*">(.*?)</div>', text, flags=re.S)
        )
        titles = " ".join(html.unescape(t) for t in re.findall(r'title="([^"]*)"', text))
        hits = PRIVATE_DEFAULT.findall(signatures + " " + titles + " " + _prose(text))
        if hits:
            found[page] = sorted(set(hits))
    assert not found, found
    bus = site.pages["api/servobus/"]
    assert "stale_after_s" in bus  # (the parameter is there, its default readable)


def _toc_levels(ul: Node) -> Iterator[list[str]]:
    """The entries' texts of each list of a table of contents, the top one first (badges left out)."""
    lis = ul.kids("li")
    yield [link.text(skip="doc-symbol") if (link := li.find("a")) else "" for li in lis]
    for li in lis:
        nav = li.find("nav")
        if nav is not None and (nested := nav.find("ul")) is not None:
            yield from _toc_levels(nested)


def _repeats(texts: list[str]) -> list[str]:
    return sorted({t for t in texts if t and texts.count(t) > 1})


def test_no_page_repeats_an_entry_of_its_contents(site: Site) -> None:
    repeated = {}
    for page in site.pages:
        toc = site.dom(page).find("nav", "md-nav--secondary")
        if toc is None or (ul := toc.find("ul")) is None:
            continue
        title = (h1.text() if (h1 := site.dom(page).find("h1")) else "").rstrip("¶").strip()
        levels = list(_toc_levels(ul))
        top = levels[0]
        bad = [r for level in levels for r in _repeats(level)] + [t for t in top if t == title]
        if bad:
            repeated[page] = bad
    assert not repeated, repeated


def test_a_section_does_not_repeat_its_only_entry_s_name(site: Site) -> None:
    """The "Frame" section holding the class Frame (the sidebar's "Frame" twice)."""
    doubled: dict[str, list[str]] = {}
    for page in site.pages:
        toc = site.dom(page).find("nav", "md-nav--secondary")
        for li in toc.find_all("li") if toc else ():
            link, nested = li.find("a"), li.find("ul")
            if link is None or nested is None:
                continue
            parent = link.text(skip="doc-symbol")
            children = [c.find("a") for c in nested.kids("li")]
            names = [a.text(skip="doc-symbol") for a in children if a is not None]
            if parent in names:
                doubled.setdefault(page, []).append(parent)
    assert not doubled, doubled


# ---- the navigation ----

#: (title, href) for a page, (title, [entries]) for a section.
NavEntry = tuple[str, "str | list[NavEntry]"]


def _primary(site: Site) -> list[NavEntry]:
    """The home page's navigation (the sidebar's, which the header's tabs show the top of)."""
    nav = site.dom("").find("nav", "md-nav--primary")
    ul = nav.find("ul") if nav else None
    assert ul is not None, "no navigation"
    return _nav(ul)


def _nav(ul: Node) -> list[NavEntry]:
    """The primary navigation as (title, href) for a page, (title, [...]) for a section."""
    out: list[NavEntry] = []
    for li in ul.kids("li"):
        if "md-nav__item--nested" in li.classes:
            label = li.find("label")
            nested = li.find("nav")
            ul_nested = nested.find("ul") if nested else None
            out.append((label.text() if label else "", _nav(ul_nested) if ul_nested else []))
        else:
            link = next((a for a in li.find_all("a") if "md-nav__link" in a.classes), None)
            if link is not None:
                out.append((link.text(), link.attrs.get("href", "")))
    return out


def _flat(entries: list[NavEntry]) -> list[tuple[str, str]]:
    pages: list[tuple[str, str]] = []
    for title, target in entries:
        pages += _flat(target) if isinstance(target, list) else [(title, target)]
    return pages


def test_the_four_sections_and_the_pages_the_issue_names(site: Site) -> None:
    nav = _primary(site)
    titles = [t for t, _ in nav]
    for section in ("Tutorial", "How-to guides", "Reference", "Explanation"):
        assert section in titles, titles
    sections = dict(nav)
    tutorial = sections["Tutorial"]
    assert tutorial == "tutorial/" or (isinstance(tutorial, list) and tutorial), tutorial
    guides = [t.lower() for t, _ in _flat(sections["How-to guides"])]  # type: ignore[arg-type]
    for wanted in ("hardware bring-up", "1 khz loop", "across computers"):
        assert any(wanted in g for g in guides), (wanted, guides)
    reference = _flat(sections["Reference"])  # type: ignore[arg-type]
    assert ("Command line", "reference/cli/") in reference, reference
    for _, href in _flat(nav):
        assert href.strip("./") + "/" in site.pages or href in (".", "./"), href


def test_the_sidebar_has_no_repeated_entry(site: Site) -> None:
    def levels(entries: list[NavEntry]) -> Iterator[list[str]]:
        yield [t for t, _ in entries]
        for _, target in entries:
            if isinstance(target, list):
                yield from levels(target)

    nav = _primary(site)
    assert not [r for level in levels(nav) for r in _repeats(level)]


# ---- the command line ----


def _commands(
    command: click.Command, path: tuple[str, ...]
) -> Iterator[tuple[tuple[str, ...], click.Command]]:
    yield path, command
    if isinstance(command, click.Group):
        ctx = click.Context(command, info_name=path[-1])
        for name in command.list_commands(ctx):
            sub = command.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                yield from _commands(sub, (*path, name))


def _cli_sections(page_html: str) -> dict[str, str]:
    """The CLI page's text under each command's heading (``servobus-config-dump``), up to the next."""
    parts = re.split(r'<h[1-6] id="(servobus(?:-[\w-]+)?)"', page_html)
    return {parts[i]: html.unescape(re.sub(r"<[^>]+>", " ", parts[i + 1])) for i in range(1, len(parts), 2)}


def test_every_command_and_option_is_on_the_cli_page(site: Site) -> None:
    """Under each command's heading: its usage line, every option, and its first example."""
    from servobus.cli import cli

    sections = _cli_sections(site.pages["reference/cli/"])
    commands = list(_commands(cli, ("servobus",)))
    assert len(commands) > 24  # (the 24 commands, config's subcommands, the group)
    missing = []
    for path, command in commands:
        anchor = "-".join(path)
        text = " ".join(sections.get(anchor, "").split())
        if f"{' '.join(path)} [OPTIONS]" not in text:
            missing.append(f"{' '.join(path)}: no usage line")
        if command.epilog and "\b\n" in command.epilog:  # (its examples, as --help shows them)
            example = command.epilog.split("\b\n", 1)[1].strip().splitlines()[0]
            if " ".join(example.split()) not in text:
                missing.append(f"{' '.join(path)}: not its example {example!r}")
        ctx = click.Context(command, info_name=path[-1])
        for param in command.get_params(ctx):
            shown = isinstance(param, click.Option) and not param.hidden
            named = (re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", text) for opt in param.opts)
            if shown and not all(named):
                missing.append(f"{' '.join(path)} {param.opts}")
    assert not missing, missing


def test_every_command_s_usage_is_somewhere_on_the_site(site: Site) -> None:
    """The issue's measure: each command named with its usage (``servobus NAME [OPTIONS]``)."""
    from servobus.cli import cli

    text = " ".join(" ".join(html.unescape(re.sub(r"<[^>]+>", " ", t)).split()) for t in site.pages.values())
    for path, _ in _commands(cli, ("servobus",)):
        assert f"{' '.join(path)} [OPTIONS]" in text, path


def test_the_cli_page_shows_no_markup_and_no_unset_default(site: Site) -> None:
    text = _prose(site.pages["reference/cli/"]) + " ".join(
        re.findall(r"<pre.*?</pre>", site.pages["reference/cli/"], flags=re.S)
    )
    assert not RICH_MARKUP.search(text), RICH_MARKUP.findall(text)
    assert "Sentinel" not in text and "UNSET" not in text
