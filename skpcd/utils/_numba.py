"""Arrays without reference counting, for the hot loops of numba kernels.

numba counts references to arrays atomically. Passing an array to an
inlined helper or binding it to another name inside a loop costs a pair
of atomic updates each time; with several threads working on the same
arrays these updates fight over one cache line. In the neighbour search
they took a third of the time and kept two threads from running faster
than one.

:func:`borrow` returns the same array (same data, shape and strides) with
no reference count: numba's increments and decrements on it are no-ops.
The borrowed array must not outlive its owner. A kernel borrows its
arguments (the caller holds them until the kernel returns) and the scratch
arrays it allocates itself, which it keeps alive to its end with
:func:`keep`.
"""

from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["borrow", "keep"]


@intrinsic
def borrow(typingctx, arr):
    """The array ``arr`` without a reference count (nopython mode only)."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        src = context.make_array(arr)(context, builder, value=args[0])
        out = context.make_array(arr)(context, builder)
        out.data = src.data
        out.shape = src.shape
        out.strides = src.strides
        out.itemsize = src.itemsize
        out.nitems = src.nitems
        out.meminfo = cgutils.get_null_value(out.meminfo.type)
        out.parent = cgutils.get_null_value(out.parent.type)
        return out._getvalue()

    return arr(arr), codegen


@intrinsic
def keep(typingctx, arr):
    """Use ``arr`` here: numba frees an array after its last use, so a
    scratch array whose borrowed views are used to the end of a kernel is
    kept alive by ``keep(scratch)`` at the end (nopython mode only)."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return types.none(arr), codegen
