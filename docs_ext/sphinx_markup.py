"""A griffe extension for the API pages: idkit's docstrings use Sphinx's inline markup, which reads
well in ``help()`` but which mkdocstrings renders as written (``:func:`run```, a bare ``::``).

Each role becomes a cross-reference to the object it names, resolved the way Python would from the
docstring's own scope (a link when that object has a page, its name in code otherwise), and a
literal block (a paragraph ending in ``::``) a fenced Python block. mkdocs.yml loads it by path.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

#: ``:func:`name```, ``:func:`~pkg.name``` (shown as its last part), ``:func:`title <pkg.name>```
ROLE = re.compile(r":(?:func|class|meth|mod|data|attr|exc|obj|const):`(?P<body>[^`]+)`")


def resolve(scope: griffe.Object, target: str) -> str | None:
    """The path of the object ``target`` names as seen from ``scope``, or None when there is none."""
    collection = scope.modules_collection
    candidates = [target]
    parent: griffe.Object | None = scope
    while parent is not None:
        candidates.append(f"{parent.path}.{target}")
        parent = parent.parent
    for path in candidates:
        try:
            found = collection[path]
            return str(found.final_target.path if isinstance(found, griffe.Alias) else found.path)
        except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
            continue
    return None


def cross_reference(scope: griffe.Object, body: str) -> str:
    """One role's text as an optional autorefs reference (plain code where nothing is found)."""
    title, _, bracketed = body.partition(" <")
    target = bracketed.rstrip(">") if bracketed else title
    short = target.startswith("~")
    target = target.lstrip("~.").removesuffix("()")
    shown = (target.rsplit(".", 1)[-1] if short else target) if not bracketed else title
    path = resolve(scope, target)
    code = f"<code>{shown}</code>"
    return f'<autoref identifier="{path}" optional>{code}</autoref>' if path else code


def indent_of(line: str) -> int:
    return len(line) - len(line.lstrip())


def fence_literal_blocks(text: str) -> str:
    """``Example::`` followed by an indented block → ``Example:`` and a fenced Python block."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        if line.rstrip().endswith("::") and i + 1 < len(lines) and not lines[i + 1].strip():
            indent = indent_of(line)
            head = line.rstrip()[:-2].rstrip()
            out.append(f"{head}:" if head.strip() else "")
            j = i + 2
            block = []
            while j < len(lines) and (not lines[j].strip() or indent_of(lines[j]) > indent):
                block.append(lines[j])
                j += 1
            while block and not block[-1].strip():
                block.pop()
            if block:
                cut = min(indent_of(b) for b in block if b.strip())
                pad = " " * indent
                out += ["", f"{pad}```python", *[pad + b[cut:] for b in block], f"{pad}```", ""]
                i = j
                continue
        out.append(line)
        i += 1
    return "\n".join(out)


class SphinxMarkup(griffe.Extension):
    """Rewrites every docstring once the package is loaded (names then resolve across modules)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        self.rewrite(pkg)

    def rewrite(self, obj: griffe.Object) -> None:
        if obj.docstring is not None:
            text = fence_literal_blocks(obj.docstring.value)
            obj.docstring.value = ROLE.sub(lambda m: cross_reference(obj, m["body"]), text)
        for member in obj.members.values():
            if not isinstance(member, griffe.Alias) and member.parent is obj:
                self.rewrite(member)
