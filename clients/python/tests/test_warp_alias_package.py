"""A package that re-exports weft under another name (a `warp` package made of `from weft import
*`, as users keep `import warp` working): its submodules are weft's own modules (one module, one
state), Warp's private module names resolve where weft has them, a module the package provides
itself wins, and an unmarked package gets nothing. Also the kernel side: a constant reached
through a user's package under the alias name (`warp.tests.helpers.CONST`) is that constant."""
import textwrap

ALIAS_INIT = """
import weft as _weft
from weft import *  # noqa: F401,F403
for _k in dir(_weft):
    if not _k.startswith("__"):
        globals()[_k] = getattr(_weft, _k)
"""


def _make_alias(tmp_path, name="warp", marked=True):
    pkg = tmp_path / name
    (pkg / "helpers").mkdir(parents=True)
    init = ALIAS_INIT if marked else "import weft as _weft\nfrom weft import *  # noqa: F401,F403\n"
    (pkg / "__init__.py").write_text(init)
    (pkg / "helpers" / "__init__.py").write_text("")
    (pkg / "helpers" / "consts.py").write_text("import warp as wp\nMINUS_SEVEN = wp.constant(-7)\n")
    (pkg / "ownmod.py").write_text("WHO = 'the package itself'\n")
    return pkg


def test_submodules_of_an_alias_package_are_weft_modules(tmp_path, run_client, client_env):
    _make_alias(tmp_path)
    env = client_env({"PYTHONPATH": f"{tmp_path}:{client_env({})['PYTHONPATH']}"})
    code = textwrap.dedent("""
        import weft, weft.utils, weft.geometry, weft.examples
        import warp.utils, warp.geometry, warp.examples, warp.ownmod
        from warp.utils import array_sum
        from warp._src.utils import check_p2p
        assert warp.utils is weft.utils and array_sum is weft.utils.array_sum
        assert warp.geometry is weft.geometry
        assert warp.ownmod.WHO == 'the package itself'    # the package's own module wins
        assert warp.examples.get_asset_directory().endswith('assets')
        assert check_p2p() in (True, False)
        from warp._src.codegen import codegen_func_forward
        try:
            codegen_func_forward(None)
        except NotImplementedError as e:
            assert 'daemon' in str(e)
        else:
            raise AssertionError('codegen_func_forward must refuse')
        try:
            import warp.no_such_module  # noqa: F401
        except ModuleNotFoundError:
            pass
        else:
            raise AssertionError('an unknown submodule must not import')
        print('ok')
    """)
    assert run_client(code, env=env).stdout.strip().endswith("ok")


def test_an_unmarked_package_gets_no_weft_submodules(tmp_path, run_client, client_env):
    _make_alias(tmp_path, name="notweft", marked=False)
    env = client_env({"PYTHONPATH": f"{tmp_path}:{client_env({})['PYTHONPATH']}"})
    code = textwrap.dedent("""
        import notweft
        try:
            import notweft.utils  # noqa: F401
        except ModuleNotFoundError:
            print('ok')
    """)
    assert run_client(code, env=env).stdout.strip().endswith("ok")


def test_kernel_constant_through_a_user_package_under_the_alias(tmp_path, run_client, client_env):
    _make_alias(tmp_path)
    (tmp_path / "user_kernel.py").write_text(textwrap.dedent("""
        import warp as wp
        import warp.helpers.consts

        @wp.kernel
        def k(out: wp.array(dtype=int), h: wp.array(dtype=wp.handle)):
            out[0] = 10 + warp.helpers.consts.MINUS_SEVEN
            h[0] = h[0] * wp.uint64(0xFF51AFD7ED558CCD)   # a literal above int64's range
    """))
    env = client_env({"PYTHONPATH": f"{tmp_path}:{client_env({})['PYTHONPATH']}"})
    code = textwrap.dedent("""
        import numpy as np
        import warp as wp
        import user_kernel
        out = wp.zeros(1, dtype=int)
        h = wp.array(np.array([3], dtype=np.uint64), dtype=wp.handle)
        wp.launch(user_kernel.k, dim=1, inputs=[out, h])
        assert out.numpy()[0] == 3, out.numpy()
        assert int(h.numpy()[0]) == (3 * 0xFF51AFD7ED558CCD) % 2**64, h.numpy()
        print('ok')
    """)
    assert run_client(code, env=env).stdout.strip().endswith("ok")
