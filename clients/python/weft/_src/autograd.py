"""`warp._src.autograd`: Warp's private module of the gradient debugging tools, which Warp's
tests import FunctionMetadata from; the implementation is weft.autograd."""
from ..autograd import (FunctionMetadata, gradcheck, gradcheck_tape, infer_device,  # noqa: F401
                        jacobian, jacobian_fd, jacobian_plot, print_table, zero_grads)

__all__ = ["FunctionMetadata", "gradcheck", "gradcheck_tape", "jacobian", "jacobian_fd",
           "jacobian_plot"]
