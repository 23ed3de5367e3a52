"""A griffe extension that makes servobus's docstrings render in mkdocstrings (mkdocs.yml loads it).

The docstrings are written for Sphinx: ``:meth:`cycle```, ``:class:`~servobus.frame.Frame```,
``:func:`Plant.grid <servobus.sim.plant.Plant.grid>```. Markdown would show them as raw text, so each
role becomes ``<autoref identifier="FULL.PATH" optional><code>shown</code></autoref>``: mkdocs-autorefs
links it when the target is rendered somewhere on the site and leaves the code span otherwise, with no
warning. Every Sphinx Python role is taken (``:class:``, ``:meth:``, ``:func:``, ``:attr:``, ``:data:``,
``:mod:``, ``:exc:``, ``:obj:``, ``:const:``, ``:ref:``, and their ``:py:`` spellings). What is shown
follows Sphinx: the name as written, its last part after ``~``, the title of ``title <target>``, and
``()`` after a function or method.

A paragraph that ends with Sphinx's literal-block marker (``blocking::``, or ``::`` alone) loses it
as Sphinx drops it (``blocking:``; nothing): the indented block after it is already Markdown's code.

A name is resolved as Sphinx would find it, against the object whose docstring it is, then its
class, its module, the packages above it, and ``servobus``; an alias found so (``servobus.Frame``, a
name a module imports) is followed to the object's own path, the one its page renders it under.
What resolves nowhere keeps the name as written (a code span on the page).

Private defaults. A parameter whose default is a private name (``stale_after_s=_DEFAULT`` in Bus: a
sentinel meaning "the link's own value") would show that name, which a reader cannot use. A private
constant bound to a literal (``high_water_bytes=_HIGH_WATER_BYTES``, 64) shows its value; any other
private default (a sentinel, a dataclass field's private ``default_factory``) shows as ``...`` (the
typeshed convention: there is a default, and the docstring's Args entry says what it is). A private
type in the annotation (``float | _Default | None``) is dropped from the union, since no caller
passes it.
"""

from __future__ import annotations

import ast
import html
import re
from collections.abc import Iterator
from typing import Any

import griffe

#: ``:role:`text``` and ``:py:role:`text```; the text may run over a line break.
ROLE = re.compile(r":(?:py:)?(?P<role>class|meth|func|attr|data|mod|exc|obj|const|ref):`(?P<text>[^`]+)`")
_TITLED = re.compile(r"^(?P<title>.*?)\s*<(?P<target>[^<>]+)>$", re.S)
_CALLABLE = ("meth", "func")
_PRIVATE = re.compile(r"^_[A-Za-z0-9_]*$")
#: A private name or a call of one (a dataclass field's ``default_factory=_no_ops`` is ``_no_ops()``).
_PRIVATE_DEFAULT = re.compile(r"^_[A-Za-z0-9_]*(?:\(\))?$")


def _members(obj: griffe.Object) -> Iterator[griffe.Object]:
    """``obj`` and every object defined under it (not what it imports: aliases are not walked)."""
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _members(member)  # type: ignore[arg-type]


def _lookup(scope: griffe.Object | griffe.Alias, dotted: str) -> str | None:
    """The rendered path of ``dotted`` looked up inside ``scope``, following aliases; None if absent."""
    try:
        found = scope[dotted]
    except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None
    try:
        return str(found.final_target.path if found.is_alias else found.path)
    except (griffe.AliasResolutionError, griffe.CyclicAliasError):
        return str(found.target_path if found.is_alias else found.path)


def _scopes(obj: griffe.Object, root: griffe.Object) -> Iterator[griffe.Object]:
    """Where a name in ``obj``'s docstring is looked for, nearest first."""
    node: griffe.Object | None = obj
    while node is not None:
        yield node
        node = node.parent
    yield root


def resolve(target: str, obj: griffe.Object, root: griffe.Object) -> str:
    """The full path of ``target`` as written in ``obj``'s docstring (``target`` itself if unknown)."""
    dotted = target.lstrip(".")
    if dotted == root.path:
        return root.path
    if dotted.startswith(root.path + "."):
        return _lookup(root, dotted[len(root.path) + 1 :]) or dotted
    for scope in _scopes(obj, root):
        if (path := _lookup(scope, dotted)) is not None:
            return path
    return dotted


def _parts(match: re.Match[str], obj: griffe.Object, root: griffe.Object) -> tuple[str, str]:
    """What a role shows and the full path of what it names."""
    text = " ".join(match["text"].split())
    titled = _TITLED.match(text)
    if titled:
        title, target = titled["title"], titled["target"]
    else:
        target = text.lstrip("!")
        shown = target.lstrip("~").lstrip(".")
        title = shown.rsplit(".", 1)[-1] if target.startswith("~") else shown
        if match["role"] in _CALLABLE and not title.endswith(")"):
            title += "()"
    target = target.lstrip("~").removesuffix("()")
    # (a :ref: names a label: a heading's anchor, which autorefs knows as it knows objects)
    return title, target if match["role"] == "ref" else resolve(target, obj, root)


def _replace(match: re.Match[str], obj: griffe.Object, root: griffe.Object) -> str:
    title, full = _parts(match, obj, root)
    return f'<autoref identifier="{html.escape(full)}" optional><code>{html.escape(title)}</code></autoref>'


def _code_lines(lines: list[str]) -> list[bool]:
    """Which of a docstring's lines Markdown shows as code: in a ``` fence, or indented four spaces
    after a blank line (a Google section's entries follow their heading with no blank line)."""
    code, fenced, in_block, after_blank = [], False, False, True
    for line in lines:
        stripped = line.strip()
        if stripped.startswith("```"):
            code.append(True)
            fenced, after_blank = not fenced, False
            continue
        if fenced:
            code.append(True)
            continue
        if stripped:
            in_block = len(line) - len(line.lstrip()) >= 4 and (in_block or after_blank)
        code.append(in_block)
        after_blank = not stripped
    return code


#: Sphinx's literal-block marker at the end of a paragraph, a blank line (or the end) after it.
_LITERAL = re.compile(r"(?P<before>\S?)(?P<space>[ \t]*)::[ \t]*(?=\n[ \t]*(?:\n|\Z)|\Z)")


def _literal_marker(match: re.Match[str]) -> str:
    if not match["before"]:  # ("::" alone on its line: dropped)
        return ""
    return match["before"] + ("" if match["space"] else ":")  # ("text ::" -> "text", "text::" -> "text:")


def convert(text: str, obj: griffe.Object, root: griffe.Object) -> str:
    """``text`` with every Sphinx role made a cross-reference and its literal-block markers dropped;
    in code (where Markdown would show the cross-reference's HTML as text) a role is what it shows."""
    lines = text.split("\n")
    for i, code in enumerate(_code_lines(lines)):
        if code:
            lines[i] = ROLE.sub(lambda m: _parts(m, obj, root)[0], lines[i])
    text = "\n".join(lines)
    return _LITERAL.sub(_literal_marker, ROLE.sub(lambda m: _replace(m, obj, root), text))


def _literal(module: griffe.Module, name: str) -> str | None:
    """The source of the literal a module-level private constant is bound to, or None."""
    member = module.members.get(name)
    if member is None or member.is_alias or not isinstance(member, griffe.Attribute):
        return None
    value = member.value
    try:
        ast.literal_eval(str(value))
    except (ValueError, SyntaxError, TypeError):
        return None
    return str(value)


def _without_private(annotation: Any) -> Any:
    """A union annotation without its private members (``float | _Default | None``)."""
    if not isinstance(annotation, griffe.ExprBinOp) or annotation.operator != "|":
        return annotation
    parts: list[Any] = []

    def flatten(expr: Any) -> None:
        if isinstance(expr, griffe.ExprBinOp) and expr.operator == "|":
            flatten(expr.left)
            flatten(expr.right)
        else:
            parts.append(expr)

    flatten(annotation)
    kept = [p for p in parts if not _PRIVATE.match(str(p))]
    if not kept or len(kept) == len(parts):
        return annotation
    result = kept[0]
    for part in kept[1:]:
        result = griffe.ExprBinOp(result, "|", part)
    return result


def public_defaults(function: griffe.Function) -> None:
    """Replace each private default (and private union member) of ``function``'s parameters."""
    module = function.module
    for parameter in function.parameters:
        default = parameter.default
        if default is not None and _PRIVATE_DEFAULT.match(str(default)):
            parameter.default = _literal(module, str(default)) or "..."
            parameter.annotation = _without_private(parameter.annotation)


class ServobusDocstrings(griffe.Extension):
    """Sphinx roles made cross-references, private defaults made readable (the module says how)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        for obj in _members(pkg):
            if obj.docstring is not None:
                obj.docstring.value = convert(obj.docstring.value, obj, pkg)
            if isinstance(obj, griffe.Function):
                public_defaults(obj)
