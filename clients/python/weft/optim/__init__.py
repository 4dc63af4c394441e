"""Gradient-descent optimizers with Warp's interface (warp.optim): Adam and SGD update lists of
weft arrays in place with kernels that run in the daemon on the arrays' own devices.
`import weft.optim` (or `import warp.optim` under the alias) makes them reachable as
weft.optim.Adam / weft.optim.SGD."""
from .adam import Adam
from .sgd import SGD

__all__ = ["Adam", "SGD"]
