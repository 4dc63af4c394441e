"""The client's optional C accelerators (clients/python/native/, built by CMake against Python's
stable ABI into this package): how a module of them is found. The client does everything they
do in Python too; a module that was not built, or that its environment variable turns off, is
simply absent."""
from __future__ import annotations

import importlib
import os


def optional(name: str, env: str):
    """weft.<name>, or None when it was not built (no Python development headers at build time)
    or `env`=0 turns it off."""
    if os.environ.get(env, "1") == "0":
        return None
    try:
        return importlib.import_module("weft." + name)
    except ImportError:
        return None
