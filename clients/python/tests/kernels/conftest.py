"""Fixtures of the kernel tests: fresh random data (seed printed so a failure can be
replayed with WEFT_TEST_SEED), the launch device, and `kernel_module` which writes kernel
source to a temp file and imports it (for tests that generate one kernel per builtin)."""
from __future__ import annotations

import importlib.util
import os
import sys
import textwrap
import uuid

import numpy as np
import pytest


@pytest.fixture
def rng(request):
    seed = int(os.environ.get("WEFT_TEST_SEED", "0")) or int.from_bytes(os.urandom(4), "little")
    print(f"{request.node.nodeid}: WEFT_TEST_SEED={seed}")
    return np.random.default_rng(seed)


@pytest.fixture
def device(wp):
    return "cpu"


@pytest.fixture
def kernel_module(tmp_path):
    """kernel_module(source) -> the imported module (source gets `import weft as wp`)."""

    def load(source: str, name: str | None = None):
        name = name or f"weft_gen_{uuid.uuid4().hex[:12]}"
        path = tmp_path / f"{name}.py"
        path.write_text("import math\nimport typing\nimport weft as wp\n\n" +
                        textwrap.dedent(source))
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module

    return load
