"""Warp's logging interface on weft (weft/logger.py): wp.Logger (a Protocol), wp.set_logger /
get_logger, wp.ScopedLogger, wp.ScopedLogLevel, the default logger's streams and formats, the
gating by wp.config.log_level (errors never gated), warnings given once, a custom logger's
warnings pointing at the caller, and the library's own messages (print_launches, module
compiles with wp.config.verbose, its warnings) reaching the active logger. Also wp.force_load
and wp.clear_kernel_cache."""
from __future__ import annotations

import io
import sys
import textwrap
import warnings

import numpy as np
import pytest


class CaptureLogger:
    def __init__(self):
        self.debugs, self.infos, self.warnings, self.errors = [], [], [], []

    def debug(self, message):
        self.debugs.append(message)

    def info(self, message):
        self.infos.append(message)

    def warning(self, message, category=None, stacklevel=1):
        self.warnings.append((message, category))

    def error(self, message):
        self.errors.append(message)


@pytest.fixture
def logger_module(wp):
    from weft import logger

    saved = wp.get_logger()
    level = wp.config.log_level
    yield logger
    wp.set_logger(saved)
    wp.config.log_level = level


def test_protocol_and_set_get(wp, logger_module):
    assert (wp.LOG_DEBUG, wp.LOG_INFO, wp.LOG_WARNING, wp.LOG_ERROR) == (10, 20, 30, 40)
    with pytest.raises(TypeError):
        wp.Logger()
    assert isinstance(wp.get_logger(), logger_module.LoggerBasic)
    capture = CaptureLogger()
    wp.set_logger(capture)
    assert wp.get_logger() is capture
    wp.set_logger(None)
    assert isinstance(wp.get_logger(), logger_module.LoggerBasic)

    class Partial:
        def debug(self, message):
            pass

    class NotCallable(CaptureLogger):
        info = None

    for bad in ("not a logger", Partial(), NotCallable(), 42):
        with pytest.raises(TypeError, match="Logger protocol"):
            wp.set_logger(bad)


def test_scoped_logger_and_level_restore_even_on_errors(wp, logger_module):
    original = wp.get_logger()
    capture = CaptureLogger()
    with wp.ScopedLogger(capture) as scope:
        assert scope.logger is capture and wp.get_logger() is capture
    assert wp.get_logger() is original
    with pytest.raises(RuntimeError, match="boom"):
        with wp.ScopedLogger(capture):
            raise RuntimeError("boom")
    assert wp.get_logger() is original
    wp.set_logger(capture)
    with wp.ScopedLogger(None):
        assert isinstance(wp.get_logger(), logger_module.LoggerBasic)
    assert wp.get_logger() is capture
    outer = CaptureLogger()
    wp.set_logger(outer)
    with wp.ScopedLogger(CaptureLogger()):
        outer.debug = None                # broken meanwhile: restored without validation
    assert wp.get_logger() is outer
    wp.config.log_level = wp.LOG_INFO
    with pytest.raises(RuntimeError):
        with wp.ScopedLogLevel(wp.LOG_ERROR):
            assert wp.config.log_level == wp.LOG_ERROR
            raise RuntimeError("boom")
    assert wp.config.log_level == wp.LOG_INFO


def test_default_logger_streams_and_gating(wp, logger_module, monkeypatch):
    out, err = io.StringIO(), io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setattr(sys, "stderr", err)
    basic = logger_module.LoggerBasic()
    basic.debug("d")
    basic.info("i")
    basic.error("something broke")
    wp.config.log_level = wp.LOG_WARNING
    logger_module.log_debug("hidden debug")
    logger_module.log_info("hidden info")
    wp.config.log_level = wp.LOG_ERROR + 10
    logger_module.log_error("critical failure")     # never gated
    logger_module.log_warning("hidden warning")
    wp.config.log_level = wp.LOG_DEBUG
    logger_module.log_debug("shown debug")
    assert out.getvalue() == "d\ni\nshown debug\n"
    assert err.getvalue() == "Warp Error: something broke\nWarp Error: critical failure\n"


def test_warnings_once_and_user_filters(wp, logger_module, monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    logger_module._warnings_seen.clear()
    with warnings.catch_warnings():
        warnings.resetwarnings()
        logger_module.log_warning("dup warning", category=UserWarning, once=True)
        logger_module.log_warning("dup warning", category=UserWarning, once=True)
        logger_module.log_warning("legacy api", category=DeprecationWarning)
        logger_module.log_warning("legacy api", category=DeprecationWarning)
    assert err.getvalue().count("dup warning") == 1
    assert err.getvalue().count("Warp DeprecationWarning: legacy api") == 1
    err.truncate(0)
    err.seek(0)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        logger_module.LoggerBasic().warning("old API", category=DeprecationWarning)
    assert err.getvalue() == ""


def test_a_custom_loggers_warning_points_at_the_caller(wp, logger_module, tmp_path):
    class WarningsLogger(CaptureLogger):
        def warning(self, message, category=None, stacklevel=1):
            warnings.warn(message, category, stacklevel=stacklevel)

    wp.set_logger(WarningsLogger())
    caller = str(tmp_path / "external_warning_caller.py")
    namespace = {"log_warning": logger_module.log_warning, "UserWarning": UserWarning}
    with warnings.catch_warnings(record=True) as recorded:
        warnings.simplefilter("always", UserWarning)
        exec(compile("log_warning('custom logger warning', category=UserWarning)", caller, "exec"),
             namespace)
    assert len(recorded) == 1 and recorded[0].filename == caller


def test_the_librarys_messages_reach_the_active_logger(wp, logger_module, kernel_module, capsys):
    mod = kernel_module("""
        @wp.kernel
        def logged_kernel(a: wp.array(dtype=float)):
            i = wp.tid()
            a[i] = a[i] + 1.0
    """)
    capture = CaptureLogger()
    wp.set_logger(capture)
    saved = wp.config.print_launches, wp.config.verbose
    try:
        wp.config.print_launches = True
        wp.config.verbose = True
        a = wp.zeros(4, dtype=float, device="cpu")
        wp.launch(mod.logged_kernel, dim=4, inputs=[a], device="cpu")
        with wp.ScopedTimer("timed block"):
            pass
        logger_module._warnings_seen.clear()
        wp.MarchingCubes                  # a deprecated name: a warning through the logger
    finally:
        wp.config.print_launches, wp.config.verbose = saved
    np.testing.assert_array_equal(a.numpy(), np.ones(4, np.float32))
    assert any("kernel: logged_kernel" in m for m in capture.infos), capture.infos
    assert any(m.startswith("Module ") and "took" in m for m in capture.infos), capture.infos
    assert any("timed block took" in m for m in capture.infos), capture.infos
    assert [c for m, c in capture.warnings if "MarchingCubes is deprecated" in m] == [DeprecationWarning]
    assert capsys.readouterr().out == ""      # nothing went around the logger


def test_private_paths_and_kernel_cache_helpers(wp, logger_module, kernel_module):
    from weft._src import build, logger

    assert logger.LoggerBasic is logger_module.LoggerBasic and logger.log_debug is logger_module.log_debug
    assert build.clear_kernel_cache is wp.clear_kernel_cache
    mod = kernel_module("""
        @wp.kernel
        def loaded_early(a: wp.array(dtype=float), s: float):
            i = wp.tid()
            a[i] = a[i] * s
    """)
    kernel = mod.loaded_early
    assert not kernel._compiled
    wp.force_load(device="cpu", modules=[kernel.module])
    assert kernel._compiled                      # compiled before any launch
    a = wp.array(np.arange(8, dtype=np.float32), device="cpu")
    wp.launch(kernel, dim=8, inputs=[a, 3.0], device="cpu")
    np.testing.assert_array_equal(a.numpy(), np.arange(8, dtype=np.float32) * 3)
    wp.clear_kernel_cache()
    assert not kernel._compiled                  # asked of weftd again at the next launch
    wp.launch(kernel, dim=8, inputs=[a, 2.0], device="cpu")
    np.testing.assert_array_equal(a.numpy(), np.arange(8, dtype=np.float32) * 6)
    with pytest.raises(TypeError, match="modules must be"):
        wp.force_load(device="cpu", modules=[42])
