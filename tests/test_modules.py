"""Every module owns one idea and says what it offers (issue 15): none is over about 450 lines, and every public
function and method has a numpydoc docstring (a ``Parameters`` section once it takes two or more arguments)."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "handcap"
MAX_LINES = 470  # "about 450"


def _public_functions(tree):
    """(name, node) of the module's public functions and of the public methods of its public classes."""
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
            yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("_"):
                    yield f"{node.name}.{item.name}", item


def _undocumented(source: str) -> list:
    found = []
    for name, node in _public_functions(ast.parse(source)):
        doc = ast.get_docstring(node) or ""
        args = [a.arg for a in node.args.args + node.args.kwonlyargs if a.arg not in ("self", "cls")]
        if not doc or (len(args) >= 2 and "Parameters" not in doc):
            found.append(name)
    return found


def test_the_docstring_check_can_fail():
    source = ('def a(x, y):\n    """Sum."""\n\n\ndef b(x, y):\n    """Sum.\n\n    Parameters\n    ----------\n    '
              'x, y : float\n    """\n\n\nclass C:\n    def m(self):\n        pass\n\n    def _private(self):\n'
              '        pass\n')
    assert _undocumented(source) == ["a", "C.m"]


def test_every_public_function_has_its_numpydoc():
    found = [f"{path.relative_to(PACKAGE)}: {name}" for path in sorted(PACKAGE.rglob("*.py"))
             if "cli" not in path.relative_to(PACKAGE).parts for name in _undocumented(path.read_text())]
    assert found == []


def test_no_module_is_over_about_450_lines():
    sizes = {str(path.relative_to(PACKAGE)): len(path.read_text().splitlines()) for path in PACKAGE.rglob("*.py")}
    assert len(sizes) > 100
    assert {name: n for name, n in sizes.items() if n > MAX_LINES} == {}


def test_every_module_says_what_it_owns():
    missing = [str(path.relative_to(PACKAGE)) for path in PACKAGE.rglob("*.py")
               if path.name != "__main__.py" and not ast.get_docstring(ast.parse(path.read_text()))]
    assert missing == []
