"""`depth` may import `vbgs` but never `experiments` (ARCHITECTURE.md import rule)."""

import ast
from pathlib import Path

import depth

FORBIDDEN = ("experiments",)


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_depth_never_imports_experiments():
    files = sorted(Path(depth.__file__).parent.glob("*.py"))
    assert files
    for path in files:
        bad = {m for m in _imported_modules(path) if m.split(".")[0] in FORBIDDEN}
        assert not bad, f"{path.name} imports {bad}"
