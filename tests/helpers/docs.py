"""The documentation as the tests read it: README.md, the front page, and the site's pages in docs/."""

from __future__ import annotations

import importlib.util
from functools import cache
from types import ModuleType

from tests.helpers.dataflow import ROOT

DOCS = ROOT / "docs"


def page_text(name: str) -> str:
    """One page of the site, by its path under docs/ (e.g. "nodes/simulation.md"), as written (markers unexpanded)."""
    return (DOCS / name).read_text(encoding="utf-8")


def pages() -> dict[str, str]:
    """Every page of the site: its path under docs/ -> its text."""
    return {str(path.relative_to(DOCS)): path.read_text(encoding="utf-8") for path in sorted(DOCS.rglob("*.md"))}


def docs_text() -> str:
    """README.md and every page, one after the other: where a fact told once may be found."""
    return "\n\n".join([(ROOT / "README.md").read_text(encoding="utf-8"), *pages().values()])


@cache
def hooks() -> ModuleType:
    """docs/hooks.py, the MkDocs hooks that make the settings tables and the commands' help from the code."""
    spec = importlib.util.spec_from_file_location("so101_docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
