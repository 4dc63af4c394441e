"""How a module's kernels are split into builds (weft/_kernel/module.py, _partition_groups):
kernels made per dtype from one factory (a name bound to another type in each) and kernels
with their own enable_backward option are compiled once per build group, whichever kernel is
launched first, and each still computes its own result (float64 reference, random data)."""
from __future__ import annotations

import numpy as np

SOURCE = '''
DTYPES = (wp.float32, wp.float64, wp.int32)
kernels = {}


def make(dtype):
    vec3 = wp.types.vector(length=3, dtype=dtype)

    def scale_fn(a: wp.array(dtype=vec3), out: wp.array(dtype=dtype)):
        i = wp.tid()
        v = vec3(dtype(2)) + a[i]
        out[i] = v[0] + v[1] + v[2]

    def negate_fn(a: wp.array(dtype=dtype), out: wp.array(dtype=dtype)):
        i = wp.tid()
        out[i] = -a[i]

    name = dtype.__name__
    kernels["scale", name] = wp.Kernel(func=scale_fn, key="scale_" + name,
                                       options={"enable_backward": dtype is not wp.int32})
    kernels["negate", name] = wp.Kernel(func=negate_fn, key="negate_" + name,
                                        options={"enable_backward": False})


for t in DTYPES:
    make(t)
'''


def test_kernels_of_one_factory_build_once_per_group(wp, kernel_module, rng, device):
    from weft._kernel import module as module_mod

    mod = kernel_module(SOURCE)
    # one build message per group, whichever kernel asks
    messages = {}
    for (kind, name), k in mod.kernels.items():
        msg, _ = module_mod.build_module_source(k)
        messages.setdefault(module_mod.content_hash(msg), set()).add((kind, name))
    # scale_fn binds `vec3` to another type per dtype: three groups, each holding one scale
    # kernel; a negate kernel joins the first group without a kernel of its name
    assert len(messages) == 3, messages
    for members in messages.values():
        assert len({name for _kind, name in members if _kind == "scale"}) == 1
    # kernel-level enable_backward does not split a build (the daemon generates adjoints
    # only when a backward pass needs them)
    msg, _ = module_mod.build_module_source(mod.kernels["negate", "float32"])
    assert "enable_backward" not in msg.options

    for (kind, name), k in mod.kernels.items():
        dtype = getattr(wp, name)
        np_t = np.dtype(wp.types.dtype_to_numpy(dtype))
        n = 17
        if kind == "scale":
            x = rng.uniform(0.5, 2.0, size=(n, 3)) if np_t.kind == "f" else \
                rng.integers(1, 50, size=(n, 3))
            a = wp.array(x.astype(np_t), dtype=wp.types.vector(3, dtype), device=device)
            ref = 6.0 + x.astype(np_t).astype(np.float64).sum(axis=1)
        else:
            x = rng.uniform(0.5, 2.0, size=n) if np_t.kind == "f" else rng.integers(1, 50, size=n)
            a = wp.array(x.astype(np_t), dtype=dtype, device=device)
            ref = -x.astype(np_t).astype(np.float64)
        out = wp.zeros(n, dtype=dtype, device=device)
        wp.launch(k, dim=n, inputs=[a, out], device=device)
        tol = 1e-12 if np_t == np.float64 else 1e-5
        np.testing.assert_allclose(out.numpy().astype(np.float64), ref, rtol=tol)

    # six launches, three builds: each group's message was compiled,
    built = {digest for (_rt, digest, dev) in module_mod.compiled_modules() if dev == device}
    assert set(messages) <= built


def test_backward_of_a_group_member(wp, kernel_module, rng, device):
    mod = kernel_module(SOURCE)
    n = 9
    x = rng.uniform(0.5, 2.0, size=(n, 3))
    a = wp.array(x, dtype=wp.types.vector(3, wp.float64), device=device, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(mod.kernels["scale", "float64"], dim=n, inputs=[a, out], device=device)
    tape.backward(grads={out: wp.array(np.ones(n), dtype=wp.float64, device=device)})
    np.testing.assert_allclose(a.grad.numpy(), np.ones((n, 3)), rtol=1e-12)


BROKEN_SOURCE = '''
@wp.kernel
def fine_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] * 3.0


@wp.kernel
def broken_kernel(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = wp.no_such_builtin(a[i])
'''


def _check_triples(wp, kernel, rng, device, n):
    """Launches `kernel` (out[i] = 3 * a[i]) on random data; returns its input array."""
    x = rng.uniform(-2.0, 2.0, size=n)
    a = wp.array(x, dtype=float, device=device)
    out = wp.zeros(n, dtype=float, device=device)
    wp.launch(kernel, dim=n, inputs=[a, out], device=device)
    np.testing.assert_allclose(out.numpy(), 3.0 * x.astype(np.float32), rtol=1e-6)
    return a


def test_module_load_leaves_out_a_kernel_that_does_not_compile(wp, kernel_module, rng, device):
    import pytest
    from weft._kernel.errors import WeftCompileError

    mod = kernel_module(BROKEN_SOURCE)
    mod.fine_kernel.module.load(device)          # the broken kernel does not stop the load
    assert mod.broken_kernel.broken and not mod.fine_kernel.broken
    a = _check_triples(wp, mod.fine_kernel, rng, device, 11)
    # launching the broken kernel raises its own error, with its line
    with pytest.raises(WeftCompileError, match="no_such_builtin"):
        wp.launch(mod.broken_kernel, dim=11, inputs=[a], device=device)


UNIQUE_SOURCE = '''
@wp.kernel
def triple(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 3.0 * a[i]


@wp.kernel(module="unique")
def unique_broken(a: wp.array(dtype=float)):
    wp.printf("%d %d\\n", 1)          # a format that does not match its arguments
'''


def test_load_module_leaves_out_unique_kernels(wp, kernel_module, rng, device):
    """A module="unique" kernel has a module of its own (as in Warp): loading the file's module
    neither builds it nor fails on it; its own module's load raises its error."""
    import pytest
    from weft._kernel.errors import WeftCompileError

    mod = kernel_module(UNIQUE_SOURCE)
    wp.load_module(mod, device=device)
    _check_triples(wp, mod.triple, rng, device, 7)
    with pytest.raises(WeftCompileError, match="printf"):
        mod.unique_broken.module.load(device)


def test_module_named_with_any_characters(wp, kernel_module, rng):
    """wp.get_module(name) with a name that is no dotted Python name (Warp's tests key
    isolated modules as "pkg.<locals>.f:150"): the daemon gets a sanitized name, and two such
    names stay two modules."""
    mod = kernel_module('''
def scale_fn(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] * 3.0

def shift_fn(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] + 1.0

scale = wp.Kernel(func=scale_fn, module=wp.get_module("pkg.f.<locals>.scale_fn:150"))
shift = wp.Kernel(func=shift_fn, module=wp.get_module("pkg.f.<locals>.scale_fn:151"))
''')
    x = rng.uniform(-2.0, 2.0, 16)
    a = wp.array(x.astype(np.float32), dtype=float)
    out = wp.zeros(16, dtype=float)
    wp.launch(mod.scale, 16, inputs=[a], outputs=[out])
    np.testing.assert_allclose(out.numpy(), x.astype(np.float32).astype(np.float64) * 3.0, rtol=1e-6)
    wp.launch(mod.shift, 16, inputs=[a], outputs=[out])
    np.testing.assert_allclose(out.numpy(), x.astype(np.float32).astype(np.float64) + 1.0, rtol=1e-6)
