"""Write docs/verbs/: one page per verb from its --help, and an index (README.md). A test checks that the
pages match the current help, so run this after changing a verb's arguments.

    .venv/bin/python tools/make_verb_docs.py
"""

import os
from pathlib import Path

os.environ["COLUMNS"] = "100"  # argparse wraps the help to the terminal: a fixed width gives the same pages

from handcap.cli.main import verb_parsers  # noqa: E402  (after COLUMNS)

DOCS = Path(__file__).resolve().parents[1] / "docs" / "verbs"


def pages() -> dict:
    """File name -> text of every page."""
    parsers = verb_parsers()
    out = {}
    rows = []
    for verb, parser in parsers.items():
        out[f"{verb}.md"] = f"# handcap {verb}\n\n```text\n{parser.format_help().rstrip()}\n```\n"
        summary = (parser.description or "").split(". ")[0].rstrip(".")
        rows.append(f"| [`{verb}`]({verb}.md) | {summary} |")
    out["README.md"] = ("# handcap's verbs\n\nEach page is the verb's `--help` (written by `tools/make_verb_docs.py`; "
                        "a test keeps them current).\n\n| verb | what it does |\n|---|---|\n" + "\n".join(rows) + "\n")
    return out


if __name__ == "__main__":
    DOCS.mkdir(parents=True, exist_ok=True)
    for name, text in pages().items():
        (DOCS / name).write_text(text)
    print(f"wrote {len(pages())} pages into {DOCS}")
