"""Fixtures of the kernel tests: fresh random data (seed printed so a failure can be
replayed with WEFT_TEST_SEED), the launch device, `kernel_module` which writes kernel
source to a temp file and imports it (for tests that generate one kernel per builtin), and
`run_script` which runs a client program from a file in a child process (kernels need their
source in a file, so `python -c` clients cannot define kernels)."""
from __future__ import annotations

import importlib.util
import os
import subprocess
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


TEST_DEVICES = [d.strip() for d in os.environ.get("WEFT_TEST_DEVICES", "cpu,cuda:0").split(",")
                if d.strip()]


@pytest.fixture(params=TEST_DEVICES, autouse=True)
def device(request, wp):
    """The device of every kernel test: each runs on `cpu` and on `cuda:0` as the default
    device (skipped with the reason when the daemon has no GPU it can run kernels on); tests
    that name a device keep it. WEFT_TEST_DEVICES narrows the list (e.g. "cpu")."""
    name = request.param
    if name.startswith("cuda"):
        if not any(d.is_cuda and d.is_compute_supported and d.alias == name
                   for d in wp.get_cuda_devices()):
            pytest.skip(f"weftd has no CUDA device {name} it can run kernels on")
    with wp.ScopedDevice(name):
        yield name


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


CLIENT_DIR = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


@pytest.fixture
def run_script(weftd, tmp_path):
    """run_script(code, env=None, timeout=120, check=True, filename=None) -> CompletedProcess
    of a child client running `code` from a file (connected to the `weftd` fixture's daemon
    unless env sets WEFT_ADDRESS). Give the same filename to run the same file again (kernel
    modules include the file path, so the same file means the same module)."""
    counter = [0]

    def run(code: str, env: dict | None = None, timeout: float = 120, check: bool = True,
            filename: str | None = None):
        counter[0] += 1
        path = tmp_path / (filename or f"client_{counter[0]}.py")
        path.write_text(textwrap.dedent(code))
        child_env = dict(os.environ)
        child_env["PYTHONPATH"] = os.pathsep.join(
            [CLIENT_DIR] + ([child_env["PYTHONPATH"]] if child_env.get("PYTHONPATH") else []))
        child_env["PYTHONUNBUFFERED"] = "1"
        for key, value in (env or {}).items():
            if value is None:
                child_env.pop(key, None)
            else:
                child_env[key] = str(value)
        proc = subprocess.run([sys.executable, str(path)], env=child_env, capture_output=True,
                              text=True, timeout=timeout)
        if check:
            assert proc.returncode == 0, (f"child client failed ({proc.returncode}):\n"
                                          f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
        return proc

    return run
