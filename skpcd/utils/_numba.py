"""Arrays without reference counting, for the hot loops of numba kernels.

numba counts references to arrays atomically. Passing an array to an
inlined helper or binding it to another name inside a loop costs a pair
of atomic updates each time; with several threads working on the same
arrays these updates fight over one cache line. In the neighbour search
they took a third of the time and kept two threads from running faster
than one.

:func:`borrow` returns the same arrays (same data, shape and strides) with
no reference count: numba's increments and decrements on them are no-ops.
A borrowed array must not outlive its owner. A kernel borrows its
arguments (the caller holds them until the kernel returns) and the scratch
arrays it allocates itself, which it keeps alive to its end with
:func:`keep`. :func:`counted` is :func:`borrow` with the reference counts
left on, for measuring what borrowing saves
(``benchmarks/bench_borrow.py``).
"""

from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["borrow", "counted", "keep"]


def _same_arrays(arrs, count):
    """The signature and code of :func:`borrow` and :func:`counted`: each
    argument an array or a tuple of arrays (such as a
    :class:`~skpcd.neighbors._grid.VoxelGrid`), returned as it is, several
    as a tuple; ``count(context, builder, arr, value)`` gives each array's
    value out."""
    if not arrs or not all(_of_arrays(a) for a in arrs):
        return None
    ret = arrs[0] if len(arrs) == 1 else types.Tuple(arrs)

    def each(context, builder, typ, value):
        if isinstance(typ, types.Array):
            return count(context, builder, typ, value)
        members = cgutils.unpack_tuple(builder, value)
        members = [count(context, builder, t, v) for t, v in zip(typ, members)]
        return context.make_tuple(builder, typ, members)

    def codegen(context, builder, signature, args):
        values = cgutils.unpack_tuple(builder, args[0])
        outs = [each(context, builder, a, v) for a, v in zip(arrs, values)]
        if len(outs) == 1:
            return outs[0]
        return context.make_tuple(builder, ret, outs)

    return ret(types.StarArgTuple.from_types(arrs)), codegen


def _of_arrays(typ):
    """Whether ``typ`` is an array type or a non-empty tuple of them."""
    if isinstance(typ, types.Array):
        return True
    return (
        isinstance(typ, types.BaseTuple)
        and len(typ) > 0
        and all(isinstance(t, types.Array) for t in typ)
    )


def _uncounted(context, builder, arr, value):
    src = context.make_array(arr)(context, builder, value=value)
    out = context.make_array(arr)(context, builder)
    out.data = src.data
    out.shape = src.shape
    out.strides = src.strides
    out.itemsize = src.itemsize
    out.nitems = src.nitems
    out.meminfo = cgutils.get_null_value(out.meminfo.type)
    out.parent = cgutils.get_null_value(out.parent.type)
    return out._getvalue()


def _counted(context, builder, arr, value):
    # an intrinsic returns a new reference
    context.nrt.incref(builder, arr, value)
    return value


@intrinsic
def borrow(typingctx, *arrs):
    """The arrays ``arrs`` without a reference count (nopython mode only):
    ``a = borrow(a)``, or ``a, b = borrow(a, b)`` for several; a tuple of
    arrays (a :class:`~skpcd.neighbors._grid.VoxelGrid`) comes back as the
    same tuple of borrowed arrays."""
    return _same_arrays(arrs, _uncounted)


@intrinsic
def counted(typingctx, *arrs):
    """:func:`borrow` with the reference counts kept: the arrays ``arrs``
    themselves (nopython mode only)."""
    return _same_arrays(arrs, _counted)


@intrinsic
def keep(typingctx, *arrs):
    """Use the arrays ``arrs`` here: numba frees an array after its last
    use, so a scratch array whose borrowed views are used to the end of a
    kernel is kept alive by ``keep(scratch)`` at the end (nopython mode
    only)."""
    if not arrs or not all(isinstance(a, types.Array) for a in arrs):
        return None

    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return types.none(types.StarArgTuple.from_types(arrs)), codegen
