"""The package's own source: no module defines a name twice (a later definition silently
replaces the earlier one for every caller)."""

from __future__ import annotations

import ast
import pathlib
from collections import Counter

import bitrock


def test_no_module_of_the_package_defines_a_function_or_class_twice() -> None:
    package = pathlib.Path(bitrock.__file__).parent
    twice = {}
    for path in sorted(package.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = Counter(
            node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
        )
        repeated = sorted(name for name, count in names.items() if count > 1)
        if repeated:
            twice[path.name] = repeated
    assert twice == {}
