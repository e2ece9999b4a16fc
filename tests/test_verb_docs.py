"""docs/verbs/ holds every verb's --help as it is now (tools/make_verb_docs.py writes it)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_verb_has_its_current_help_page(monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    spec = importlib.util.spec_from_file_location("make_verb_docs", ROOT / "tools" / "make_verb_docs.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    pages = tool.pages()
    assert {"README.md", "solve.md", "export.md", "report.md", "track-object.md"} <= set(pages)
    stale = [name for name, text in pages.items()
             if not (ROOT / "docs" / "verbs" / name).is_file() or (ROOT / "docs" / "verbs" / name).read_text() != text]
    assert stale == [], f"run tools/make_verb_docs.py: {stale}"
    committed = {p.name for p in (ROOT / "docs" / "verbs").glob("*.md")}
    assert committed == set(pages), committed ^ set(pages)
