"""Submodules of a package that re-exports weft under another name.

A Warp program runs on weft by changing its import; a program that keeps `import warp` gets there
through a small `warp` package that re-exports weft (`from weft import *` and weft's other
attributes, `_weft_reexport_of_` among them). Such a package has weft's attributes but not its
submodules: `import warp.utils` or `import warp.geometry` would find nothing, or load a second,
separate copy of the file. This finder gives the importing package weft's own module instead:
`<alias>.utils` is `weft.utils`, one module and one state. Warp's private module names
(`<alias>._src.X`) resolve to weft's `weft._src.X` where weft has one (weft/_src/).

It sits last on `sys.meta_path`, so a module the alias package itself provides always wins, and it
answers only for packages that carry the marker.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

MARKER = "_weft_reexport_of_"


class _ExistingModuleLoader(importlib.abc.Loader):
    """Loads an alias name as the already-importable weft module."""

    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        return importlib.import_module(self.target)

    def exec_module(self, module):
        pass  # the weft module ran when it was imported under its own name


class WeftAliasFinder(importlib.abc.MetaPathFinder):
    """Maps `<alias>.<rest>` to `weft.<rest>` for packages marked as re-exports of weft."""

    def find_spec(self, fullname, path=None, target=None):
        root, dot, rest = fullname.partition(".")
        if not dot or root == "weft":
            return None
        package = sys.modules.get(root)
        if package is None or getattr(package, MARKER, None) != "weft":
            return None
        target_name = "weft." + rest
        try:
            found = importlib.util.find_spec(target_name)
        except (ImportError, ValueError):
            return None
        if found is None:
            return None
        return importlib.util.spec_from_loader(fullname, _ExistingModuleLoader(target_name),
                                               is_package=found.submodule_search_locations is not None)


def install() -> None:
    if not any(isinstance(f, WeftAliasFinder) for f in sys.meta_path):
        sys.meta_path.append(WeftAliasFinder())
