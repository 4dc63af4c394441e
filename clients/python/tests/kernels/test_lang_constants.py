"""Language: constants resolved by the client: wp.constant of scalars and vectors, plain module
ints/floats/bools, math.pi, constants of another module (mymod.N), closure
constants, and typed constants (wp.float64, wp.uint8)."""
import math

import numpy as np

import kernel_consts as mymod
import weft as wp

SIZE = wp.constant(16)
DAMPING = wp.constant(0.25)
OFFSET = wp.constant(wp.vec3(1.0, 2.0, 3.0))
ENABLED = True
PRECISE = wp.constant(wp.float64(1.0000000001))
SMALL = wp.constant(wp.uint8(200))

params = math                            # a module alias: params.e


@wp.kernel
def use_constants(out: wp.array(dtype=float, ndim=2), dout: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i, 0] = float(SIZE) * DAMPING
    out[i, 1] = OFFSET[0] + OFFSET[1] + OFFSET[2]
    if ENABLED:
        out[i, 2] = math.pi
    out[i, 3] = params.e
    out[i, 4] = float(SMALL)
    dout[i] = PRECISE * wp.float64(2.0)
    out[i, 5] = float(mymod.N) * mymod.SCALE


def test_constants(wp):
    out = wp.zeros((4, 6), dtype=float)
    dout = wp.zeros(4, dtype=wp.float64)
    wp.launch(use_constants, dim=4, outputs=[out, dout])
    ref = np.array([16 * 0.25, 6.0, math.pi, math.e, 200.0, 1.5], dtype=np.float32)
    np.testing.assert_allclose(out.numpy(), np.tile(ref, (4, 1)), rtol=1e-7)
    np.testing.assert_array_equal(dout.numpy(), np.full(4, 1.0000000001 * 2.0))


def test_closure_constant(wp):
    scale = 3.5

    @wp.kernel
    def closure(out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = float(i) * scale

    out = wp.zeros(8, dtype=float)
    wp.launch(closure, dim=8, outputs=[out])
    np.testing.assert_allclose(out.numpy(), np.arange(8) * 3.5)
