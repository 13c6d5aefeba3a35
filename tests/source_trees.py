"""The project's Python sources parsed once per process, for the tests that
read them (the import graph of tests/test_imports.py, the fmpy imports and
calls of tests/engine/test_engine_fmu_log.py): each of them parsed every
module and walked every tree again, about 1-2 s of CPU a test for the same
answer. Keyed by the file's size and time of change (a changed file is read
again). The trees are shared: read them, never change them."""
from __future__ import annotations

import ast
import os
from functools import lru_cache
from pathlib import Path

__all__ = ["tree", "nodes"]


def tree(path: Path) -> ast.Module:
    """``ast.parse`` of the source file ``path``."""
    return _parsed(*_key(path))[0]


def nodes(path: Path) -> tuple[ast.AST, ...]:
    """Every node of :func:`tree` (``path``), in ``ast.walk``'s order."""
    return _parsed(*_key(path))[1]


def _key(path: Path) -> tuple[str, int, int]:
    stat = os.stat(path)
    return os.path.realpath(path), stat.st_mtime_ns, stat.st_size


@lru_cache(maxsize=None)
def _parsed(path: str, mtime_ns: int, size: int) -> tuple[ast.Module, tuple[ast.AST, ...]]:
    module = ast.parse(Path(path).read_text(), path)
    return module, tuple(ast.walk(module))
