"""Eight float64 lanes as one value inside numba-compiled code (an LLVM <8 x double>).

numba vectorises only innermost loops, and only where it can check that the arrays a loop
writes do not overlap those it reads, so a loop that keeps partial sums in registers across
rows, or writes two outputs, stays scalar. With an explicit lane type the kernel holds eight
hypotheses' values in one register and reuses it (core/_kalman). LLVM lowers the type to what
the CPU has: one AVX-512 register, two AVX2 ones, four SSE2/NEON ones.

Only for compiled code: ``vload(a, i)`` and ``vstore(a, i, v)`` read and write a[i:i + W] of a
1-D C-contiguous float64 array without bounds checks (the caller keeps i + W <= len(a));
``vsplat(x)`` has x in every lane; +, -, *, / are lane-wise and may fuse a multiply-add (as the
kernels' fastmath={'contract'}); ``vsqrt`` is the lane-wise square root.
"""

import operator

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, models, overload, register_model

W = 8
_LANES = ir.VectorType(ir.DoubleType(), W)
_CONTRACT = ('contract',)


class _VecType(types.Type):
    def __init__(self):
        super().__init__(name=f'f64x{W}')


vec = _VecType()


@register_model(_VecType)
class _VecModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _LANES)


def _is_row(a):
    return isinstance(a, types.Array) and a.dtype == types.float64 and a.ndim == 1 \
        and a.layout == 'C'


def _lanes_pointer(context, builder, aryty, ary, i):
    data = context.make_array(aryty)(context, builder, ary).data
    return builder.bitcast(builder.gep(data, [i]), _LANES.as_pointer())


@intrinsic
def vload(typingctx, a, i):
    if not (_is_row(a) and isinstance(i, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        return builder.load(_lanes_pointer(context, builder, sig.args[0], args[0], args[1]),
                            align=8)
    return vec(a, i), codegen


@intrinsic
def vstore(typingctx, a, i, v):
    if not (_is_row(a) and isinstance(i, types.Integer) and v == vec):
        return None

    def codegen(context, builder, sig, args):
        builder.store(args[2], _lanes_pointer(context, builder, sig.args[0], args[0], args[1]),
                      align=8)
        return context.get_dummy_value()
    return types.none(a, i, v), codegen


@intrinsic
def vsplat(typingctx, x):
    if not isinstance(x, types.Float):
        return None

    def codegen(context, builder, sig, args):
        x = context.cast(builder, args[0], sig.args[0], types.float64)
        one = builder.insert_element(ir.Constant(_LANES, ir.Undefined), x,
                                     ir.Constant(ir.IntType(32), 0))
        return builder.shuffle_vector(one, one, ir.Constant(ir.VectorType(ir.IntType(32), W),
                                                             [0] * W))
    return vec(x), codegen


@intrinsic
def vsqrt(typingctx, v):
    if v != vec:
        return None

    def codegen(context, builder, sig, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_LANES, [_LANES]),
                                            f'llvm.sqrt.v{W}f64')
        return builder.call(fn, [args[0]])
    return vec(v), codegen


def _lanewise(name):
    @intrinsic
    def op(typingctx, a, b):
        if not (a == vec and b == vec):
            return None

        def codegen(context, builder, sig, args):
            return getattr(builder, name)(args[0], args[1], flags=_CONTRACT)
        return vec(a, b), codegen

    def impl(a, b):
        if a == vec and b == vec:
            return lambda a, b: op(a, b)
    return impl


for _op, _name in ((operator.add, 'fadd'), (operator.sub, 'fsub'), (operator.mul, 'fmul'),
                   (operator.truediv, 'fdiv')):
    overload(_op)(_lanewise(_name))
