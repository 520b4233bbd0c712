"""A number that is ``WIDTH`` scenarios at once, for the batch kernel (:mod:`.compiled`).

:func:`.plant.rk4_period` and :func:`.model.accel`, :func:`.observer.z_next` and the built-in laws' ``pure_step``
(``Law.pure_lanes``) are plain arithmetic on their arguments plus ``m.sin``, ``m.cos`` and ``m.exp``. Compiled by
numba with every per-scenario value a :data:`lanes` (an LLVM ``<WIDTH x double>``: ``+``, ``-``, ``*``, ``/``, unary
``-`` and ``**`` a constant lane by lane, a float or an int mixed in as every lane's value) and ``m`` this module,
the same code integrates ``WIDTH`` scenarios in one pass: the same operations in the same order on each lane, IEEE
arithmetic, no contraction into fused multiply-adds, so each lane's result is the scalar result bit for bit but for
``sin``, ``cos`` and ``exp``. Those are glibc's vector math library (``libmvec``: ``_ZGVeN8v_sin`` and
``_ZGVeN8v_cos`` with AVX-512, the 4-lane AVX2 ones otherwise; glibc documents them within 4 ulp of libm's) instead
of libm's scalar ``sin``/``cos`` (their accuracy and cost here: BENCHMARKS.md, "Measurements moved out of the core's
docstrings"). numba's own vectorizer cannot do this: llvmlite's LLVM has no vector library (SVML) to map ``sin`` to,
so a loop over scenarios stays a loop of scalar calls.

:data:`WIDTH` is 0 (and the batch kernel stays scalar) where there is no libmvec (not glibc, not x86-64) or the
CPU has neither AVX-512F nor AVX2, or when ``MWIP_BATCH_SIMD=0`` (``MWIP_BATCH_SIMD=4``: the AVX2 functions, 4
lanes, even where AVX-512 is there).
"""
from __future__ import annotations

import ctypes.util
import operator
import os

import llvmlite.binding as ll
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.datamodel import models
from numba.core.extending import intrinsic, lower_builtin, register_model
from numba.core.typing.templates import AbstractTemplate, ConcreteTemplate, infer_global, signature

__all__ = ["SIMD_ENV", "WIDTH", "lanes", "load", "store", "sin", "cos", "exp"]

SIMD_ENV = "MWIP_BATCH_SIMD"   # "0": no lanes in the batch kernel (one scenario after another); "4": 4 lanes


def _width() -> int:
    want = os.environ.get(SIMD_ENV, "").strip()
    if want in ("0", "false", "no", "off"):
        return 0
    features = ll.get_host_cpu_features()
    lib = ctypes.util.find_library("mvec")
    if not lib or ll.get_process_triple().split("-")[0] != "x86_64":
        return 0
    try:
        ll.load_library_permanently(lib)   # the JIT resolves the vector sin, cos and exp from it
    except RuntimeError:
        return 0
    best = 8 if features.get("avx512f") else 4 if features.get("avx2") else 0
    return 4 if want == "4" and best else best   # "4": the AVX2 functions even with AVX-512


WIDTH = _width()
_W = WIDTH or 4   # the type exists even when unused (WIDTH 0)
_NAMES = {8: ("_ZGVeN8v_sin", "_ZGVeN8v_cos", "_ZGVeN8v_exp"),
          4: ("_ZGVdN4v_sin", "_ZGVdN4v_cos", "_ZGVdN4v_exp")}[_W]
_VT = ir.VectorType(ir.DoubleType(), _W)


class Lanes(types.Type):
    def __init__(self):
        super().__init__(name=f"float64x{_W}")


lanes = Lanes()


@register_model(Lanes)
class _LanesModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _VT)


def _splat(builder, v):
    vec = builder.insert_element(ir.Constant(_VT, ir.Undefined), v, ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(vec, ir.Constant(_VT, ir.Undefined), ir.Constant(ir.VectorType(ir.IntType(32), _W),
                                                                                    [0] * _W))


for _op, _name in ((operator.add, "fadd"), (operator.sub, "fsub"), (operator.mul, "fmul"),
                   (operator.truediv, "fdiv")):
    @infer_global(_op)
    class _Binary(ConcreteTemplate):
        cases = [signature(lanes, lanes, lanes), signature(lanes, lanes, types.float64),
                 signature(lanes, types.float64, lanes)]

    def _lower(context, builder, sig, args, _name=_name):
        a, b = (v if t == lanes else _splat(builder, context.cast(builder, v, t, types.float64))
                for v, t in zip(args, sig.args))
        return getattr(builder, _name)(a, b)

    for _sig in ((lanes, lanes), (lanes, types.float64), (types.float64, lanes)):
        lower_builtin(_op, *_sig)(_lower)


@infer_global(operator.pow)
class _Pow(AbstractTemplate):
    def generic(self, args, kws):
        if len(args) == 2 and args[0] == lanes and isinstance(args[1], types.IntegerLiteral) \
                and args[1].literal_value >= 0:
            return signature(lanes, *args)


@lower_builtin(operator.pow, Lanes, types.IntegerLiteral)
def _lower_pow(context, builder, sig, args):
    """``x ** n`` for a constant n >= 0: numba's own unrolled product for a float (``static_power_impl``), the
    same multiplications in the same order, lane by lane."""
    exp = sig.args[1].literal_value
    res, val = ir.Constant(_VT, [1.0] * _W), args[0]
    while exp != 0:
        if exp & 1:
            res = builder.fmul(res, val)
        exp >>= 1
        val = builder.fmul(val, val)
    return res


@infer_global(operator.neg)
class _Neg(ConcreteTemplate):
    cases = [signature(lanes, lanes)]


@lower_builtin(operator.neg, lanes)
def _lower_neg(context, builder, sig, args):
    return builder.fneg(args[0])


def _array_ptr(context, builder, aryty, ary, i):
    a = context.make_array(aryty)(context, builder, ary)
    return builder.bitcast(builder.gep(a.data, [i]), _VT.as_pointer())


@intrinsic
def load(typingctx, ary, i):
    """``ary[i : i + WIDTH]`` (a C-contiguous float64 array) as one :data:`lanes`."""
    def codegen(context, builder, sig, args):
        return builder.load(_array_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
    return lanes(ary, types.intp), codegen


@intrinsic
def store(typingctx, ary, i, v):
    """``ary[i : i + WIDTH] = v``."""
    def codegen(context, builder, sig, args):
        builder.store(args[2], _array_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
        return context.get_dummy_value()
    return types.void(ary, types.intp, lanes), codegen


def _vector_call(fname):
    @intrinsic
    def call(typingctx, v):
        if v != lanes:
            return None

        def codegen(context, builder, sig, args):
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_VT, [_VT]), fname)
            return builder.call(fn, [args[0]])
        return lanes(lanes), codegen
    return call


sin, cos, exp = (_vector_call(f) for f in _NAMES)
