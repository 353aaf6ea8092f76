"""The documentation site as a reader meets it: offline from ``file://``, API pages whose Sphinx
markup became links and code, and ``help(idkit)`` that starts with what to type."""

from __future__ import annotations

import pydoc
import sys

import griffe
import yaml

from conftest import REPO

sys.path.insert(0, str(REPO / "docs_ext"))
from sphinx_markup import ROLE, SphinxMarkup, fence_literal_blocks  # noqa: E402


def mkdocs_config() -> dict:
    """mkdocs.yml, its ``!!python/name`` tags (material's emoji options) read as plain strings."""

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_multi_constructor("tag:yaml.org,2002:python/", lambda loader, suffix, node: suffix)
    return yaml.load((REPO / "mkdocs.yml").read_text(), Loader=Loader)


def test_the_site_works_from_disk():
    config = mkdocs_config()
    assert config["use_directory_urls"] is False  # page.html, not page/ (a folder listing from file://)
    plugins = [p if isinstance(p, str) else next(iter(p)) for p in config["plugins"]]
    assert "offline" in plugins  # the search index inlined: browsers refuse to fetch it from file://
    assert config["theme"].get("font") is False  # no request to a font server


def test_roles_become_optional_cross_references_resolved_from_the_scope(tmp_path):
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text(
        '"""See :func:`helper`, :class:`~pkg.tools.Thing`, :mod:`missing.module` and\n'
        ':func:`the helper <pkg.tools.helper>`::\n\n    helper(1)\n"""\n'
        "from pkg.tools import helper\n"
    )
    (package / "tools.py").write_text(
        'def helper(x):\n    """Help."""\n\n\nclass Thing:\n    """A thing."""\n'
    )
    loaded = griffe.load("pkg", search_paths=[str(tmp_path)], extensions=griffe.load_extensions(SphinxMarkup))
    text = loaded.docstring.value
    assert not ROLE.search(text) and "::" not in text
    assert '<autoref identifier="pkg.tools.helper" optional><code>helper</code></autoref>' in text
    assert '<autoref identifier="pkg.tools.Thing" optional><code>Thing</code></autoref>' in text
    assert "<code>the helper</code></autoref>" in text
    assert (
        "<code>missing.module</code>" in text and 'identifier="missing.module"' not in text
    )  # no such object
    assert "```python\n    helper(1)\n```" not in text and "```python\nhelper(1)\n```" in text


def test_a_literal_block_keeps_its_indentation_inside_a_section():
    text = "Args:\n    x: as in::\n\n        f(x)\n\n    y: next"
    assert (
        fence_literal_blocks(text)
        == "Args:\n    x: as in:\n\n    ```python\n    f(x)\n    ```\n\n    y: next"
    )


def test_help_opens_with_what_to_type():
    import idkit

    lines = pydoc.render_doc(idkit, renderer=pydoc.plaintext).splitlines()
    opening = "\n".join(lines[:12])
    assert "idkit.identify(" in opening and ".save(" in opening and "idkit.data.demo" in opening
