"""The module cache, checked through the daemon's own counters (SessionService.Stats), not
timings: a second client process launching the same kernel hits the memory cache, and a
restarted daemon with the same --cache-dir hits the disk cache."""
import importlib.util
import textwrap
from pathlib import Path


def _load_daemon_class():
    """tests/conftest.py's Daemon (loaded by path: several conftest modules share the name)."""
    path = Path(__file__).resolve().parents[1] / "conftest.py"
    spec = importlib.util.spec_from_file_location("weft_tests_root_conftest", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Daemon


Daemon = _load_daemon_class()

CLIENT = textwrap.dedent('''
    import numpy as np
    import weft as wp

    @wp.kernel
    def cache_probe_kernel(a: wp.array(dtype=float), s: float):
        i = wp.tid()
        a[i] = float(i) * s + 0.123456

    a = wp.zeros(16, dtype=float)
    wp.launch(cache_probe_kernel, dim=16, inputs=[a, 2.0])
    np.testing.assert_allclose(a.numpy(), np.arange(16) * 2.0 + 0.123456, rtol=1e-6)
    print("CLIENT-OK")
''')


def test_second_client_hits_memory_cache(weftd, run_script, tmp_path):
    code = CLIENT
    before = weftd.stats()
    first = run_script(code, filename="cache_probe_client.py")
    assert "CLIENT-OK" in first.stdout
    middle = weftd.stats()
    second = run_script(code, filename="cache_probe_client.py")
    assert "CLIENT-OK" in second.stdout
    after = weftd.stats()
    assert middle.module_cache_misses >= before.module_cache_misses + 1
    assert after.module_cache_misses == middle.module_cache_misses, (middle, after)
    assert after.module_cache_hits >= middle.module_cache_hits + 1, (middle, after)


def test_restarted_daemon_hits_disk_cache(run_script, tmp_path):
    workdir = tmp_path / "daemon"
    workdir.mkdir()
    code = CLIENT
    daemon = Daemon(workdir)
    try:
        run_script(code, env={"WEFT_ADDRESS": daemon.address},
                   filename="cache_probe_client.py")
        first = daemon.stats()
        assert first.module_cache_misses >= 1
    finally:
        assert daemon.stop() == 0
    restarted = Daemon(workdir)      # same workdir -> same --cache-dir
    try:
        run_script(code, env={"WEFT_ADDRESS": restarted.address},
                   filename="cache_probe_client.py")
        stats = restarted.stats()
        assert stats.module_cache_disk_hits >= 1, stats
        assert stats.module_cache_misses == 0, stats
    finally:
        assert restarted.stop() == 0
