"""Table lookups as explicit vector gathers, and appends as compressed stores (numba intrinsics that emit LLVM
vector IR).

numba never vectorises a loop that reads a table at data-dependent indices and stores into another array:
without type-based alias information LLVM must assume a store may change the table, so the loop stays scalar.
`differences16` loads 16 RGB pixels of both frames, splits the channels with shuffles and reads each pixel's 12
table values with `llvm.masked.gather`, with the same float32 operations in the same order as the scalar loop,
so the results are bit-identical.
`gather8` is the general form (8 values into a plain row), after which the compiler vectorises the
arithmetic itself. `run_bounds16` appends a row's run starts and ends, and `append_where16` the positions of
nonzero flags, by compressing vectors (`llvm.experimental.vector.compress`) and storing them whole (a loop
that appends carries its count from element to element and is never vectorised); `fill8` stores one value
eight times as one vector.

The code is chosen per compile target, when numba compiles: on AVX-512 gathers and compresses are single
instructions. Without AVX-512 the gathers are loads lane by lane, each from its 32-bit index. An AVX2 target
without AVX-512 has no compress, which LLVM would expand into one store per lane; there the appends move the
kept lanes first with AVX2's variable permute (`vpermd`), their order read from a 256-entry table indexed by the
lane mask (`_append_permuted`). Other targets get LLVM's generic expansion.
Every path gives the same results (the golden tests pass built for the host, for AVX2 with
`NUMBA_CPU_NAME=haswell` and `NUMBA_CPU_FEATURES` set to Haswell's features — the CPU name alone keeps the host's
AVX-512 — and for a generic x86-64). What they gain: docs/performance.md.

The calls are written in LLVM's four-argument form (pointers, alignment, mask, pass-through); LLVM 22 drops the
alignment operand and upgrades such calls itself. numba's cache is keyed by the sources of every module that uses
numba (core/jit.py), so edits here reach the kernels that inline these intrinsics.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from core.jit import target_features  # (also sets numba's vector width, before anything compiles)

LANES = 16  # pixels per differences16 call
_LLVM_NAME = {types.float32: "f32", types.float64: "f64", types.int32: "i32", types.int64: "i64"}

_F32 = ir.FloatType()
_I32 = ir.IntType(32)
_I64 = ir.IntType(64)
_I8 = ir.IntType(8)
_I16 = ir.IntType(16)
_PICK8 = ir.VectorType(_I32, 8)  # shuffle indices that pick 8 lanes
_V = ir.VectorType(_F32, LANES)
_VI = ir.VectorType(_I32, LANES)


def _splat(builder: ir.IRBuilder, value: ir.Value, vtype: ir.VectorType) -> ir.Value:
    v = builder.insert_element(ir.Constant(vtype, ir.Undefined), value, ir.Constant(_I32, 0))
    pick = ir.Constant(ir.VectorType(_I32, vtype.count), [0] * vtype.count)
    return builder.shuffle_vector(v, ir.Constant(vtype, ir.Undefined), pick)


def _positions(builder: ir.IRBuilder, x: ir.Value, elem: ir.IntType = _I64) -> ir.Value:
    """The vector x, x + 1, ..., x + LANES - 1 of elem (int64 or int32: x truncated) (the positions of the lanes
    of a block at x)."""
    v = ir.VectorType(elem, LANES)
    x = builder.trunc(x, elem) if elem.width < x.type.width else x
    return builder.add(_splat(builder, x, v), ir.Constant(v, list(range(LANES))))


def _masked_gather(builder: ir.IRBuilder, base: ir.Value, index: ir.Value, value: ir.Type, name: str) -> ir.Value:
    """base[index] for a vector index (all lanes on): a vector of `value`; name is LLVM's type suffix (f32...)."""
    lanes = index.type.count
    if "avx512f" not in target_features():
        # LLVM expands the gather into scalar loads here anyway, but from 64-bit addresses it first builds as
        # vectors; loads from each lane's 32-bit index are cheaper (docs/performance.md) and read the same values
        out = ir.Constant(ir.VectorType(value, lanes), ir.Undefined)
        for i in range(lanes):
            at = builder.extract_element(index, ir.Constant(_I32, i))
            out = builder.insert_element(out, builder.load(builder.gep(base, [at])), ir.Constant(_I32, i))
        return out
    vptr = ir.VectorType(value.as_pointer(), lanes)
    # a GEP with a vector index gives the lanes' addresses; llvmlite's GEP types only scalar indices, so it is
    # built with one and then given the vector and its result type (llvmlite internals, checked by the tests)
    gep = builder.gep(base, [ir.Constant(index.type.element, 0)])
    gep.indices = [index]
    gep.operands = [base, index]
    gep.type = vptr
    vval = ir.VectorType(value, lanes)
    vmask = ir.VectorType(ir.IntType(1), lanes)
    fn = cgutils.get_or_insert_function(
        builder.module,
        ir.FunctionType(vval, [vptr, _I32, vmask, vval]),
        f"llvm.masked.gather.v{lanes}{name}.v{lanes}p0",
    )
    align = ir.Constant(_I32, int(name[1:]) // 8)
    return builder.call(fn, [gep, align, ir.Constant(vmask, [1] * lanes), ir.Constant(vval, ir.Undefined)])


def compress_by_permute() -> bool:
    """Whether appends use AVX2's variable permute with a table of lane orders: an AVX2 target without AVX-512."""
    f = target_features()
    return "avx2" in f and "avx512f" not in f


_V8 = ir.VectorType(_I32, 8)


def _lane_orders(module: ir.Module, pairs: bool) -> ir.GlobalVariable:
    """The module's constant table of lane orders: entry m lists the set lanes of mask m first, in order (8 int32
    lanes, 256 masks; with pairs 4 int64 lanes as int32 pairs, 16 masks); the rest are 0 (stored, never counted)."""
    name = "slscan.lane_orders64" if pairs else "slscan.lane_orders32"
    if name in module.globals:
        return module.globals[name]
    rows = []
    for m in range(16 if pairs else 256):
        if pairs:
            order = [i for q in range(4) if m >> q & 1 for i in (2 * q, 2 * q + 1)]
        else:
            order = [q for q in range(8) if m >> q & 1]
        rows.append(ir.Constant(_V8, order + [0] * (8 - len(order))))
    table_t = ir.ArrayType(_V8, len(rows))
    gv = ir.GlobalVariable(module, table_t, name)
    gv.linkage = "internal"
    gv.global_constant = True
    gv.initializer = ir.Constant(table_t, rows)
    gv.align = 32
    return gv


def _append_permuted(builder: ir.IRBuilder, values: ir.Value, mask: ir.Value, base: ir.Value, at: ir.Value) -> ir.Value:
    """_append for AVX2: per 256-bit part (8 int32 or 4 int64 lanes), the kept lanes moved first by vpermd in the
    order the table gives for the part's mask, the part stored whole, the count advanced by the mask's popcount."""
    pairs = values.type.element.width == 64
    per = 4 if pairs else 8
    table = _lane_orders(builder.module, pairs)
    permd = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_V8, [_V8, _V8]), "llvm.x86.avx2.permd")
    popcount = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_I8, [_I8]), "llvm.ctpop.i8")
    part_t = ir.VectorType(values.type.element, per)
    for h in range(LANES // per):
        lanes = ir.Constant(ir.VectorType(_I32, per), list(range(per * h, per * h + per)))
        v = builder.shuffle_vector(values, ir.Constant(values.type, ir.Undefined), lanes)
        m = builder.shuffle_vector(mask, ir.Constant(mask.type, ir.Undefined), lanes)
        bits = builder.bitcast(m, ir.IntType(per))
        bits8 = builder.zext(bits, _I8) if per < 8 else bits
        order = builder.load(builder.gep(table, [ir.Constant(_I32, 0), builder.zext(bits8, _I64)]), align=32)
        packed = builder.bitcast(builder.call(permd, [builder.bitcast(v, _V8), order]), part_t)
        builder.store(packed, builder.bitcast(builder.gep(base, [at]), part_t.as_pointer()), align=4)
        at = builder.add(at, builder.zext(builder.call(popcount, [bits8]), _I64))
    return at


def _append(builder: ir.IRBuilder, values: ir.Value, mask: ir.Value, base: ir.Value, at: ir.Value) -> ir.Value:
    """Store the lanes of 16 int64 or int32 values where mask is on, packed, at base[at:], and return at + their
    count (whole vectors are written: the caller keeps room for 16 more values there). int64 compressed into
    registers eight lanes at a time, each stored plainly: vpcompressq with a memory operand is several times slower on
    Intel, and LLVM splits a 16-lane compress through an aligned stack slot that numba's frames do not align
    (a crash). On an AVX2 target without AVX-512: _append_permuted."""
    if compress_by_permute():
        return _append_permuted(builder, values, mask, base, at)
    if values.type.element.width == 32:
        # int32: the 16 lanes fill one 512-bit register, compressed at once
        full = values.type
        fmask = ir.VectorType(ir.IntType(1), LANES)
        compress = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(full, [full, fmask, full]), "llvm.experimental.vector.compress.v16i32"
        )
        pop16 = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_I16, [_I16]), "llvm.ctpop.i16")
        packed = builder.call(compress, [values, mask, ir.Constant(full, ir.Undefined)])
        builder.store(packed, builder.bitcast(builder.gep(base, [at]), full.as_pointer()), align=4)
        return builder.add(at, builder.zext(builder.call(pop16, [builder.bitcast(mask, _I16)]), _I64))
    half = ir.VectorType(_I64, 8)
    hmask = ir.VectorType(ir.IntType(1), 8)
    compress = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(half, [half, hmask, half]), "llvm.experimental.vector.compress.v8i64"
    )
    popcount = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_I8, [_I8]), "llvm.ctpop.i8")
    for h in range(2):
        lanes = ir.Constant(_PICK8, list(range(8 * h, 8 * h + 8)))
        v = builder.shuffle_vector(values, ir.Constant(values.type, ir.Undefined), lanes)
        m = builder.shuffle_vector(mask, ir.Constant(mask.type, ir.Undefined), lanes)
        packed = builder.call(compress, [v, m, ir.Constant(half, ir.Undefined)])
        builder.store(packed, builder.bitcast(builder.gep(base, [at]), half.as_pointer()), align=8)
        at = builder.add(at, builder.zext(builder.call(popcount, [builder.bitcast(m, _I8)]), _I64))
    return at


def _c(t: types.Type, ndim: int, dtypes: tuple) -> bool:
    return isinstance(t, types.Array) and t.ndim == ndim and t.layout == "C" and t.dtype in dtypes


def _coefficients(coefs: types.Type) -> bool:
    """The unmixing coefficients the differences take: a tuple of seven float32 (the two unmixing rows, then the
    half noise floor)."""
    return isinstance(coefs, types.UniTuple) and coefs.count == 7 and coefs.dtype == types.float32


def _coefficient_values(builder: ir.IRBuilder, coefs: ir.Value) -> list[ir.Value]:
    return [builder.extract_value(coefs, i) for i in range(7)]


def differences16_takes(frame, lin, dlin, unmix, ta, out) -> bool:
    """Whether differences16 can take rows of these (numba) types: C-contiguous uint8/uint16 frames (H, W, C),
    float32 tables (3, levels), float32 unmixing rows and noise floor, a float32 C-contiguous output. (The
    caller still checks at run time that C and the table rows are 3.)"""
    return (
        _c(frame, 3, (types.uint8, types.uint16))
        and _c(lin, 2, (types.float32,))
        and _c(dlin, 2, (types.float32,))
        and isinstance(unmix, types.Array)
        and unmix.dtype == types.float32
        and ta == types.float32
        and _c(out, 2, (types.float32,))
    )


def gather8_takes(dst: types.Type, table: types.Type, idx: types.Type) -> bool:
    """Whether gather8 takes arrays of these (numba) types (see gather8)."""
    return (
        _c(dst, 1, tuple(_LLVM_NAME))
        and _c(table, 1, tuple(_LLVM_NAME))
        and _c(idx, 1, (types.int32, types.int64))
        and isinstance(dst.dtype, types.Float) == isinstance(table.dtype, types.Float)
        and dst.dtype.bitwidth >= table.dtype.bitwidth
    )


def _channels(builder: ir.IRBuilder, pa: ir.Value, pb: ir.Value, elem: ir.Type, xa: ir.Value) -> list[list[ir.Value]]:
    """The 16 pixels at xa of two (W, 3) rows: each frame's channels split and widened to int32 vectors."""
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
    return chans


def _gather_pairs(builder: ir.IRBuilder, base: ir.Value, index: ir.Value) -> tuple[ir.Value, ir.Value]:
    """base[index] for an int64 table whose entries are float32 pairs (pack_tables, pair_tables): the 16 low
    halves and the 16 high halves, as two float32 vectors (one 8-byte gather per lane)."""
    v32 = ir.VectorType(_F32, 2 * LANES)
    q = builder.bitcast(_masked_gather(builder, base, index, _I64, "i64"), v32)
    undef = ir.Constant(v32, ir.Undefined)
    low = builder.shuffle_vector(q, undef, ir.Constant(_VI, list(range(0, 2 * LANES, 2))))
    high = builder.shuffle_vector(q, undef, ir.Constant(_VI, list(range(1, 2 * LANES, 2))))
    return low, high


def _mix_store(
    builder: ir.IRBuilder, e: list, n: list, coefs: tuple, pout: ir.Value, width: ir.Value, xa: ir.Value
) -> None:
    """Rows 0-3 of out at xa: the two unmixed differences of the channels' differences e and their noise floors
    from the channels' noise slopes n (coefs: the two unmixing rows and the half noise floor, scalars)."""
    co = [_splat(builder, v, _V) for v in coefs]
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


@intrinsic
def differences16_pairs(typingctx, a, b, pairs, coefs, out, x):
    """differences16 for 8-bit frames from a table over value pairs: entry (c * stride) + 256 a + b holds the
    float32 pair (lin[b] - lin[a], dlin[b] + dlin[a]) of channel c (see pair_tables), stride 65536, or 0 when
    the three channels share one table. One 8-byte gather per channel for both frames: half the gathered
    elements of the packed tables (and a few hundred hot entries of the 512 KB table in the L1 cache: the
    stripes' values cluster). Same values: the pair's float32 difference and sum are the ones computed here
    from two gathers. coefs: see _coefficients."""
    if not (
        _c(a, 2, (types.uint8,))
        and b == a
        and _c(pairs, 1, (types.int64,))
        and _coefficients(coefs)
        and _c(out, 2, (types.float32,))
        and isinstance(x, types.Integer)
    ):
        return None
    sig = types.void(a, b, pairs, coefs, out, x)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        xa = context.cast(builder, args[-1], kinds[-1], types.int64)
        arr = [context.make_array(kinds[i])(context, builder, args[i]) for i in (0, 1, 2, 4)]
        pa, pb, ppair, pout = (ar.data for ar in arr)
        width = builder.extract_value(arr[3].shape, 1)
        chans = _channels(builder, pa, pb, ir.IntType(8), xa)
        # one table for all channels (65536 entries) or one per channel (3 x 65536)
        size = builder.trunc(builder.extract_value(arr[2].shape, 0), _I32)
        stride = builder.select(
            builder.icmp_unsigned("==", size, ir.Constant(_I32, 65536)), ir.Constant(_I32, 0), ir.Constant(_I32, 65536)
        )
        e = []
        n = []
        for c in range(3):
            off = _splat(builder, builder.mul(stride, ir.Constant(_I32, c)), _VI)
            idx = builder.add(
                builder.add(builder.shl(chans[0][c], _splat(builder, ir.Constant(_I32, 8), _VI)), chans[1][c]), off
            )
            diff, noise = _gather_pairs(builder, ppair, idx)
            e.append(diff)
            n.append(noise)
        _mix_store(builder, e, n, _coefficient_values(builder, args[3]), pout, width, xa)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def differences16(typingctx, a, b, lin, dlin, coefs, out, x):
    """Pixels x .. x + 15 of _row_differences: a, b the two frames' rows (W, 3) uint8/uint16, C-contiguous;
    lin, dlin (3 * levels,) float32, the channels' tables one after the other, or lin int64 (3 * levels,): both
    tables packed, each entry the float32 pair (lin, dlin) (see pack_tables; dlin is then not read): one 8-byte
    gather per frame and channel instead of two 4-byte ones, half the gathered elements; coefs the two unmixing
    rows and the half noise floor (see _coefficients); out (>= 4, W) float32 C-contiguous receives the differences d0,
    d1 and the noise floors n0, n1 in its first four rows. The caller keeps x + 16 <= W."""
    packed = _c(lin, 1, (types.int64,))
    if not (
        _c(a, 2, (types.uint8, types.uint16))
        and b == a
        and (packed or _c(lin, 1, (types.float32,)))
        and _c(dlin, 1, (types.float32, types.int64))
        and _coefficients(coefs)
        and _c(out, 2, (types.float32,))
        and isinstance(x, types.Integer)
    ):
        return None
    sig = types.void(a, b, lin, dlin, coefs, out, x)
    elem = ir.IntType(a.dtype.bitwidth)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        xa = context.cast(builder, args[-1], kinds[-1], types.int64)
        arr = [context.make_array(kinds[i])(context, builder, args[i]) for i in (0, 1, 2, 3, 5)]
        pa, pb, plin, pdlin, pout = (ar.data for ar in arr)
        width = builder.extract_value(arr[4].shape, 1)
        chans = _channels(builder, pa, pb, elem, xa)
        levels = builder.trunc(builder.udiv(builder.extract_value(arr[2].shape, 0), ir.Constant(_I64, 3)), _I32)
        e = []
        n = []
        for c in range(3):
            off = _splat(builder, builder.mul(levels, ir.Constant(_I32, c)), _VI)
            ia = builder.add(chans[0][c], off)
            ib = builder.add(chans[1][c], off)
            if packed:
                # each gathered int64 is the pair (lin, dlin): the low half (even float lane) lin, the high dlin
                la, da = _gather_pairs(builder, plin, ia)
                lb, db = _gather_pairs(builder, plin, ib)
                e.append(builder.fsub(lb, la))
                n.append(builder.fadd(db, da))
                continue
            e.append(
                builder.fsub(
                    _masked_gather(builder, plin, ib, _F32, "f32"), _masked_gather(builder, plin, ia, _F32, "f32")
                )
            )
            n.append(
                builder.fadd(
                    _masked_gather(builder, pdlin, ib, _F32, "f32"), _masked_gather(builder, pdlin, ia, _F32, "f32")
                )
            )
        _mix_store(builder, e, n, _coefficient_values(builder, args[4]), pout, width, xa)
        return context.get_dummy_value()

    return sig, codegen


GATHER_LANES = 8  # values per gather8 call (8 int64 indices fill one 512-bit register)


@intrinsic
def gather8(typingctx, dst, table, idx, i):
    """dst[i + l] = table[idx[i + l]] for l < 8, as one vector gather: dst and table 1-D C-contiguous arrays of
    float32/64 or int32/64 (dst of the table's kind, as wide or wider: the values are widened), idx a 1-D
    C-contiguous int32/int64 array. The caller keeps i + 8 <= len(idx), len(dst) and the indices inside the
    table. (numba emits no gathers itself: see the module docstring.)"""
    if not (gather8_takes(dst, table, idx) and isinstance(i, types.Integer)):
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
        vout = ir.VectorType(out_t, lanes)
        vidx = ir.VectorType(idx_t, lanes)
        index = builder.load(builder.bitcast(builder.gep(ix.data, [at]), vidx.as_pointer()), align=idx_t.width // 8)
        index = builder.sext(index, ir.VectorType(_I64, lanes)) if idx_t.width < 64 else index
        got = _masked_gather(builder, t.data, index, val_t, _LLVM_NAME[kinds[1].dtype])
        if kinds[0].dtype != kinds[1].dtype:
            float_ = isinstance(kinds[0].dtype, types.Float)
            got = builder.fpext(got, vout) if float_ else builder.sext(got, vout)
        builder.store(got, builder.bitcast(builder.gep(d.data, [at]), vout.as_pointer()), align=1)
        return context.get_dummy_value()

    return sig, codegen


def run_bounds16_takes(code: types.Type, rs: types.Type, re: types.Type, rc: types.Type) -> bool:
    """Whether run_bounds16 takes arrays of these (numba) types (see run_bounds16)."""
    same = any(all(_c(t, 1, (w,)) for t in (rs, re, rc)) for w in (types.int32, types.int64))
    return _c(code, 1, (types.int8,)) and same


@intrinsic
def run_bounds16(typingctx, code, x, rs, re, rc, ns, ne):
    """The run bounds among pixels x .. x + 15 of a row of int8 codes (runs of one code >= 0; -1 is no code):
    each pixel that starts a run (its code differs from the pixel before) appends its position to rs[ns:] and
    its code to rc[ns:], each that ends one (differs from the pixel after) its position to re[ne:], with
    compressed vectors (see _append; a scalar loop appends with a dependency from pixel to pixel). Returns the
    advanced (ns, ne). code is 1-D C-contiguous int8, rs/re/rc 1-D C-contiguous, all int32 or all int64; the
    caller keeps 1 <= x and x + 17 <= len(code) (the neighbours are read) and room for 16 more entries."""
    if not (run_bounds16_takes(code, rs, re, rc) and all(isinstance(t, types.Integer) for t in (x, ns, ne))):
        return None
    ret = types.UniTuple(types.int64, 2)
    sig = ret(code, x, rs, re, rc, ns, ne)
    i8 = ir.IntType(8)
    v8 = ir.VectorType(i8, LANES)
    elem = ir.IntType(rs.dtype.bitwidth)
    vout = ir.VectorType(elem, LANES)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        c, s, e, k = (context.make_array(kinds[i])(context, builder, args[i]) for i in (0, 2, 3, 4))
        xa, n_s, n_e = (context.cast(builder, args[i], kinds[i], types.int64) for i in (1, 5, 6))

        def load(offset):
            at = builder.add(xa, ir.Constant(_I64, offset))
            return builder.load(builder.bitcast(builder.gep(c.data, [at]), v8.as_pointer()), align=1)

        prev, cur, nxt = load(-1), load(0), load(1)
        coded = builder.icmp_signed(">=", cur, ir.Constant(v8, [0] * LANES))
        start = builder.and_(coded, builder.icmp_signed("!=", cur, prev))
        end = builder.and_(coded, builder.icmp_signed("!=", cur, nxt))
        pos = _positions(builder, xa, elem)
        _append(builder, builder.sext(cur, vout), start, k.data, n_s)
        out = (_append(builder, pos, start, s.data, n_s), _append(builder, pos, end, e.data, n_e))
        return context.make_tuple(builder, ret, out)

    return sig, codegen


def append_where16_takes(flags: types.Type, out: types.Type) -> bool:
    """Whether append_where16 takes arrays of these (numba) types (see append_where16)."""
    return _c(flags, 1, (types.int8, types.uint8, types.boolean)) and _c(out, 1, (types.int32, types.int64))


def _append_where16_typer(flags, x, out, n, skip_empty: bool):
    """append_where16's signature and codegen; skip_empty: a block without a set flag (on an AVX2 target without
    AVX-512) appends nothing, tested on its mask, instead of permuting and storing its two parts."""
    if not (append_where16_takes(flags, out) and isinstance(x, types.Integer) and isinstance(n, types.Integer)):
        return None
    sig = types.int64(flags, x, out, n)
    v8 = ir.VectorType(ir.IntType(8), LANES)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        f, o = (
            context.make_array(kinds[0])(context, builder, args[0]),
            context.make_array(kinds[2])(context, builder, args[2]),
        )
        xa = context.cast(builder, args[1], kinds[1], types.int64)
        na = context.cast(builder, args[3], kinds[3], types.int64)
        # (numba stores a bool as one byte: 0 or 1)
        raw = builder.load(builder.bitcast(builder.gep(f.data, [xa]), v8.as_pointer()), align=1)
        keep = builder.icmp_unsigned("!=", raw, ir.Constant(v8, [0] * LANES))
        pos = _positions(builder, xa, ir.IntType(kinds[2].dtype.bitwidth))
        if not (skip_empty and compress_by_permute()):
            return _append(builder, pos, keep, o.data, na)
        any_kept = builder.icmp_unsigned("!=", builder.bitcast(keep, _I16), ir.Constant(_I16, 0))
        before = builder.block
        with builder.if_then(any_kept, likely=False):
            appended = _append(builder, pos, keep, o.data, na)
            last = builder.block
        n_out = builder.phi(_I64)
        n_out.add_incoming(na, before)
        n_out.add_incoming(appended, last)
        return n_out

    return sig, codegen


@intrinsic
def append_where16(typingctx, flags, x, out, n):
    """Append to out[n:] the positions x + l (l < 16) where flags[x + l] is nonzero, with
    compressed vectors (see _append); returns the new n. flags is 1-D C-contiguous int8/uint8/bool, out 1-D
    C-contiguous int32/int64; the caller keeps x + 16 <= len(flags) and room for 16 more entries in out."""
    return _append_where16_typer(flags, x, out, n, False)


@intrinsic
def append_sparse16(typingctx, flags, x, out, n):
    """append_where16 for flags that are mostly zero (a few set in a row's hundreds): on an AVX2 target without
    AVX-512 a block of 16 without a set flag is skipped on its mask, a predictable branch where set flags are
    rare (the permutes and stores of its two parts cost more than the test); elsewhere append_where16."""
    return _append_where16_typer(flags, x, out, n, True)


@intrinsic
def fill8(typingctx, arr, i, value):
    """arr[i:i + 8] = value as one vector store (LLVM leaves eight scalar stores of one value as they are): arr a
    1-D C-contiguous int64 or float32 array, value of its kind (an integer or a float); the caller keeps
    0 <= i and i + 8 <= len(arr)."""
    if not (
        _c(arr, 1, (types.int64, types.float32))
        and isinstance(i, types.Integer)
        and isinstance(value, types.Integer if arr.dtype == types.int64 else types.Float)
    ):
        return None
    sig = types.void(arr, i, value)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        a = context.make_array(kinds[0])(context, builder, args[0])
        at = context.cast(builder, args[1], kinds[1], types.int64)
        val = context.cast(builder, args[2], kinds[2], kinds[0].dtype)
        vec = ir.VectorType(context.get_value_type(kinds[0].dtype), 8)
        builder.store(_splat(builder, val, vec), builder.bitcast(builder.gep(a.data, [at]), vec.as_pointer()), align=4)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def spread8x2(typingctx, src, i, dst, x):
    """dst[x:x + 8] = src[i] and dst[x + 8:x + 16] = src[i + 1] as one 16-lane vector (two values, each over a
    block of 8 pixels): src and dst 1-D C-contiguous float32; the caller keeps i + 2 <= len(src) and
    x + 16 <= len(dst)."""
    if not (
        _c(src, 1, (types.float32,))
        and _c(dst, 1, (types.float32,))
        and isinstance(i, types.Integer)
        and isinstance(x, types.Integer)
    ):
        return None
    sig = types.void(src, i, dst, x)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        s = context.make_array(kinds[0])(context, builder, args[0])
        d = context.make_array(kinds[2])(context, builder, args[2])
        at_s = context.cast(builder, args[1], kinds[1], types.int64)
        at_d = context.cast(builder, args[3], kinds[3], types.int64)
        two = ir.VectorType(_F32, 2)
        pair = builder.load(builder.bitcast(builder.gep(s.data, [at_s]), two.as_pointer()), align=4)
        spread = builder.shuffle_vector(pair, ir.Constant(two, ir.Undefined), ir.Constant(_VI, [0] * 8 + [1] * 8))
        builder.store(spread, builder.bitcast(builder.gep(d.data, [at_d]), _V.as_pointer()), align=4)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def prefetch_at(typingctx, arr, y, x):
    """Ask the caches for the 64-byte line holding arr[y, x] (2-D C-contiguous) ahead of its use, into L2
    (llvm.prefetch, locality 2): a hint, with no effect on values and no fault at any address."""
    if not (
        isinstance(arr, types.Array)
        and arr.ndim == 2
        and arr.layout == "C"
        and isinstance(y, types.Integer)
        and isinstance(x, types.Integer)
    ):
        return None
    sig = types.void(arr, y, x)

    def codegen(context, builder, signature, args):
        kinds = signature.args
        a = context.make_array(kinds[0])(context, builder, args[0])
        row = context.cast(builder, args[1], kinds[1], types.int64)
        col = context.cast(builder, args[2], kinds[2], types.int64)
        width = builder.extract_value(a.shape, 1)
        i8p = ir.IntType(8).as_pointer()
        at = builder.bitcast(builder.gep(a.data, [builder.add(builder.mul(row, width), col)]), i8p)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [i8p, _I32, _I32, _I32]), "llvm.prefetch.p0"
        )
        builder.call(fn, [at, ir.Constant(_I32, 0), ir.Constant(_I32, 2), ir.Constant(_I32, 1)])
        return context.get_dummy_value()

    return sig, codegen
