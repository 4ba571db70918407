"""A light's run of candidates in vector code (DESIGN section 2, "Affects" and the
contribution model of "Priority").

point_run takes a run of object records (grid.visible_objects: [V, 8] float64, lo, hi,
mask bits, e2) at positions v0..v1-1 and one light's sphere and mask; it appends the hits
(range test and mask), as (position, d2), to the light's segment of the pair buffers and
returns the new end. After the light's whole walk, point_priority (a point light) or
spot_priority (a spot light: the cone, then the spot factor) turn the hits into (object
row, P) in place, under the contribution model. walk.light_pass uses point_run for every
point and spot light with float64 records, and finishes the thesis model's hits with its
scalar code; "fast" float32 records keep the scalar loop throughout. candidate_run turns
the lanes around for the candidate lists (candidates.candidate_pairs): one object against eight
of its candidate lights a step, each light's 64-byte row of light_hot loaded whole and
transposed as the objects' records are here, the same rule and operations lane by lane.
The stream kernels do the same for a whole chunk of objects with the lanes filled across
objects: stream_fill lays their candidates end to end as (light row, object row) entries,
stream_run tests eight entries a step (each lane's object record loaded and transposed as
its light's row is) and lists the spot lights in range, stream_spots takes those eight a
step through the cone, stream_pack packs the pairs by object. held_row takes the object
pass's common case (objects.object_pass: slots that hold the object's selection, still in
last frame's order) with its pairs in the lanes, and writes each of the object's output
rows with one store.

Why LLVM IR: the scalar loop spends most of its time on the range test and the compaction
of the survivors, one candidate at a time; LLVM's loop vectoriser does not vectorise a
compaction (a store at an index that grows by the test), and numba has no vector types,
masked loads or compress. So the loop is written here as IR, eight candidates a step: eight
loads of whole records (masked in a run's last, short step) transposed into fields, the
range test and the mask on all eight lanes, and the lanes that pass packed to the front and
stored. P follows on the packed hits, eight a step (a quarter of the records in the city,
so the rule's divisions run on pairs, not candidates): e2 and the object rows gathered by
position, or, for a spot, the whole records loaded again for the bounding sphere. The
arithmetic is the scalar rule's, the same IEEE operations in the same order and without
contraction (no fast-math flags): priority.box_d2, priority.spot_cone, then
priority.falloff (times s) plus p_user; every lane's P is a float64 bit for bit equal to
the scalar loop's (tests/test_simd.py). maxnum/minnum stand for numba's max/min, which keep
the first argument unless the second is larger (smaller): they agree wherever the scalar
rule drops a NaN too (w = max(0, 1 - q*q) and min(1, a/e2) with a NaN second argument, e.g.
0/0 when r*r underflows), the box distance meets no NaN from finite coordinates, and -0.0
against +0.0 is removed by squaring.

Packing the lanes (_compress_store, the one primitive here with a version per target,
chosen by PACKING from the features numba compiles for): with AVX-512 (avx512f and
avx512vl) vcompress packs them in a register; with AVX2 a table indexed by the lane mask
gives a vpermps permutation (the standard left-pack; 64-bit lanes in two halves of four);
both then store the whole register where the caller's room holds eight more entries
(_store_lanes), and the first lanes with a masked store only at the room's end. Elsewhere
each lane is stored, without a branch, either to its place or to a scratch slot. (LLVM's
portable ``llvm.masked.compressstore`` expands to a branch a lane on every target without a
compress instruction.) AVX-512's compress straight to memory is avoided, and so are
gathers of the candidates' fields. With the range test alone in vector code (the pairs'
rest cut out), the light pass at (100k, 10k) took 9.0 ms one-thread scalar, 20.2 with
gathers and the memory form, 11.3 with gathers and a register, 6.6 with masked loads of
whole records, a transpose and a register.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, config, types
from numba.core.codegen import get_host_cpu_features
from numba.core.extending import intrinsic

from .fade import ONE_EPS
from .priority import R0
from .scene import FADING_IN, ON, SPOT

LANES = 8
RECORD = 8  # float64 words per object record
# The bits of a record's mask word that pair with lights. In a grid of every object an
# object out of view must pair with no light, yet the candidate lists' walk of a moving
# camera must find it by its own mask (scheduler.Scheduler._candidates). Float64 records
# keep such an object's mask in the upper half of the word (mask << 32): no light's mask
# (uint32, DESIGN section 1) meets it, the walk's all-ones mask (-1.0 as a light mask:
# ``np.int64`` and ``fptosi`` both give all 64 bits) does. Float32 records have no upper
# half: there such an object's mask is 0 and the walk puts it in for its duration.
SHOWN = 0xFFFFFFFF
STREAM_AHEAD = 32  # stream_run prefetches the light rows of the entries this far ahead

_F64 = ir.DoubleType()
_I64 = ir.IntType(64)
_I32 = ir.IntType(32)
_I8 = ir.IntType(8)
_VF = ir.VectorType(_F64, LANES)
_VI64 = ir.VectorType(_I64, LANES)
_VI32 = ir.VectorType(_I32, LANES)
_VB = ir.VectorType(ir.IntType(1), LANES)
_ALWAYS = ir.Constant(ir.IntType(1), 1)  # _store_lanes' room where the caller leaves slack


def target_features() -> str:
    """The CPU features numba compiles for: NUMBA_CPU_FEATURES if set, else the host's as
    numba's codegen reads them (NUMBA_CPU_NAME alone keeps the host's features, and
    NUMBA_ENABLE_AVX=0 turns the AVX ones off)."""
    if config.CPU_FEATURES is not None:
        return config.CPU_FEATURES
    return get_host_cpu_features()


PACKINGS = ("avx512", "avx2", "portable")
# Targets numba can be made to compile for on an x86 host (NUMBA_CPU_NAME, NUMBA_CPU_FEATURES),
# so that one machine measures and tests the code of others: an AVX2 machine without
# AVX-512 (most game developers' x86 machines) and x86-64 as every 64-bit x86 CPU has it.
FORCED_TARGETS = {
    "avx2": ("haswell", "+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+f16c,+fma,+fxsr,+lzcnt,"
                        "+mmx,+movbe,+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,"
                        "+xsave,-avx512f,-avx512vl"),
    "x86-64": ("x86-64", "+64bit,+cmov,+cx8,+fxsr,+mmx,+sse,+sse2,-avx,-avx2,-avx512f,"
                         "-avx512vl"),
}


def packing_for(features: str) -> str:
    """The left-pack (_compress_store) for a target's features: "avx512" (avx512f and
    avx512vl), "avx2", or "portable" (any other target, aarch64 included)."""
    names = set(features.split(","))
    if "+avx512f" in names and "+avx512vl" in names:
        return "avx512"
    return "avx2" if "+avx2" in names else "portable"


# Read when a kernel that uses the intrinsics is compiled (tests switch it to check that
# every packing the host can run gives the same bits).
PACKING = packing_for(target_features())


def _declare(builder: ir.IRBuilder, name: str, ret: ir.Type, args: list[ir.Type]) -> ir.Function:
    return cgutils.get_or_insert_function(builder.module, ir.FunctionType(ret, args), name)


def _splat(builder: ir.IRBuilder, x: ir.Value, vty: ir.VectorType) -> ir.Value:
    v = builder.insert_element(ir.Constant(vty, ir.Undefined), x, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(vty, ir.Undefined),
                                  ir.Constant(ir.VectorType(_I32, vty.count), [0] * vty.count))


def _masked_load(builder: ir.IRBuilder, ptr: ir.Value, lanes: ir.Value, fill: ir.Value
                 ) -> ir.Value:
    """The lanes of the vector at ``ptr`` (``fill`` elsewhere; a lane off reads no memory)."""
    suffix, size = _element(fill.type)
    fn = _declare(builder, f"llvm.masked.load.v8{suffix}.p0", fill.type,
                  [ptr.type, _I32, _VB, fill.type])
    return builder.call(fn, [ptr, ir.Constant(_I32, size), lanes, fill])


def _at_rows(builder: ir.IRBuilder, ptr: ir.Value, rows: ir.Value) -> ir.Value:
    """ptr[rows[k]] in lane k, by scalar loads (every lane a valid row): cheaper than a
    gather for bytes, which x86 cannot gather."""
    vec = ir.Constant(ir.VectorType(ptr.type.pointee, LANES), ir.Undefined)
    for k in range(LANES):
        at = builder.extract_element(rows, ir.Constant(_I32, k))
        value = builder.load(builder.gep(ptr, [builder.sext(at, _I64)]))
        vec = builder.insert_element(vec, value, ir.Constant(_I32, k))
    return vec


def _transpose(builder: ir.IRBuilder, recs: list[ir.Value]) -> list[ir.Value]:
    """Eight records (one vector each) -> eight fields (one vector each, lane k from record
    k): three rounds of two-source shuffles (pairs, quads, halves)."""
    def mix(x, y, lanes):
        return builder.shuffle_vector(x, y, ir.Constant(_VI32, lanes))

    even, odd = [0, 8, 2, 10, 4, 12, 6, 14], [1, 9, 3, 11, 5, 13, 7, 15]
    t = []
    for k in range(0, LANES, 2):
        t += [mix(recs[k], recs[k + 1], even), mix(recs[k], recs[k + 1], odd)]
    lo2, hi2 = [0, 1, 8, 9, 4, 5, 12, 13], [2, 3, 10, 11, 6, 7, 14, 15]
    u = []
    for k in (0, 4):
        u += [mix(t[k], t[k + 2], lo2), mix(t[k], t[k + 2], hi2),
              mix(t[k + 1], t[k + 3], lo2), mix(t[k + 1], t[k + 3], hi2)]
    lo4, hi4 = [0, 1, 2, 3, 8, 9, 10, 11], [4, 5, 6, 7, 12, 13, 14, 15]
    # u[0] holds fields 0 and 4, u[1] 2 and 6, u[2] 1 and 5, u[3] 3 and 7 (four records each).
    return [mix(u[0], u[4], lo4), mix(u[2], u[6], lo4), mix(u[1], u[5], lo4),
            mix(u[3], u[7], lo4), mix(u[0], u[4], hi4), mix(u[2], u[6], hi4),
            mix(u[1], u[5], hi4), mix(u[3], u[7], hi4)]


class _Run:
    """IR of one point_run call (the light's constants as vectors) or of one step of
    candidate_run (eight lights' fields, one a lane), and the intrinsics."""

    def __init__(self, builder: ir.IRBuilder, light: list[ir.Value], packing: str):
        """light = (x, y, z, r, mask, i, p_user): one light's scalars (splat to every
        lane) or vectors (one light a lane, as candidate_run takes them)."""
        b = self.b = builder
        self.packing = packing
        self.zero = ir.Constant(_VF, [0.0] * LANES)
        self.one = ir.Constant(_VF, [1.0] * LANES)
        self.iota = ir.Constant(_VI64, list(range(LANES)))
        light = [x if isinstance(x.type, ir.VectorType) else _splat(b, x, _VF) for x in light]
        self.p = light[:3]
        r = light[3]
        self.rr = b.fmul(r, r)
        self.four_rr = b.fmul(b.fmul(ir.Constant(_VF, [4.0] * LANES), r), r)
        self.mask = b.fptosi(light[4], _VI64)
        self.intensity = light[5]
        self.p_user = light[6]
        self.maxnum = _declare(b, "llvm.maxnum.v8f64", _VF, [_VF, _VF])
        self.minnum = _declare(b, "llvm.minnum.v8f64", _VF, [_VF, _VF])
        self.popcount = _declare(b, "llvm.ctpop.i8", _I8, [_I8])

    def records(self, box: ir.Value, v: ir.Value, left: ir.Value | None) -> list[ir.Value]:
        """The fields of records v .. v+7 (those from ``left`` on read as zeros; all eight
        read whole when ``left`` is None)."""
        b = self.b
        recs = []
        for k in range(LANES):
            at = b.mul(b.add(v, ir.Constant(_I64, k)), ir.Constant(_I64, RECORD))
            ptr = b.bitcast(b.gep(box, [at]), ir.PointerType(_VF))
            if left is None:
                recs.append(b.load(ptr, align=8))
                continue
            live = _splat(b, b.icmp_signed("<", ir.Constant(_I64, k), left), _VB)
            recs.append(_masked_load(b, ptr, live, self.zero))
        return _transpose(b, recs)

    def records_at(self, box: ir.Value, at: ir.Value) -> list[ir.Value]:
        """The fields of the records at positions ``at`` (every lane a valid position)."""
        return _Run.fields_at(self.b, box, at)

    @staticmethod
    def fields_at(b: ir.IRBuilder, table: ir.Value, at: ir.Value, lanes: ir.Value | None = None
                  ) -> list[ir.Value]:
        """The fields of the 8-word rows ``at`` of ``table`` (every lane a valid row); with
        ``lanes``, only those rows are read (zeros elsewhere: a masked load touches no
        memory, so a row not needed costs no cache miss)."""
        recs = []
        for k in range(LANES):
            v = b.extract_element(at, ir.Constant(_I32, k))
            ptr = b.bitcast(b.gep(table, [b.mul(v, ir.Constant(_I64, RECORD))]),
                            ir.PointerType(_VF))
            if lanes is None:
                recs.append(b.load(ptr, align=8))
                continue
            live = _splat(b, b.extract_element(lanes, ir.Constant(_I32, k)), _VB)
            recs.append(_masked_load(b, ptr, live, ir.Constant(_VF, [0.0] * LANES)))
        return _transpose(b, recs)

    def hits_at(self, p_ptr: ir.Value, obj_ptr: ir.Value, i: ir.Value, end: ir.Value
                ) -> tuple[ir.Value, ...]:
        """The eight hits point_run left from i (before ``end``): (lanes, their pointers
        into out_p and out_obj, d2, positions as int64; 0 in lanes past the end)."""
        b = self.b
        lanes = b.icmp_signed("<", self.iota, _splat(b, b.sub(end, i), _VI64))
        p_at = b.bitcast(b.gep(p_ptr, [i]), ir.PointerType(_VF))
        obj_at = b.bitcast(b.gep(obj_ptr, [i]), ir.PointerType(_VI32))
        d2 = _masked_load(b, p_at, lanes, self.zero)
        at = b.sext(_masked_load(b, obj_at, lanes, ir.Constant(_VI32, [0] * LANES)), _VI64)
        return lanes, p_at, obj_at, d2, at

    def gather(self, base: ir.Value, at: ir.Value, lanes: ir.Value, fill: ir.Value
               ) -> ir.Value:
        """base[at[k]] in lane k (``fill`` where a lane is off)."""
        b = self.b
        suffix, size = _element(fill.type)
        pty = base.type
        addr = b.add(_splat(b, b.ptrtoint(base, _I64), _VI64),
                     b.mul(at, ir.Constant(_VI64, [size] * LANES)))
        ptrs = b.inttoptr(addr, ir.VectorType(pty, LANES))
        fn = _declare(b, f"llvm.masked.gather.v8{suffix}.v8p0", fill.type,
                      [ptrs.type, _I32, _VB, fill.type])
        return b.call(fn, [ptrs, ir.Constant(_I32, size), lanes, fill])

    def hits(self, f: list[ir.Value], lanes: ir.Value) -> tuple[ir.Value, ir.Value]:
        """(hit per lane, d2 per lane) of the light and the records' fields f: box_d2, then
        d2 <= r*r and the mask (priority.py)."""
        b = self.b
        d2 = None
        for a in range(3):
            d = b.call(self.maxnum, [b.fsub(f[a], self.p[a]), self.zero])
            d = b.call(self.maxnum, [d, b.fsub(self.p[a], f[3 + a])])
            d2 = b.fmul(d, d) if d2 is None else b.fadd(d2, b.fmul(d, d))
        hit = b.and_(lanes, b.fcmp_ordered("<=", d2, self.rr))
        bits = b.and_(b.bitcast(f[6], _VI64), self.mask)
        hit = b.and_(hit, b.icmp_unsigned("!=", bits, ir.Constant(_VI64, [0] * LANES)))
        return hit, d2

    def priority(self, d2: ir.Value, e2: ir.Value, lanes: ir.Value) -> ir.Value:
        """priority.falloff per lane of the pairs at distance d2 from objects of e2."""
        b = self.b
        q = b.fdiv(d2, self.rr)
        w = b.call(self.maxnum, [b.fsub(self.one, b.fmul(q, q)), self.zero])
        g_is_one = b.or_(b.fcmp_ordered("==", e2, self.zero),
                         b.fcmp_ordered(">=", self.four_rr, e2))
        # g's division only when a pair needs it (an object wider than twice the range:
        # rare), as falloff skips it.
        g_slot = cgutils.alloca_once_value(b, self.one)
        needs = b.bitcast(b.and_(lanes, b.not_(g_is_one)), _I8)
        with b.if_then(b.icmp_unsigned("!=", needs, ir.Constant(_I8, 0)), likely=False):
            g_div = b.call(self.minnum, [b.fdiv(self.four_rr, e2), self.one])
            b.store(b.select(g_is_one, self.one, g_div), g_slot)
        g = b.load(g_slot)
        num = b.fmul(b.fmul(b.fmul(self.intensity, w), w), g)
        return b.fdiv(num, b.fadd(d2, ir.Constant(_VF, [R0 * R0] * LANES)))

    def cone(self, f: list[ir.Value], spot: list[ir.Value]) -> tuple[ir.Value, ir.Value]:
        """(meets, s) per lane of the spot and the records' fields f: priority.spot_cone
        on the bounding sphere of priority.record_geometry, the same operations in the same order;
        spot = (axis x, y, z, cos o, sin o, cos inner or NaN) as vectors."""
        b = self.b
        two = ir.Constant(_VF, [2.0] * LANES)
        big_r = b.fdiv(self.sqrt(f[7]), two)
        v = [b.fsub(b.fdiv(b.fadd(f[k], f[3 + k]), two), self.p[k]) for k in range(3)]
        n = self.sqrt(b.fadd(b.fadd(b.fmul(v[0], v[0]), b.fmul(v[1], v[1])),
                             b.fmul(v[2], v[2])))
        a = b.fadd(b.fadd(b.fmul(v[0], spot[0]), b.fmul(v[1], spot[1])),
                   b.fmul(v[2], spot[2]))
        nn = b.fmul(n, n)
        sq = self.sqrt(b.call(self.maxnum, [b.fsub(nn, b.fmul(big_r, big_r)), self.zero]))
        inside = b.fcmp_ordered("<=", n, big_r)
        meets = b.or_(inside, b.fcmp_ordered(">=", a, b.fsub(b.fmul(spot[3], sq),
                                                              b.fmul(big_r, spot[4]))))
        whole = b.or_(b.or_(inside, b.fcmp_ordered(">=", a, sq)),
                      b.fcmp_ordered("==", nn, self.zero))
        side = self.sqrt(b.call(self.maxnum, [b.fsub(nn, b.fmul(a, a)), self.zero]))
        c = b.select(whole, self.one,
                     b.fdiv(b.fadd(b.fmul(a, sq), b.fmul(big_r, side)), nn))
        t = b.fdiv(b.fsub(c, spot[3]), b.fsub(spot[5], spot[3]))
        t = b.call(self.minnum, [b.call(self.maxnum, [t, self.zero]), self.one])
        step = b.select(b.fcmp_ordered(">=", c, spot[3]), self.one, self.zero)
        s = b.select(b.fcmp_unordered("uno", spot[5], spot[5]), step, b.fmul(t, t))
        return meets, s

    def sqrt(self, x: ir.Value) -> ir.Value:
        return self.b.call(_declare(self.b, "llvm.sqrt.v8f64", _VF, [_VF]), [x])

    def append(self, values: ir.Value, hit: ir.Value, out: ir.Value, count: ir.Value,
               room: ir.Value | None = None) -> None:
        """Stores the lanes of ``values`` that hit, in lane order, from ``out`` on (count
        of them; ``room`` as _compress_store's)."""
        _compress_store(self.b, values, hit, out, count, self.packing, room)


def _masked_store(builder: ir.IRBuilder, values: ir.Value, ptr: ir.Value, lanes: ir.Value
                  ) -> None:
    """Stores the lanes of ``values`` at ``ptr`` (a pointer to the vector type)."""
    suffix, size = _element(values.type)
    fn = _declare(builder, f"llvm.masked.store.v{values.type.count}{suffix}.p0", ir.VoidType(),
                  [values.type, ptr.type, _I32, ir.VectorType(ir.IntType(1), values.type.count)])
    builder.call(fn, [values, ptr, ir.Constant(_I32, size), lanes])


def _left_pack_rows(lanes: int, words: int) -> list[list[int]]:
    """The AVX2 left-pack table: row m lists, for a lane mask m of ``lanes`` lanes, the
    32-bit words of the set lanes in lane order (``words`` words a lane), as vpermd /
    vpermps indices for 8 words; the rest 0 (never stored)."""
    rows = []
    for m in range(1 << lanes):
        idx = [w for k in range(lanes) if m >> k & 1 for w in range(k * words, (k + 1) * words)]
        rows.append(idx + [0] * (8 - len(idx)))
    return rows


def _left_pack_table(b: ir.IRBuilder, lanes: int, words: int) -> ir.GlobalVariable:
    """_left_pack_rows as a constant of the module (one copy a module)."""
    name = f"lightsched.left_pack.{lanes}x{words}"
    if name in b.module.globals:
        return b.module.globals[name]
    rows = _left_pack_rows(lanes, words)
    ty = ir.ArrayType(_VI32, len(rows))
    table = ir.GlobalVariable(b.module, ty, name)
    table.linkage = "internal"
    table.global_constant = True
    table.align = 32
    table.initializer = ir.Constant(ty, [ir.Constant(_VI32, row) for row in rows])
    return table


def _permute(b: ir.IRBuilder, values: ir.Value, lanes: int, words: int, mask: ir.Value
             ) -> ir.Value:
    """``values`` (8 words: <8 x i32> or <4 x double>) with the lanes set in ``mask`` (i64,
    ``lanes`` bits) moved to the front in order: one table row and one vpermps."""
    idx = b.load(b.gep(_left_pack_table(b, lanes, words), [ir.Constant(_I32, 0), mask]),
                 align=32)
    vf32 = ir.VectorType(ir.FloatType(), 8)
    permps = _declare(b, "llvm.x86.avx2.permps", vf32, [vf32, _VI32])
    return b.bitcast(b.call(permps, [b.bitcast(values, vf32), idx]), values.type)


def _first_lanes(b: ir.IRBuilder, count: ir.Value) -> ir.Value:
    """The lane mask of the first ``count`` (i64) of LANES lanes."""
    return b.icmp_signed("<", ir.Constant(_VI64, list(range(LANES))), _splat(b, count, _VI64))


def _packed(b: ir.IRBuilder, values: ir.Value, hit: ir.Value, count: ir.Value,
            fill: ir.Value, packing: str) -> ir.Value:
    """The lanes of ``values`` that hit (``count`` of them) in lane order, then ``fill``'s
    lanes, in a register: "avx512" (any lane width) by vcompress, "avx2" (32-bit lanes)
    by a table row and vpermps."""
    vty = values.type
    suffix, size = _element(vty)
    if packing == "avx512":
        name = f"llvm.x86.avx512.mask.compress.v8{suffix}"
        return b.call(_declare(b, name, vty, [vty, vty, _VB]), [values, fill, hit])
    assert packing == "avx2" and size == 4, "a register left-pack needs AVX-512 or 32-bit lanes"
    permuted = _permute(b, values, 8, 1, b.zext(b.bitcast(hit, _I8), _I64))
    return b.select(_first_lanes(b, count), permuted, fill)


def _store_lanes(b: ir.IRBuilder, values: ir.Value, ptr: ir.Value, lanes: ir.Value,
                 room: ir.Value | None) -> None:
    """Stores the lanes of ``values`` set in ``lanes`` at ``ptr`` (a pointer to the vector
    type). Where ``room`` (i1; None: never) holds, the lanes past them are the caller's to
    overwrite, and the whole vector goes in one plain store: a masked store is 42 uops
    on AMD's Zen 2 and 3 (12 cycles, against one on Intel; uops.info), and held a third
    of the candidate stream's samples there (bench/RESULTS.md, issue 49)."""
    if room is None:
        _masked_store(b, values, ptr, lanes)
        return
    _, size = _element(values.type)
    if isinstance(room, ir.Constant):
        assert room.constant, "room is a caller's promise: true, a test, or None"
        b.store(values, ptr, align=size)
        return
    with b.if_else(room, likely=True) as (whole, part):
        with whole:
            b.store(values, ptr, align=size)
        with part:
            _masked_store(b, values, ptr, lanes)


def _room_from(b: ir.IRBuilder, at: ir.Value, end: ir.Value) -> ir.Value:
    """Whether the LANES elements from index ``at`` (i64) lie before ``end``."""
    return b.icmp_signed("<=", b.add(at, ir.Constant(_I64, LANES)), end)


def _compress_store(b: ir.IRBuilder, values: ir.Value, hit: ir.Value, out: ir.Value,
                    count: ir.Value, packing: str, room: ir.Value | None = None) -> None:
    """Stores the lanes of ``values`` (8 lanes of 32 or 64 bits) that hit, in lane order,
    from ``out`` (a pointer to the element) on; ``count`` of them; nothing past them,
    unless ``room`` (_store_lanes') says the LANES elements from ``out`` are the caller's
    to overwrite. ``packing`` (PACKINGS): "avx512" packs them in a register with
    vcompress, "avx2" with a movemask-indexed table and vpermps (64-bit lanes a half of
    four at a time), both then store the first lanes (_store_lanes); "portable" stores
    every lane to its place or, if it missed, to a scratch slot, without a branch."""
    vty = values.type
    _, size = _element(vty)
    if packing == "avx512" or (packing == "avx2" and size == 4):
        packed = _packed(b, values, hit, count, ir.Constant(vty, [0] * LANES), packing)
        _store_lanes(b, packed, b.bitcast(out, ir.PointerType(vty)), _first_lanes(b, count),
                     room)
    elif packing == "avx2":
        v4 = ir.VectorType(vty.element, 4)
        iota4 = ir.Constant(ir.VectorType(_I64, 4), list(range(4)))
        mask = b.zext(b.bitcast(hit, _I8), _I64)
        at = out
        left = count
        for half in (0, 1):
            part = b.shuffle_vector(values, ir.Constant(vty, ir.Undefined),
                                    ir.Constant(ir.VectorType(_I32, 4),
                                                list(range(4 * half, 4 * half + 4))))
            bits = b.and_(b.lshr(mask, ir.Constant(_I64, 4 * half)), ir.Constant(_I64, 15))
            packed = _permute(b, part, 4, 2, bits)
            lanes = b.icmp_signed("<", iota4, _splat(b, left, ir.VectorType(_I64, 4)))
            _store_lanes(b, packed, b.bitcast(at, ir.PointerType(v4)), lanes, room)
            if half == 0:
                n_lo = b.call(_declare(b, "llvm.ctpop.i64", _I64, [_I64]), [bits])
                at = b.gep(at, [n_lo])
                left = b.sub(count, n_lo)
    else:
        scratch = cgutils.alloca_once(b, vty.element)
        n = ir.Constant(_I64, 0)
        for k in range(LANES):
            lane = ir.Constant(_I32, k)
            on = b.extract_element(hit, lane)
            b.store(b.extract_element(values, lane), b.select(on, b.gep(out, [n]), scratch))
            n = b.add(n, b.zext(on, _I64))


def _element(vty: ir.VectorType) -> tuple[str, int]:
    """(intrinsic name suffix, bytes) of a vector's element: f64 or iN."""
    if isinstance(vty.element, ir.DoubleType):
        return "f64", 8
    return f"i{vty.element.width}", vty.element.width // 8


def _typed(box, box_rows, light, out_obj, out_p) -> bool:
    """Whether the arguments are those point_run, point_priority and spot_priority take."""
    arrays = (box, box_rows, out_obj, out_p)
    return (all(isinstance(a, types.Array) and a.layout == "C" for a in arrays)
            and box.dtype in (types.float64, types.float32) and box.ndim == 2
            and box_rows.dtype == types.int64 and box_rows.ndim == 1
            and out_obj.dtype == types.int32 and out_p.dtype == types.float64
            and isinstance(light, types.UniTuple) and light.count == 7
            and light.dtype == types.float64)


def _lowering(context, builder, signature, args, at: tuple[int, ...], light_at: int
              ) -> tuple[_Run, list[ir.Value]]:
    """The _Run of the light tuple at argument ``light_at``, and the data pointers of the
    arrays box, box_rows, out_obj, out_p (argument positions ``at``) as double*, i64*, i32*,
    double*."""
    kinds = (_F64, _I64, _I32, _F64)
    ptrs = [builder.bitcast(context.make_array(signature.args[k])(context, builder,
                                                                  args[k]).data,
                            ir.PointerType(t)) for k, t in zip(at, kinds, strict=True)]
    light = args[light_at]
    run = _Run(builder, [builder.extract_value(light, k) for k in range(7)], PACKING)
    return run, ptrs


@intrinsic(prefer_literal=False)
def point_run(typingctx, box, box_rows, v0, v1, light, out_obj, out_p, n, end):
    """Appends the hits of one light's sphere among the records at positions v0..v1-1 of
    ``box`` ([V, 8] float64, C order) to out_obj (int32) / out_p (float64) from n, as
    (position, d2): the range test and the mask, not yet P; returns the new n.
    point_priority or spot_priority then turn them into (object row, P); for other models
    the light pass does. light = (x, y, z, r, mask, i, p_user) as float64 (light_hot
    columns 0-4, 6, 7); box_rows (int64 [V], the records' object rows) is
    point_priority's; every array contiguous. The caller guarantees the room: at most one
    pair per record; out_obj / out_p from n to ``end`` are its to overwrite (whole
    stores while eight fit). Float32 records ("fast" precision) are typed too, so that a kernel
    holding both branches compiles, and return -1 at once: not handled, the caller runs its
    scalar loop."""
    if not _typed(box, box_rows, light, out_obj, out_p):
        return None
    sig = types.int64(box, box_rows, types.int64, types.int64, light, out_obj, out_p,
                      types.int64, types.int64)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return ir.Constant(_I64, -1)
        run, (box_ptr, _, obj_ptr, p_ptr) = _lowering(context, builder, signature, args,
                                                      (0, 1, 5, 6), 4)
        v0_, v1_, n0, end = args[2], args[3], args[7], args[8]
        n_slot = cgutils.alloca_once_value(builder, n0)

        def step(v: ir.Value, left: ir.Value | None) -> None:
            lanes = (ir.Constant(_VB, [1] * LANES) if left is None else
                     builder.icmp_signed("<", run.iota, _splat(builder, left, _VI64)))
            hit, d2 = run.hits(run.records(box_ptr, v, left), lanes)
            count = builder.zext(builder.call(run.popcount, [builder.bitcast(hit, _I8)]), _I64)
            n = builder.load(n_slot)
            at = builder.add(_splat(builder, v, _VI64), run.iota)
            room = _room_from(builder, n, end)
            run.append(builder.trunc(at, _VI32), hit, builder.gep(obj_ptr, [n]), count, room)
            run.append(d2, hit, builder.gep(p_ptr, [n]), count, room)
            builder.store(builder.add(n, count), n_slot)

        # Whole steps read their records without masks (a mask per record costs a compare
        # and a mask move each); the last, short step masks them.
        whole = builder.add(v0_, builder.mul(builder.sdiv(builder.sub(v1_, v0_),
                                                          ir.Constant(_I64, LANES)),
                                             ir.Constant(_I64, LANES)))
        with cgutils.for_range_slice(builder, v0_, whole, ir.Constant(_I64, LANES)) as (v, _):
            step(v, None)
        with builder.if_then(builder.icmp_signed("<", whole, v1_)):
            step(whole, builder.sub(v1_, whole))
        return builder.load(n_slot)

    return sig, codegen


@intrinsic(prefer_literal=False)
def point_priority(typingctx, box, box_rows, light, out_obj, out_p, n0, n1, end):
    """Turns the (position, d2) that point_run left at n0..n1-1 of out_obj / out_p into
    (object row, P) in place, eight pairs a step: P is computed for the hits only (a
    quarter of the records in the city), and after the light's whole walk, when its
    positions are no longer in the store buffer. Arguments as point_run's; for float32
    records it does nothing (point_run left them to the scalar loop)."""
    if not _typed(box, box_rows, light, out_obj, out_p):
        return None
    sig = types.void(box, box_rows, light, out_obj, out_p, types.int64, types.int64,
                     types.int64)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return context.get_dummy_value()
        run, (box_ptr, rows_ptr, obj_ptr, p_ptr) = _lowering(context, builder, signature,
                                                             args, (0, 1, 3, 4), 2)
        n0_, n1_, end = args[5], args[6], args[7]
        with cgutils.for_range_slice(builder, n0_, n1_, ir.Constant(_I64, LANES)) as (i, _):
            lanes, p_at, obj_at, d2, at = run.hits_at(p_ptr, obj_ptr, i, n1_)
            e2_at = builder.add(builder.mul(at, ir.Constant(_VI64, [RECORD] * LANES)),
                                ir.Constant(_VI64, [RECORD - 1] * LANES))
            e2 = run.gather(box_ptr, e2_at, lanes, run.zero)
            rows = run.gather(rows_ptr, at, lanes, ir.Constant(_VI64, [0] * LANES))
            room = _room_from(builder, i, end)
            _store_lanes(builder, builder.fadd(run.priority(d2, e2, lanes), run.p_user), p_at,
                         lanes, room)
            _store_lanes(builder, builder.trunc(rows, _VI32), obj_at, lanes, room)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic(prefer_literal=False)
def spot_priority(typingctx, box, box_rows, light, spot, out_obj, out_p, n0, n1, end):
    """point_priority for a spot light under the contribution model: of the (position, d2)
    that point_run left at n0..n1-1, keeps those whose bounding sphere meets the cone
    (priority.spot_cone), packed to the front from n0 as (object row, P = falloff * s +
    p_user), eight a step; returns the new end. spot = (axis x, y, z, cos o, sin o, cos
    inner or NaN: light_f columns 0-5); ``end`` as point_run's. For float32 records it
    returns -1 at once (the scalar loop handled them)."""
    if not (_typed(box, box_rows, light, out_obj, out_p) and isinstance(spot, types.UniTuple)
            and spot.count == 6 and spot.dtype == types.float64):
        return None
    sig = types.int64(box, box_rows, light, spot, out_obj, out_p, types.int64, types.int64,
                      types.int64)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return ir.Constant(_I64, -1)
        run, (box_ptr, rows_ptr, obj_ptr, p_ptr) = _lowering(context, builder, signature,
                                                             args, (0, 1, 4, 5), 2)
        spot_, n0_, n1_, end = args[3], args[6], args[7], args[8]
        axis = [_splat(builder, builder.extract_value(spot_, k), _VF) for k in range(6)]
        m_slot = cgutils.alloca_once_value(builder, n0_)
        with cgutils.for_range_slice(builder, n0_, n1_, ir.Constant(_I64, LANES)) as (i, _):
            # Lanes past the end read position 0, a record that exists (there are hits).
            lanes, _, _, d2, at = run.hits_at(p_ptr, obj_ptr, i, n1_)
            f = run.records_at(box_ptr, at)
            meets, s = run.cone(f, axis)
            hit = builder.and_(lanes, meets)
            p = builder.fadd(builder.fmul(run.priority(d2, f[7], hit), s), run.p_user)
            rows = run.gather(rows_ptr, at, hit, ir.Constant(_VI64, [0] * LANES))
            count = builder.zext(builder.call(run.popcount, [builder.bitcast(hit, _I8)]), _I64)
            m = builder.load(m_slot)
            # Whole stores from m <= i overwrite only entries this step has read.
            room = _room_from(builder, m, end)
            run.append(builder.trunc(rows, _VI32), hit, builder.gep(obj_ptr, [m]), count, room)
            run.append(p, hit, builder.gep(p_ptr, [m]), count, room)
            builder.store(builder.add(m, count), m_slot)
        return builder.load(m_slot)

    return sig, codegen


def _candidate_typed(box, hot, lf, compete, c_j, out_p, out_j) -> bool:
    """Whether the arguments are those candidate_run takes."""
    arrays = (box, hot, lf, compete, c_j, out_p, out_j)
    return (all(isinstance(a, types.Array) and a.layout == "C" for a in arrays)
            and box.dtype in (types.float64, types.float32) and box.ndim == 2
            and hot.dtype == lf.dtype == types.float64 and hot.ndim == lf.ndim == 2
            and compete.dtype == types.boolean and compete.ndim == 1
            and c_j.dtype == out_j.dtype == types.int32 and c_j.ndim == out_j.ndim == 1
            and out_p.dtype == types.float64 and out_p.ndim == 1)


@intrinsic(prefer_literal=False)
def candidate_run(typingctx, box, o, hot, lf, compete, c_j, a, b, out_p, out_j, m, end):
    """The pairs of object row o (record o of ``box``, [N, 8] float64) with its candidate
    lights c_j[a:b] (point and spot rows of hot / lf, light_hot and light_f: [L, 8] float64
    each), appended from m to out_p (P) / out_j (light row), in candidate order; returns
    the new end. The rule of candidates.candidate_pairs' scalar loop under the contribution
    model, bit for bit: a light that competes (``compete``, bool [L]) with a mask bit of
    the object's, d2 <= r*r (priority.box_d2), for a spot the cone (priority.spot_cone on
    the bounding sphere), P = falloff * s + p_user (s = 1 for a point light: the same bits
    as falloff + p_user). Here the lanes are eight candidate lights against the one
    object (its fields in every lane), where point_run has eight objects against one
    light: each light's record is one 64-byte row, loaded whole and transposed like the
    objects' records; light_f rows only for the spot lanes that passed the range test
    (masked loads: where the light rows leave L2, as at (1M, 100k), every lane's row read
    is a cache miss). For float32 records ("fast") returns -1 at once: the caller
    runs its scalar loop. The caller guarantees the object has a mask bit (its record's
    mask has a SHOWN bit) and the room: at most one pair per candidate; out_p / out_j
    from m to ``end`` are its to overwrite (whole stores while eight fit)."""
    if not _candidate_typed(box, hot, lf, compete, c_j, out_p, out_j):
        return None
    sig = types.int64(box, types.int64, hot, lf, compete, c_j, types.int64, types.int64,
                      out_p, out_j, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return ir.Constant(_I64, -1)
        at_ = (0, 2, 3, 4, 5, 8, 9)
        kinds = (_F64, _F64, _F64, _I8, _I32, _F64, _I32)
        box_ptr, hot_ptr, lf_ptr, comp_ptr, cj_ptr, p_ptr, j_ptr = [
            builder.bitcast(context.make_array(signature.args[k])(context, builder,
                                                                  args[k]).data,
                            ir.PointerType(t)) for k, t in zip(at_, kinds, strict=True)]
        o_, a_, b_, m0, end = args[1], args[6], args[7], args[10], args[11]
        rec = builder.load(builder.bitcast(
            builder.gep(box_ptr, [builder.mul(o_, ir.Constant(_I64, RECORD))]),
            ir.PointerType(_VF)), align=8)
        f = [builder.shuffle_vector(rec, ir.Constant(_VF, ir.Undefined),
                                    ir.Constant(_VI32, [k] * LANES)) for k in range(RECORD)]
        m_slot = cgutils.alloca_once_value(builder, m0)
        iota = ir.Constant(_VI64, list(range(LANES)))
        with cgutils.for_range_slice(builder, a_, b_, ir.Constant(_I64, LANES)) as (i, _):
            lanes = builder.icmp_signed("<", iota, _splat(builder, builder.sub(b_, i), _VI64))
            cj_at = builder.bitcast(builder.gep(cj_ptr, [i]), ir.PointerType(_VI32))
            rows32 = _masked_load(builder, cj_at, lanes, ir.Constant(_VI32, [0] * LANES))
            rows = builder.sext(rows32, _VI64)
            # Lanes past the end read light row 0, which exists (there are candidates).
            light = _Run.fields_at(builder, hot_ptr, rows)
            run = _Run(builder, [*light[:5], light[6], light[7]], PACKING)
            comp = _at_rows(builder, comp_ptr, rows32)
            live = builder.and_(lanes, builder.icmp_unsigned(
                "!=", comp, ir.Constant(ir.VectorType(_I8, LANES), [0] * LANES)))
            hit, d2 = run.hits(f, live)
            spot = _is_spot(builder, light[5])
            hit_slot = cgutils.alloca_once_value(builder, hit)
            s_slot = cgutils.alloca_once_value(builder, run.one)
            spot_hit = builder.and_(hit, spot)
            any_spot = builder.bitcast(spot_hit, _I8)
            with builder.if_then(builder.icmp_unsigned("!=", any_spot, ir.Constant(_I8, 0))):
                meets, s = run.cone(f, _Run.fields_at(builder, lf_ptr, rows, spot_hit)[:6])
                builder.store(builder.and_(hit, builder.or_(builder.not_(spot), meets)),
                              hit_slot)
                builder.store(builder.select(spot, s, run.one), s_slot)
            hit = builder.load(hit_slot)
            p = builder.fadd(builder.fmul(run.priority(d2, f[7], hit), builder.load(s_slot)),
                             run.p_user)
            count = builder.zext(builder.call(run.popcount, [builder.bitcast(hit, _I8)]), _I64)
            m = builder.load(m_slot)
            room = _room_from(builder, m, end)
            run.append(p, hit, builder.gep(p_ptr, [m]), count, room)
            run.append(rows32, hit, builder.gep(j_ptr, [m]), count, room)
            builder.store(builder.add(m, count), m_slot)
        return builder.load(m_slot)

    return sig, codegen


def _is_spot(b: ir.IRBuilder, type_field: ir.Value) -> ir.Value:
    """Per lane, whether light_hot's column 5 (row << 5 | type << 3, priority.pack_lights)
    says spot."""
    typ = b.and_(b.ashr(b.fptosi(type_field, _VI64), ir.Constant(_VI64, [3] * LANES)),
                 ir.Constant(_VI64, [3] * LANES))
    return b.icmp_signed("==", typ, ir.Constant(_VI64, [SPOT] * LANES))


def _data(context, builder: ir.IRBuilder, ty, value: ir.Value, elem: ir.Type) -> ir.Value:
    """The data pointer of the array ``value`` (numba type ``ty``) as elem*."""
    return builder.bitcast(context.make_array(ty)(context, builder, value).data,
                           ir.PointerType(elem))


def _tuple_data(context, builder: ir.IRBuilder, ty, value: ir.Value,
                elems: tuple[ir.Type, ...]) -> list[ir.Value]:
    """The data pointers of the arrays of the tuple ``value`` (numba type ``ty``)."""
    return [_data(context, builder, ty[k], builder.extract_value(value, k), e)
            for k, e in enumerate(elems)]


def _vector_at(builder: ir.IRBuilder, ptr: ir.Value, i: ir.Value, vty: ir.VectorType
               ) -> ir.Value:
    """&ptr[i] as a pointer to a vector of vty."""
    return builder.bitcast(builder.gep(ptr, [i]), ir.PointerType(vty))


def _arrays_of(ty, want: tuple) -> bool:
    """Whether ty is a tuple of C-order arrays of the (dtype, ndim) in ``want``."""
    return (isinstance(ty, types.BaseTuple) and len(ty) == len(want)
            and all(isinstance(t, types.Array) and t.layout == "C" and (t.dtype, t.ndim) == w
                    for t, w in zip(ty, want, strict=True)))


def _array_of(ty, dtype, ndim: int) -> bool:
    return isinstance(ty, types.Array) and ty.layout == "C" and (ty.dtype, ty.ndim) == (
        dtype, ndim)


def _records(ty) -> bool:
    """Object records as the stream kernels take them: [N, 8] float64, or float32 ("fast"
    precision), typed so that a kernel holding both branches compiles, and left at once."""
    return _array_of(ty, types.float64, 2) or _array_of(ty, types.float32, 2)


# The candidates' stream (candidates.candidate_pairs): per entry the light row and the object
# row (int32 each); its results: P (float64) and whether the pair affects (uint8).
_STREAM = ((types.int32, 1), (types.int32, 1))
_STREAM_OUT = ((types.float64, 1), (types.uint8, 1))
_V8I8 = ir.VectorType(_I8, LANES)


@intrinsic(prefer_literal=False)
def stream_fill(typingctx, cands, recs, rows, r0, r1, stream, starts):
    """The candidates of the object rows rows[r0:r1] (rows int64, ascending) laid end to
    end as one stream, the input of stream_run:
    cands = (seg [N, 2] (start, length), light row int32 [C]), the lists of
    scheduler._Candidates (rooms with space to grow, so not contiguous); recs = (box, its
    integer view) the records in row order, whose mask without a SHOWN bit (out of view)
    leaves an object out. stream = (light row, object row) gets the entries, starts [r1 - r0 + 1] where
    each object's begin (the last: the end). Returns the stream's length; -1 for float32
    records ("fast": the caller runs its per-object loop). Eight entries a step, stored
    whole, so the stream needs 8 entries of room past its end; an object of more than 8
    candidates (a fifth in the city) takes further steps."""
    if not (_arrays_of(cands, ((types.int64, 2), (types.int32, 1)))
            and isinstance(recs, types.BaseTuple) and len(recs) == 2 and _records(recs[0])
            and isinstance(recs[1], types.Array) and recs[1].ndim == 2
            and recs[1].layout == "C" and isinstance(recs[1].dtype, types.Integer)
            and recs[1].dtype.bitwidth == recs[0].dtype.bitwidth
            and _array_of(rows, types.int64, 1)
            and _arrays_of(stream, _STREAM) and _array_of(starts, types.int64, 1)):
        return None
    sig = types.int64(cands, recs, rows, types.int64, types.int64, stream, starts)

    def codegen(context, builder, signature, args):
        if signature.args[1][0].dtype != types.float64:
            return ir.Constant(_I64, -1)
        b = builder
        seg_ptr, cj_ptr = _tuple_data(context, b, signature.args[0], args[0], (_I64, _I32))
        bits_ptr = _data(context, b, signature.args[1][1], b.extract_value(args[1], 1), _I64)
        rows_ptr = _data(context, b, signature.args[2], args[2], _I64)
        sj_ptr, so_ptr = _tuple_data(context, b, signature.args[5], args[5], (_I32, _I32))
        st_ptr = _data(context, b, signature.args[6], args[6], _I64)
        r0_, r1_ = args[3], args[4]
        iota = ir.Constant(_VI64, list(range(LANES)))
        zero = ir.Constant(_I64, 0)
        step = ir.Constant(_I64, LANES)
        n_slot = cgutils.alloca_once_value(b, zero)

        def copy(at, src, k, ln, o32):
            lanes = b.icmp_signed("<", iota, _splat(b, b.sub(ln, k), _VI64))
            rows = _masked_load(b, _vector_at(b, cj_ptr, b.add(src, k), _VI32), lanes,
                                ir.Constant(_VI32, [0] * LANES))
            b.store(rows, _vector_at(b, sj_ptr, b.add(at, k), _VI32), align=4)
            b.store(o32, _vector_at(b, so_ptr, b.add(at, k), _VI32), align=4)

        with cgutils.for_range_slice(b, r0_, r1_, ir.Constant(_I64, 1)) as (r, _):
            at = b.load(n_slot)
            b.store(at, b.gep(st_ptr, [b.sub(r, r0_)]))
            o = b.load(b.gep(rows_ptr, [r]))
            two = b.mul(o, ir.Constant(_I64, 2))
            src = b.load(b.gep(seg_ptr, [two]))
            ln = b.load(b.gep(seg_ptr, [b.add(two, ir.Constant(_I64, 1))]))
            ob = b.load(b.gep(bits_ptr, [b.add(b.mul(o, ir.Constant(_I64, RECORD)),
                                               ir.Constant(_I64, 6))]))
            # An object out of view keeps its list but pairs with none.
            shown = b.and_(ob, ir.Constant(_I64, SHOWN))
            ln = b.select(b.icmp_unsigned("!=", shown, zero), ln, zero)
            o32 = _splat(b, b.trunc(o, _I32), _VI32)
            # The first step whatever the length: no branch for the four objects in five
            # of at most eight candidates.
            copy(at, src, zero, ln, o32)
            with b.if_then(b.icmp_signed(">", ln, step), likely=False):
                with cgutils.for_range_slice(b, step, ln, step) as (k, _):
                    copy(at, src, k, ln, o32)
            b.store(b.add(at, ln), n_slot)
        n = b.load(n_slot)
        b.store(n, b.gep(st_ptr, [b.sub(r1_, r0_)]))
        return n

    return sig, codegen


@intrinsic(prefer_literal=False)
def stream_run(typingctx, box, hot, compete, stream, n, out, spots):
    """The stream's first n entries (stream_fill), eight a step whatever object each
    belongs to: candidate_run's rule lane by lane, with the object's record loaded and
    transposed per lane as the light's row is. The light rows of the entries STREAM_AHEAD
    on are prefetched: they are rows at random, and at (1M, 100k), where light_hot is 6.4
    MB, half of the pass's samples waited on them (bench/kernel_profile.py). The prefetch
    helps the more the slower the memory, and not where the lights stay cached
    (bench/RESULTS.md, "Measurements behind the code").

    A point light's pair gets out = (P, 1); a pair that fails gets hit 0; a spot light in
    range gets hit 0 here and its entry's index appended to ``spots`` (stream_spots decides
    it): its cone and spot factor are three square roots and three divisions on eight
    lanes, for the one lane in ten that is a spot, so they run on eight spots a step.
    Returns the spots listed. box [N, 8] float64 records in row order (float32: -1 at
    once, nothing written), hot light_hot [L, 8], compete bool [L]. ``out``'s arrays and
    ``spots`` hold LANES entries past n, which the steps overwrite: their stores are
    whole vectors (_store_lanes)."""
    if not (_records(box) and _array_of(hot, types.float64, 2)
            and _array_of(compete, types.boolean, 1) and _arrays_of(stream, _STREAM)
            and _arrays_of(out, _STREAM_OUT) and _array_of(spots, types.int32, 1)):
        return None
    sig = types.int64(box, hot, compete, stream, types.int64, out, spots)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return ir.Constant(_I64, -1)
        b = builder
        box_ptr = _data(context, b, signature.args[0], args[0], _F64)
        hot_ptr = _data(context, b, signature.args[1], args[1], _F64)
        comp_ptr = _data(context, b, signature.args[2], args[2], _I8)
        sj_ptr, so_ptr = _tuple_data(context, b, signature.args[3], args[3], (_I32, _I32))
        sp_ptr, sh_ptr = _tuple_data(context, b, signature.args[5], args[5], (_F64, _I8))
        spots_ptr = _data(context, b, signature.args[6], args[6], _I32)
        n_ = args[4]
        iota = ir.Constant(_VI64, list(range(LANES)))
        iota32 = ir.Constant(_VI32, list(range(LANES)))
        zero32 = ir.Constant(_VI32, [0] * LANES)
        ns_slot = cgutils.alloca_once_value(b, ir.Constant(_I64, 0))
        with cgutils.for_range_slice(b, ir.Constant(_I64, 0), n_, ir.Constant(_I64, LANES)
                                     ) as (i, _):
            lanes = b.icmp_signed("<", iota, _splat(b, b.sub(n_, i), _VI64))
            ahead = b.add(i, ir.Constant(_I64, STREAM_AHEAD))
            with b.if_then(b.icmp_signed("<=", b.add(ahead, ir.Constant(_I64, LANES)), n_),
                           likely=True):
                for k in range(LANES):
                    row = b.load(b.gep(sj_ptr, [b.add(ahead, ir.Constant(_I64, k))]))
                    _prefetch(b, b.gep(hot_ptr, [b.mul(b.sext(row, _I64),
                                                       ir.Constant(_I64, RECORD))]))
            rows32 = _masked_load(b, _vector_at(b, sj_ptr, i, _VI32), lanes, zero32)
            objs32 = _masked_load(b, _vector_at(b, so_ptr, i, _VI32), lanes, zero32)
            # Lanes past the end read light row 0 and object row 0, which exist.
            light = _Run.fields_at(b, hot_ptr, b.sext(rows32, _VI64))
            f = _Run.fields_at(b, box_ptr, b.sext(objs32, _VI64))
            run = _Run(b, [*light[:5], light[6], light[7]], PACKING)
            comp = _at_rows(b, comp_ptr, rows32)
            live = b.and_(lanes, b.icmp_unsigned("!=", comp, ir.Constant(_V8I8, [0] * LANES)))
            hit, d2 = run.hits(f, live)
            spot = _is_spot(b, light[5])
            point = b.and_(hit, b.not_(spot))
            # P * s with s = 1, as candidate_run has it: the same bits as P.
            p = b.fadd(b.fmul(run.priority(d2, f[7], point), run.one), run.p_user)
            _store_lanes(b, p, _vector_at(b, sp_ptr, i, _VF), lanes, _ALWAYS)
            _store_lanes(b, b.zext(point, _V8I8), _vector_at(b, sh_ptr, i, _V8I8), lanes,
                         _ALWAYS)
            in_range = b.and_(hit, spot)
            count = b.zext(b.call(run.popcount, [b.bitcast(in_range, _I8)]), _I64)
            ns = b.load(ns_slot)
            at = b.add(_splat(b, b.trunc(i, _I32), _VI32), iota32)
            run.append(at, in_range, b.gep(spots_ptr, [ns]), count, _ALWAYS)
            b.store(b.add(ns, count), ns_slot)
        return b.load(ns_slot)

    return sig, codegen


@intrinsic(prefer_literal=False)
def stream_spots(typingctx, box, lights, stream, spots, n, out):
    """The spot lights' entries stream_run listed (spots[:n], indices into the stream, all
    in range and competing with a mask bit of the object's): the cone and P = falloff * s
    + p_user as candidate_run has them (priority.spot_cone on the bounding sphere), eight
    a step; each entry's out = (P, whether the cone meets the object). lights =
    (light_hot, light_f) [L, 8] float64; the rest as stream_run."""
    if not (_records(box) and _arrays_of(lights, ((types.float64, 2), (types.float64, 2)))
            and _arrays_of(stream, _STREAM) and _array_of(spots, types.int32, 1)
            and _arrays_of(out, _STREAM_OUT)):
        return None
    sig = types.void(box, lights, stream, spots, types.int64, out)

    def codegen(context, builder, signature, args):
        if signature.args[0].dtype != types.float64:
            return context.get_dummy_value()
        b = builder
        box_ptr = _data(context, b, signature.args[0], args[0], _F64)
        hot_ptr, lf_ptr = _tuple_data(context, b, signature.args[1], args[1], (_F64, _F64))
        sj_ptr, so_ptr = _tuple_data(context, b, signature.args[2], args[2], (_I32, _I32))
        spots_ptr = _data(context, b, signature.args[3], args[3], _I32)
        sp_ptr, sh_ptr = _tuple_data(context, b, signature.args[5], args[5], (_F64, _I8))
        n_ = args[4]
        iota = ir.Constant(_VI64, list(range(LANES)))
        with cgutils.for_range_slice(b, ir.Constant(_I64, 0), n_, ir.Constant(_I64, LANES)
                                     ) as (i, _):
            lanes = b.icmp_signed("<", iota, _splat(b, b.sub(n_, i), _VI64))
            # Lanes past the end take entry 0 (there are spots, so a stream) and store
            # nothing.
            at = _masked_load(b, _vector_at(b, spots_ptr, i, _VI32), lanes,
                              ir.Constant(_VI32, [0] * LANES))
            rows = b.sext(_at_rows(b, sj_ptr, at), _VI64)
            f = _Run.fields_at(b, box_ptr, b.sext(_at_rows(b, so_ptr, at), _VI64))
            light = _Run.fields_at(b, hot_ptr, rows)
            run = _Run(b, [*light[:5], light[6], light[7]], PACKING)
            hit, d2 = run.hits(f, lanes)
            meets, s = run.cone(f, _Run.fields_at(b, lf_ptr, rows)[:6])
            hit = b.and_(hit, meets)
            p = b.fadd(b.fmul(run.priority(d2, f[7], hit), s), run.p_user)
            for k in range(LANES):
                lane = ir.Constant(_I32, k)
                with b.if_then(b.extract_element(lanes, lane), likely=True):
                    entry = b.sext(b.extract_element(at, lane), _I64)
                    b.store(b.extract_element(p, lane), b.gep(sp_ptr, [entry]))
                    b.store(b.zext(b.extract_element(hit, lane), _I8), b.gep(sh_ptr, [entry]))
        return context.get_dummy_value()

    return sig, codegen


@intrinsic(prefer_literal=False)
def stream_pack(typingctx, stream, out, n, heap, base, end, before):
    """The pairs among the stream's first n entries (out's hit set) packed, in stream
    order, into heap = (P, light row) from ``base``: a compress store of eight entries a
    step, whole while eight records fit before ``end`` (the heap's records from base to
    end are the caller's to overwrite). before[i] = the pairs before entry i (before[n]:
    all), from which each object's segment follows (candidates.candidate_pairs). The
    stream, ``out`` and ``before`` hold LANES entries past n: they are read and written
    eight whole entries a step. Returns the pairs."""
    if not (_arrays_of(stream, _STREAM) and _arrays_of(out, _STREAM_OUT)
            and _arrays_of(heap, ((types.float64, 1), (types.int32, 1)))
            and _array_of(before, types.int64, 1)):
        return None
    sig = types.int64(stream, out, types.int64, heap, types.int64, types.int64, before)

    def codegen(context, builder, signature, args):
        b = builder
        sj_ptr, _ = _tuple_data(context, b, signature.args[0], args[0], (_I32, _I32))
        sp_ptr, sh_ptr = _tuple_data(context, b, signature.args[1], args[1], (_F64, _I8))
        hp_ptr, hj_ptr = _tuple_data(context, b, signature.args[3], args[3], (_F64, _I32))
        before_ptr = _data(context, b, signature.args[6], args[6], _I64)
        n_, base, end = args[2], args[4], args[5]
        iota = ir.Constant(_VI64, list(range(LANES)))
        zeros = ir.Constant(_VI64, [0] * LANES)
        popcount = _declare(b, "llvm.ctpop.i8", _I8, [_I8])
        m_slot = cgutils.alloca_once_value(b, ir.Constant(_I64, 0))
        with cgutils.for_range_slice(b, ir.Constant(_I64, 0), n_, ir.Constant(_I64, LANES)
                                     ) as (i, _):
            lanes = b.icmp_signed("<", iota, _splat(b, b.sub(n_, i), _VI64))
            # Whole loads: a masked load of bytes has no AVX2 instruction (LLVM tests and
            # loads lane by lane), and the lanes that miss are never stored.
            h = b.load(_vector_at(b, sh_ptr, i, _V8I8), align=1)
            hit = b.and_(lanes, b.icmp_unsigned("!=", h, ir.Constant(_V8I8, [0] * LANES)))
            p = b.load(_vector_at(b, sp_ptr, i, _VF), align=8)
            j = b.load(_vector_at(b, sj_ptr, i, _VI32), align=4)
            m = b.load(m_slot)
            count = b.zext(b.call(popcount, [b.bitcast(hit, _I8)]), _I64)
            at = b.add(base, m)
            room = _room_from(b, at, end)
            _compress_store(b, p, hit, b.gep(hp_ptr, [at]), count, PACKING, room)
            _compress_store(b, j, hit, b.gep(hj_ptr, [at]), count, PACKING, room)
            # Pairs before each lane: m plus an exclusive prefix sum of the hits.
            one = b.zext(hit, _VI64)
            total = one
            for shift in (1, 2, 4):
                moved = b.shuffle_vector(total, zeros, ir.Constant(
                    _VI32, [LANES if k < shift else k - shift for k in range(LANES)]))
                total = b.add(total, moved)
            _store_lanes(b, b.add(b.sub(total, one), _splat(b, m, _VI64)),
                         _vector_at(b, before_ptr, i, _VI64), lanes, _ALWAYS)
            b.store(b.add(m, count), m_slot)
        m = b.load(m_slot)
        b.store(m, b.gep(before_ptr, [n_]))
        return m

    return sig, codegen


# The dtypes held_row reads and writes: heap (P, light row), lights (live_id), state
# (slot ids, slot weights, slot states, selection), out (objects.object_pass's nine) and
# rules (map index per light row; the others are checked by kind), as the scheduler
# passes them.
_HELD_TYPES = (
    ((types.float64, 1), (types.int32, 1)),
    ((types.int32, 1),),
    ((types.int32, 2), (types.float64, 2), (types.uint8, 2), (types.int32, 2)),
    ((types.int32, 2), (types.int32, 2), (types.float32, 2), (types.float32, 2),
     (types.uint8, 2), (types.int32, 1), (types.int32, 1), (types.int8, 2),
     (types.boolean, 1)),
    ((types.int8, 1), None, None, None, None, None))


def _held_exact(groups) -> bool:
    """Whether the tuples held_row takes hold C-order arrays of the dtypes it reads."""
    for group, want in zip(groups, _HELD_TYPES, strict=True):
        for t, w in zip(group, want, strict=True):
            if w is not None and not (isinstance(t, types.Array) and t.layout == "C"
                                      and (t.dtype, t.ndim) == w):
                return False
    return True


@intrinsic(prefer_literal=False)
def held_row(typingctx, o, a, n, heap, lights, state, out, rules):
    """The slots of object row o when they are held in last frame's order, else -1 and
    nothing written (the caller runs its scalar path, which gives every other case).
    Held: last frame's slots hold exactly this frame's selection, none fading out (DESIGN
    section 2, "Selection" and "Fade"); then the new slots are those lights in output
    order (P descending, ties to the lower id), each on at its weight or fading in a step
    further (steps 1-2 of Fade; with every slot on, fade.held_slots: weight 1), which the
    scalar path sorts from last frame's order. Here that order must still hold under this
    frame's P (P moves little between frames, so it mostly does): the outputs' rows are
    then last frame's ids with this frame's P and light rows, -1 / 0 after them.

    Two cases, by the object's n pairs heap[a:a+n]: 1 <= n <= 8, all its competing lights
    selected, and 9 <= n <= 16 with more than K = 8 competing: the top K by the hysteresis
    key (select.raised_key for last frame's selection), which here must be the
    old slots: each ranks, by key, before every other competing light, and they are in
    order by key as well as by P (the selection's order, which the scalar path keeps).
    Writes each output row, the slot weights, the selection (as the scalar path keeps it:
    in pair order, or by key), slot_shadow (pick_slot_shadows: at most ``rules[1]``
    slots whose light has a map, by weight, then output order) and the fading flag, and
    returns the number of competing lights (the count is that, at most K). Arguments as
    objects.object_pass has them (heap = (P, light row), lights = (live_id,): by light row
    its id when live, else -2; state, out) and rules = (map index per light row, how
    many slots may take one: 0 when no light has a map, h, hysteresis_abs, dt/fade_in,
    fade_in); K = 8 (the caller checks). For arrays of other dtypes or layouts (none the
    scheduler passes) returns -1 at once.

    Eight lanes, one pair each (two vectors of them from 9 pairs): the pairs loaded
    masked, each light's live_id read at its row, and every rotation of the
    selected ids compared with the old slots, which both checks that they are the same
    set and carries each pair's P, row and key to its old slot; one compare of each slot
    with the next checks the order, and each output row is one vector store. (A sorting
    network of the eight lanes instead, 6 layers of compare-exchange on (P, id), cost
    more than the whole of the first case: a chain of mask operations.)"""
    groups = (heap, lights, state, out, rules)
    if not (all(isinstance(t, types.BaseTuple) for t in groups)
            and tuple(len(g) for g in groups) == tuple(len(w) for w in _HELD_TYPES)
            and isinstance(rules[1], types.Integer)
            and all(isinstance(t, types.Float) for t in rules[2:])):
        return None
    sig = types.int64(types.int64, types.int64, types.int64, heap, lights, state, out,
                      rules)

    def codegen(context, builder, signature, args):
        if not _held_exact(signature.args[3:]):
            return ir.Constant(_I64, -1)
        b = builder
        v8i8 = ir.VectorType(_I8, LANES)
        v8f32 = ir.VectorType(ir.FloatType(), LANES)
        iota = ir.Constant(_VI64, list(range(LANES)))
        popcount = _declare(b, "llvm.ctpop.i8", _I8, [_I8])

        def data(k, i, elem):
            ty = signature.args[k][i]
            ary = context.make_array(ty)(context, b, b.extract_value(args[k], i))
            return b.bitcast(ary.data, ir.PointerType(elem))

        def row(k, i, elem):
            """Row o (eight elements) of 2-D array i of tuple argument k."""
            at = b.gep(data(k, i, elem), [b.mul(args[0], ir.Constant(_I64, LANES))])
            return b.bitcast(at, ir.PointerType(ir.VectorType(elem, LANES)))

        def splat(value, vty):
            return ir.Constant(vty, [value] * LANES)

        def turn(x, by):
            """Lane i takes lane (i + by) % 8."""
            return b.shuffle_vector(x, ir.Constant(x.type, ir.Undefined), ir.Constant(
                _VI32, [(i + by) % LANES for i in range(LANES)]))

        def all_set(mask):
            return b.icmp_unsigned("==", b.bitcast(mask, _I8), ir.Constant(_I8, 0xFF))

        def count(mask):
            return b.zext(b.call(popcount, [b.bitcast(mask, _I8)]), _I64)

        def ranks(xp, xid, yp, yid):
            """select.ranks_before per lane: higher, ties to the lower id."""
            return b.or_(b.fcmp_ordered(">", xp, yp),
                         b.and_(b.fcmp_ordered("==", xp, yp), b.icmp_signed("<", xid, yid)))

        def pairs(start, lanes):
            """(P, light row, live_id, live) of eight pairs from heap record ``start``;
            ``lanes`` are pairs, the others read light row 0, which exists (the object
            has a pair) and are not live. A lane's live_id is its light's id where live
            (then >= 0), -2 elsewhere."""
            p_at = b.bitcast(b.gep(data(3, 0, _F64), [start]), ir.PointerType(_VF))
            p = _masked_load(b, p_at, lanes, splat(0.0, _VF))
            rows_at = b.bitcast(b.gep(data(3, 1, _I32), [start]), ir.PointerType(_VI32))
            rows = _masked_load(b, rows_at, lanes, splat(0, _VI32))
            ids = _at_rows(b, data(4, 0, _I32), rows)
            return p, rows, ids, b.and_(lanes, b.icmp_signed(">=", ids, splat(0, _VI32)))

        old = b.load(row(5, 0, _I32), align=4)
        has_old = b.icmp_signed(">=", old, splat(0, _VI32))
        n_old = count(has_old)
        old_st = b.load(row(5, 2, _I8), align=1)
        on = b.icmp_unsigned("==", old_st, splat(ON, v8i8))
        all_on = all_set(b.or_(b.not_(has_old), on))
        none_out = all_set(b.or_(b.or_(b.not_(has_old), on), b.icmp_unsigned(
            "==", old_st, splat(FADING_IN, v8i8))))

        def match(halves):
            """(every old slot's light among the halves' live pairs, and the fields of
            the pair holding each old slot's light); halves = (ids of live pairs, -2
            elsewhere: light ids are not negative; their fields)."""
            found = b.not_(has_old)
            at_old = list(halves[0][1])
            for sel, fields in halves:
                for r in range(LANES):
                    same = b.icmp_signed("==", old, turn(sel, r))
                    found = b.or_(found, same)
                    at_old = [b.select(same, turn(f, r), x) for f, x in zip(fields, at_old,
                                                                          strict=True)]
            return all_set(found), at_old

        def in_order(x):
            """Each filled old slot ranks before the next by x (the last filled passes)."""
            nx, nid = turn(x, 1), turn(old, 1)
            last = b.or_(b.icmp_signed("<", nid, splat(0, _VI32)),
                         ir.Constant(_VB, [0] * (LANES - 1) + [1]))
            return all_set(b.or_(b.or_(ranks(x, old, nx, nid), last), b.not_(has_old)))

        def store_selection(sel, live):
            """The selection row: the live lanes' ids in lane order, -1 after them."""
            sel_ptr = row(5, 3, _I32)
            if PACKING == "portable":
                b.store(splat(-1, _VI32), sel_ptr, align=4)
                _compress_store(b, sel, live, b.bitcast(sel_ptr, ir.PointerType(_I32)),
                                count(live), PACKING)
            else:
                # The whole row in one store: no masked store (slow on AMD's Zen 2 and 3).
                b.store(_packed(b, sel, live, count(live), splat(-1, _VI32), PACKING),
                        sel_ptr, align=4)

        a_, n_ = args[1], args[2]
        rules = args[7]
        ok_slot = cgutils.alloca_once_value(b, ir.Constant(ir.IntType(1), 0))
        cand_slot = cgutils.alloca_once_value(b, ir.Constant(_I64, 0))
        p_slot = cgutils.alloca_once_value(b, splat(0.0, _VF))
        rows_slot = cgutils.alloca_once_value(b, splat(0, _VI32))
        with b.if_else(b.icmp_signed(">", n_, ir.Constant(_I64, LANES))) as (wide, narrow):
            with narrow:
                p, rows, ids, live = pairs(a_, b.icmp_signed("<", iota, _splat(b, n_, _VI64)))
                cand = count(live)
                sel = b.select(live, ids, splat(-2, _VI32))
                found, (old_p, old_rows) = match([(sel, (p, rows))])
                ok = b.and_(b.and_(none_out, found), b.icmp_unsigned("==", n_old, cand))
                ok = b.and_(ok, in_order(old_p))
                for slot, value in ((ok_slot, ok), (cand_slot, cand), (p_slot, old_p),
                                    (rows_slot, old_rows)):
                    b.store(value, slot)
                with b.if_then(ok):
                    store_selection(sel, live)
            with wide:
                p, rows, ids, live = pairs(a_, ir.Constant(_VB, [1] * LANES))
                rest = _splat(b, b.sub(n_, ir.Constant(_I64, LANES)), _VI64)
                p2, rows2, ids2, live2 = pairs(b.add(a_, ir.Constant(_I64, LANES)),
                                               b.icmp_signed("<", iota, rest))
                cand = b.add(count(live), count(live2))
                prev = b.load(row(5, 3, _I32), align=4)
                h, h_abs = b.extract_value(rules, 2), b.extract_value(rules, 3)
                fabs = _declare(b, "llvm.fabs.v8f64", _VF, [_VF])

                def key(p, ids):
                    """select.raised_key: P + h|P| + h_abs for last frame's selection."""
                    was = ir.Constant(_VB, [0] * LANES)
                    for r in range(LANES):
                        was = b.or_(was, b.icmp_signed("==", ids, turn(prev, r)))
                    raised = b.fmul(_splat(b, h, _VF), b.call(fabs, [p]))
                    raised = b.fadd(b.fadd(p, raised), _splat(b, h_abs, _VF))
                    return b.select(was, raised, p)

                keys, keys2 = key(p, ids), key(p2, ids2)
                sel = b.select(live, ids, splat(-2, _VI32))
                sel2 = b.select(live2, ids2, splat(-2, _VI32))
                found, (old_p, old_rows, old_key) = match([(sel, (p, rows, keys)),
                                                           (sel2, (p2, rows2, keys2))])
                last_key = _splat(b, b.extract_element(old_key, ir.Constant(_I32, 7)), _VF)
                last_id = _splat(b, b.extract_element(old, ir.Constant(_I32, 7)), _VI32)

                def after(sel, keys):
                    """Every live pair not in an old slot ranks after the last old slot."""
                    mine = ir.Constant(_VB, [0] * LANES)
                    for r in range(LANES):
                        mine = b.or_(mine, b.icmp_signed("==", sel, turn(old, r)))
                    other = b.and_(b.icmp_signed(">=", sel, splat(0, _VI32)), b.not_(mine))
                    return all_set(b.or_(b.not_(other), ranks(last_key, last_id, keys, sel)))

                ok = b.and_(b.and_(none_out, found),
                            b.icmp_unsigned("==", n_old, ir.Constant(_I64, LANES)))
                ok = b.and_(ok, b.icmp_signed(">", cand, ir.Constant(_I64, LANES)))
                for more in (in_order(old_p), in_order(old_key), after(sel, keys),
                             after(sel2, keys2)):
                    ok = b.and_(ok, more)
                for slot, value in ((ok_slot, ok), (cand_slot, cand), (p_slot, old_p),
                                    (rows_slot, old_rows)):
                    b.store(value, slot)
                with b.if_then(ok):
                    b.store(old, row(5, 3, _I32), align=4)
        result = cgutils.alloca_once_value(b, ir.Constant(_I64, -1))
        with b.if_then(b.load(ok_slot)):
            first = has_old
            old_p, old_rows = b.load(p_slot), b.load(rows_slot)
            # Weights and states: on stays on at its weight (1 while every slot is on: the
            # weights are not read then), fading in takes a step (step 1 of Fade).
            w_slot = cgutils.alloca_once_value(b, splat(1.0, _VF))
            st_slot = cgutils.alloca_once_value(b, splat(ON, v8i8))
            with b.if_then(b.not_(all_on)):
                w_old = b.load(row(5, 1, _F64), align=8)
                inc, fade_in = b.extract_value(rules, 4), b.extract_value(rules, 5)
                at_once = b.fcmp_ordered("==", fade_in, ir.Constant(_F64, 0.0))
                step = b.select(at_once, splat(1.0, _VF),
                                b.fadd(w_old, _splat(b, inc, _VF)))
                done = b.fcmp_ordered(">=", step, splat(1.0 - ONE_EPS, _VF))
                b.store(b.select(on, w_old, b.select(done, splat(1.0, _VF), step)), w_slot)
                b.store(b.select(b.or_(on, done), splat(ON, v8i8), splat(FADING_IN, v8i8)),
                        st_slot)
            w = b.select(first, b.load(w_slot), splat(0.0, _VF))
            st = b.select(first, b.load(st_slot), splat(0, v8i8))
            fading = b.icmp_unsigned("!=", b.bitcast(b.and_(first, b.icmp_unsigned(
                "!=", st, splat(ON, v8i8))), _I8), ir.Constant(_I8, 0))
            b.store(old, row(6, 0, _I32), align=4)
            b.store(b.select(first, old_rows, splat(-1, _VI32)), row(6, 1, _I32), align=4)
            b.store(b.select(first, b.fptrunc(old_p, v8f32), splat(0.0, v8f32)),
                    row(6, 2, ir.FloatType()), align=4)
            b.store(b.fptrunc(w, v8f32), row(6, 3, ir.FloatType()), align=4)
            b.store(st, row(6, 4, _I8), align=1)
            b.store(w, row(5, 1, _F64), align=8)
            fading_ptr = b.gep(data(6, 8, _I8), [args[0]])
            b.store(b.zext(fading, _I8), fading_ptr)
            # slot_shadow: -1, then at most q slots whose light has a map, by weight
            # descending, then output order: a slot's rank among those is the count of
            # such slots of a higher weight, or of the same weight before it.
            q = b.extract_value(rules, 1)
            map_slot = cgutils.alloca_once_value(b, splat(-1, v8i8))
            with b.if_then(b.icmp_signed(">", q, ir.Constant(q.type, 0))):
                maps = _at_rows(b, data(7, 0, _I8), old_rows)
                has = b.and_(first, b.icmp_signed(">=", maps, splat(0, v8i8)))
                # Few objects hold a light with a map (by default the suns are not in
                # slots): the ranking below is skipped for the others.
                with b.if_then(b.icmp_unsigned("!=", b.bitcast(has, _I8), ir.Constant(_I8, 0)),
                               likely=False):
                    rank = splat(0, _VI64)
                    for r in range(1, LANES):
                        w_r = turn(w, r)
                        earlier = ir.Constant(_VB, [int((i + r) % LANES < i)
                                                    for i in range(LANES)])
                        before = b.or_(b.fcmp_ordered(">", w_r, w),
                                       b.and_(b.fcmp_ordered("==", w_r, w), earlier))
                        rank = b.add(rank, b.zext(b.and_(turn(has, r), before), _VI64))
                    q64 = context.cast(b, q, signature.args[7][1], types.int64)
                    keep = b.and_(has, b.icmp_signed("<", rank, _splat(b, q64, _VI64)))
                    b.store(b.select(keep, maps, splat(-1, v8i8)), map_slot)
            b.store(b.load(map_slot), row(6, 7, _I8), align=1)
            b.store(b.load(cand_slot), result)
        return b.load(result)

    return sig, codegen


def _prefetch(builder: ir.IRBuilder, ptr: ir.Value) -> None:
    """Asks the cache for the line at ``ptr`` without waiting (never faults)."""
    fn = _declare(builder, "llvm.prefetch.p0", ir.VoidType(),
                  [ir.PointerType(_I8), _I32, _I32, _I32])
    builder.call(fn, [builder.bitcast(ptr, ir.PointerType(_I8)), ir.Constant(_I32, 0),
                      ir.Constant(_I32, 3), ir.Constant(_I32, 1)])


@intrinsic(prefer_literal=False)
def prefetch_row(typingctx, table, row):
    """Asks the cache for the start of ``table[row]`` (a C-order 1-D or 2-D array) without
    waiting for it: the light pass takes its lights in cell order, so each light's row of
    light_hot is a miss that stalled the walk (~9% of its samples) until fetched one light
    ahead. Out-of-range rows are allowed: a prefetch never faults."""
    if not (isinstance(table, types.Array) and table.ndim in (1, 2) and table.layout == "C"
            and isinstance(row, types.Integer)):
        return None
    sig = types.void(table, row)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        stride = builder.extract_value(ary.strides, 0)
        at = builder.mul(context.cast(builder, args[1], signature.args[1], types.int64),
                         stride)
        _prefetch(builder, builder.gep(builder.bitcast(ary.data, ir.PointerType(_I8)), [at]))
        return context.get_dummy_value()

    return sig, codegen


__all__ = ["FORCED_TARGETS", "LANES", "PACKING", "PACKINGS", "candidate_run", "held_row",
           "point_priority", "point_run", "prefetch_row", "spot_priority", "stream_fill",
           "stream_pack", "stream_run", "stream_spots", "target_features"]
