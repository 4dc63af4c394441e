"""weft.v1's message modules are generated on first import when a checkout has none (no `make
proto-py` yet). The generator (grpc_tools' protoc) carries a protobuf library of its own, so it
runs in a child process: loaded into the client's process next to another extension's protobuf
(Paddle's), the process aborts. Checked on a copy of the client package and proto/ without the
generated modules: the import generates them, grpc_tools' compiler never enters the process,
and (when Paddle is installed) `import weft, paddle` works."""
import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture
def bare_checkout(tmp_path):
    if importlib.util.find_spec("grpc_tools") is None:
        pytest.skip("grpcio-tools is not installed: nothing can generate the modules")
    client = tmp_path / "clients" / "python"
    shutil.copytree(REPO / "clients" / "python" / "weft", client / "weft",
                    ignore=shutil.ignore_patterns("*_pb2.py", "*_pb2_grpc.py", "__pycache__"))
    shutil.copytree(REPO / "proto", tmp_path / "proto")
    assert not list((client / "weft" / "v1").glob("*_pb2.py"))
    return client


def _run(client, code):
    return subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {str(client)!r})\n" + code],
                          capture_output=True, text=True, timeout=300)


def test_first_import_generates_the_modules_in_a_child_process(bare_checkout):
    out = _run(bare_checkout, "import weft, weft.v1.exec_pb2 as e\n"
                              "print(sorted(m for m in sys.modules if m.startswith('grpc_tools')))\n"
                              "print(e.SubmitRequest(run=True).run)")
    assert out.returncode == 0, out.stderr[-2000:]
    assert "grpc_tools._protoc_compiler" not in out.stdout and "True" in out.stdout, out.stdout
    assert (bare_checkout / "weft" / "v1" / "exec_pb2.py").exists()


def test_weft_and_paddle_import_together_on_a_bare_checkout(bare_checkout):
    if importlib.util.find_spec("paddle") is None:
        pytest.skip("Paddle is not installed")
    out = _run(bare_checkout, "import weft, paddle\nprint('both')")
    assert out.returncode == 0 and "both" in out.stdout, (out.returncode, out.stderr[-2000:])
