"""Language: every Warp spelling of an array annotation compiles to the same parameter type:
wp.array(dtype=T), wp.array(dtype=T, ndim=2), wp.array2d(dtype=T), wp.array[T],
wp.array2d[T]. The bracket forms need weft.array.__class_getitem__ and subscriptable
array1d..array4d (weft/array.py); the kernel is defined inside a function so a missing piece
fails these tests, not the collection of the whole suite."""
import numpy as np

import weft as wp


def _define():
    @wp.kernel
    def spellings(a: wp.array[float], b: wp.array2d[float], c: wp.array(dtype=float, ndim=2),
                  d: wp.array2d(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = a[i] + b[i, 0] + c[i, 1] + d[i, 0]

    return spellings


def test_param_types_of_every_spelling():
    assert _define().param_types == ["array(float32,1)", "array(float32,2)", "array(float32,2)",
                                     "array(float32,2)", "array(float32,1)"]


def test_keyword_spellings():
    @wp.kernel
    def keywords(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=float, ndim=3),
                 c: wp.array4d(dtype=wp.mat22), d: wp.array1d(dtype=int)):
        pass

    assert keywords.param_types == ["array(vec(3,float32),1)", "array(float32,3)",
                                    "array(mat(2,2,float32),4)", "array(int32,1)"]


def test_bracket_annotations_launch(wp, rng):
    spellings = _define()
    a = rng.standard_normal(10).astype(np.float32)
    b = rng.standard_normal((10, 2)).astype(np.float32)
    out = wp.zeros(10, dtype=float)
    wp.launch(spellings, dim=10, inputs=[wp.array(a), wp.array(b), wp.array(b), wp.array(b), out])
    np.testing.assert_allclose(out.numpy(), a + b[:, 0] + b[:, 1] + b[:, 0], rtol=1e-6)
