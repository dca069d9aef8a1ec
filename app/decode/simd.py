"""Table lookups 16 pixels at a time, written as LLVM vector code (a numba intrinsic).

numba never vectorises a loop that reads float32 tables at data-dependent indices and stores float32 results:
without type-based alias information LLVM must assume a store may change a table, so the loop stays scalar
(about 45 instructions per pixel for the two-shot differences). Here one call loads 16 RGB pixels of both
frames, splits the channels with shuffles and reads the 12 table values of each pixel with gathers (AVX-512 or
AVX2 gather instructions where the CPU has them; LLVM turns them into scalar loads where it has not), with
the same float32 operations in the same order as the scalar loop, so the results are bit-identical.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

LANES = 16  # pixels per call

_F32 = ir.FloatType()
_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
_V = ir.VectorType(_F32, LANES)
_VI = ir.VectorType(_I32, LANES)
_VP = ir.VectorType(_F32.as_pointer(), LANES)
_VB = ir.VectorType(ir.IntType(1), LANES)


def _splat(builder: ir.IRBuilder, value: ir.Value, vtype: ir.VectorType) -> ir.Value:
    v = builder.insert_element(ir.Constant(vtype, ir.Undefined), value, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(vtype, ir.Undefined), ir.Constant(_VI, [0] * LANES))


def _gather(builder: ir.IRBuilder, base: ir.Value, index: ir.Value) -> ir.Value:
    """table[index] for a vector of 16 int32 indices into a float32 table at base."""
    # a GEP with a vector index gives the 16 addresses (llvmlite's GEP types only scalar indices: built with
    # one, then given the vector and its result type)
    gep = builder.gep(base, [ir.Constant(_I32, 0)])
    gep.indices = [index]
    gep.operands = [base, index]
    gep.type = _VP
    mod = builder.module
    fn = cgutils.get_or_insert_function(
        mod, ir.FunctionType(_V, [_VP, _I32, _VB, _V]), f"llvm.masked.gather.v{LANES}f32.v{LANES}p0"
    )
    return builder.call(fn, [gep, ir.Constant(_I32, 4), ir.Constant(_VB, [1] * LANES), ir.Constant(_V, ir.Undefined)])


def _is_row(t: types.Type, dtypes: tuple) -> bool:
    return isinstance(t, types.Array) and t.ndim == 2 and t.layout == "C" and t.dtype in dtypes


def _is_table(t: types.Type) -> bool:
    return isinstance(t, types.Array) and t.ndim == 1 and t.layout == "C" and t.dtype == types.float32


@intrinsic
def differences16(typingctx, a, b, lin, dlin, u00, u01, u02, u10, u11, u12, ta, out, x):
    """Pixels x .. x + 15 of _row_differences: a, b the two frames' rows (W, 3) uint8/uint16, C-contiguous;
    lin, dlin (3 * levels,) float32, the channels' tables one after the other; u the two unmixing rows and
    ta the half noise floor, float32; out (>= 4, W) float32 C-contiguous receives the differences d0, d1 and
    the noise floors n0, n1 in its first four rows. The caller keeps x + 16 <= W."""
    coefs = (u00, u01, u02, u10, u11, u12, ta)
    if not (
        _is_row(a, (types.uint8, types.uint16))
        and b == a
        and _is_table(lin)
        and _is_table(dlin)
        and all(c == types.float32 for c in coefs)
        and isinstance(out, types.Array)
        and out.ndim == 2
        and out.layout == "C"
        and out.dtype == types.float32
        and isinstance(x, types.Integer)
    ):
        return None
    sig = types.void(a, b, lin, dlin, *coefs, out, x)
    elem = ir.IntType(a.dtype.bitwidth)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        xa = context.cast(builder, args[-1], kinds[-1], types.int64)
        arr = [context.make_array(kinds[i])(context, builder, args[i]) for i in (0, 1, 2, 3, 11)]
        pa, pb, plin, pdlin, pout = (ar.data for ar in arr)
        width = builder.extract_value(arr[4].shape, 1)
        # the 16 pixels' 48 channel values of each frame, split into channels and widened to int32 indices
        raw = ir.VectorType(elem, 3 * LANES)
        start = builder.mul(xa, ir.Constant(_I64, 3))
        chans = []
        for p in (pa, pb):
            v = builder.load(builder.bitcast(builder.gep(p, [start]), raw.as_pointer()), align=1)
            per = []
            for c in range(3):
                pick = ir.Constant(_VI, list(range(c, 3 * LANES, 3)))
                per.append(builder.zext(builder.shuffle_vector(v, ir.Constant(raw, ir.Undefined), pick), _VI))
            chans.append(per)
        levels = builder.trunc(builder.udiv(builder.extract_value(arr[2].shape, 0), ir.Constant(_I64, 3)), _I32)
        e = []
        n = []
        for c in range(3):
            off = _splat(builder, builder.mul(levels, ir.Constant(_I32, c)), _VI)
            ia = builder.add(chans[0][c], off)
            ib = builder.add(chans[1][c], off)
            e.append(builder.fsub(_gather(builder, plin, ib), _gather(builder, plin, ia)))
            n.append(builder.fadd(_gather(builder, pdlin, ib), _gather(builder, pdlin, ia)))
        co = [_splat(builder, v, _V) for v in args[4:11]]
        absf = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_V, [_V]), f"llvm.fabs.v{LANES}f32")
        w = [builder.call(absf, [c]) for c in co[:6]]
        ta = co[6]

        def mix(u0, u1, u2, v):  # (u0 v0 + u1 v1) + u2 v2, the scalar loop's order
            return builder.fadd(builder.fadd(builder.fmul(u0, v[0]), builder.fmul(u1, v[1])), builder.fmul(u2, v[2]))

        rows = (
            mix(co[0], co[1], co[2], e),
            mix(co[3], co[4], co[5], e),
            builder.fmul(ta, mix(w[0], w[1], w[2], n)),
            builder.fmul(ta, mix(w[3], w[4], w[5], n)),
        )
        for r, val in enumerate(rows):
            at = builder.add(builder.mul(ir.Constant(_I64, r), width), xa)
            builder.store(val, builder.bitcast(builder.gep(pout, [at]), _V.as_pointer()), align=4)
        return context.get_dummy_value()

    return sig, codegen


GATHER_LANES = 8  # values per gather8 call (8 int64 indices fill one 512-bit register)
_LLVM_NAME = {types.float32: "f32", types.float64: "f64", types.int32: "i32", types.int64: "i64"}


@intrinsic
def gather8(typingctx, dst, table, idx, i):
    """dst[i + l] = table[idx[i + l]] for l < 8, as one vector gather: dst and table 1-D C-contiguous arrays of
    float32/64 or int32/64 (dst of the table's kind, as wide or wider: the values are widened), idx a 1-D
    C-contiguous int32/int64 array. The caller keeps i + 8 <= len(idx), len(dst) and the indices inside the
    table. (numba emits no gathers itself: see the module docstring.)"""

    def is_1d(t):
        return isinstance(t, types.Array) and t.ndim == 1 and t.layout == "C"

    if not (
        is_1d(dst)
        and is_1d(table)
        and is_1d(idx)
        and dst.dtype in _LLVM_NAME
        and table.dtype in _LLVM_NAME
        and isinstance(dst.dtype, types.Float) == isinstance(table.dtype, types.Float)
        and dst.dtype.bitwidth >= table.dtype.bitwidth
        and idx.dtype in (types.int32, types.int64)
        and isinstance(i, types.Integer)
    ):
        return None
    sig = types.void(dst, table, idx, i)
    lanes = GATHER_LANES

    def codegen(context, builder, signature, args):
        kinds = signature.args
        d, t, ix = (context.make_array(kinds[k])(context, builder, args[k]) for k in range(3))
        at = context.cast(builder, args[3], kinds[3], types.int64)
        val_t = context.get_value_type(kinds[1].dtype)
        out_t = context.get_value_type(kinds[0].dtype)
        idx_t = context.get_value_type(kinds[2].dtype)
        vval = ir.VectorType(val_t, lanes)
        vout = ir.VectorType(out_t, lanes)
        vidx = ir.VectorType(idx_t, lanes)
        index = builder.load(builder.bitcast(builder.gep(ix.data, [at]), vidx.as_pointer()), align=idx_t.width // 8)
        index = builder.sext(index, ir.VectorType(_I64, lanes)) if idx_t.width < 64 else index
        vptr = ir.VectorType(val_t.as_pointer(), lanes)
        gep = builder.gep(t.data, [ir.Constant(_I64, 0)])
        gep.indices = [index]
        gep.operands = [t.data, index]
        gep.type = vptr
        vmask = ir.VectorType(ir.IntType(1), lanes)
        name = _LLVM_NAME[kinds[1].dtype]
        fn = cgutils.get_or_insert_function(
            builder.module,
            ir.FunctionType(vval, [vptr, _I32, vmask, vval]),
            f"llvm.masked.gather.v{lanes}{name}.v{lanes}p0",
        )
        align = ir.Constant(_I32, kinds[1].dtype.bitwidth // 8)
        got = builder.call(fn, [gep, align, ir.Constant(vmask, [1] * lanes), ir.Constant(vval, ir.Undefined)])
        if kinds[0].dtype != kinds[1].dtype:
            float_ = isinstance(kinds[0].dtype, types.Float)
            got = builder.fpext(got, vout) if float_ else builder.sext(got, vout)
        builder.store(got, builder.bitcast(builder.gep(d.data, [at]), vout.as_pointer()), align=1)
        return context.get_dummy_value()

    return sig, codegen
