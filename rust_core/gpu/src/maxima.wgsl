// The step limit's maxima reduced on the device (maxima.rs): the largest squared speed of a
// particle state and the largest of one more real per particle. `partial` reduces each
// workgroup's particles in workgroup memory to one value, `total` (one workgroup) those values
// to one. |v|² is computed in integer arithmetic on the values' bits as the host computes it
// from a read-back, in f64 whatever the state's precision (each component widened exactly,
// squared and summed in index order, each operation rounded to nearest even, subnormals
// included), so a driver's fused multiply-adds or flushed subnormals cannot change a bit; f32
// serves only to bound it (`bounds`). A maximum is order-free, so the result is the host's bit
// for bit, and the same on every run. The host prepends `const F64: bool` (the state's
// precision: f64 or f32).

struct Params {
    // Particles, reals per particle in `vel`, the first word of the extra reals in `extra`
    // (NONE: no extra), partial maxima (`partial`'s workgroups).
    n: u32,
    dim: u32,
    extra_at: u32,
    groups: u32,
};

const WG: u32 = 64u;
// Particles per thread of `partial`: a workgroup takes WG · PER of them, so that few
// workgroups (and their barriers) are run.
const PER: u32 = 16u;
const NONE: u32 = 0xffffffffu;
// f64 bits as (high word, low word): +∞ and the NaN an invalid operation gives.
const INF: vec2<u32> = vec2<u32>(0x7ff00000u, 0u);
const QNAN: vec2<u32> = vec2<u32>(0x7ff80000u, 0u);
const ONE: vec4<u32> = vec4<u32>(1u, 0u, 0u, 0u);

@group(0) @binding(0) var<uniform> P: Params;
// The velocities (`dim` reals per particle) and the extra reals, as words (an f64 is its low
// word then its high one).
@group(0) @binding(1) var<storage, read> vel: array<u32>;
@group(0) @binding(2) var<storage, read> extra: array<u32>;
// Per workgroup of `partial`: the largest |v|² as f64 bits (high, low), then the largest extra
// value's bits (f64: high, low; f32: 0, its bits). `total` writes the overall pair to `result`.
@group(0) @binding(3) var<storage, read_write> part: array<vec4<u32>>;
@group(0) @binding(4) var<storage, read_write> result: array<vec4<u32>>;

var<workgroup> best: array<vec4<u32>, WG>;

// Unsigned 128-bit integers as four words, least significant first.
fn limb(v: vec4<u32>, j: i32) -> u32 {
    if (j < 0 || j > 3) {
        return 0u;
    }
    return v[j];
}

fn shl(v: vec4<u32>, s: u32) -> vec4<u32> {
    let q = i32(min(s / 32u, 4u));
    let r = s % 32u;
    var o = vec4<u32>(0u);
    for (var i = 0; i < 4; i = i + 1) {
        let a = limb(v, i - q);
        let b = limb(v, i - q - 1);
        o[i] = select((a << r) | (b >> ((32u - r) & 31u)), a, r == 0u);
    }
    return o;
}

fn shr(v: vec4<u32>, s: u32) -> vec4<u32> {
    let q = i32(min(s / 32u, 4u));
    let r = s % 32u;
    var o = vec4<u32>(0u);
    for (var i = 0; i < 4; i = i + 1) {
        let a = limb(v, i + q);
        let b = limb(v, i + q + 1);
        o[i] = select((a >> r) | (b << ((32u - r) & 31u)), a, r == 0u);
    }
    return o;
}

fn add(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    var o = vec4<u32>(0u);
    var c = 0u;
    for (var i = 0; i < 4; i = i + 1) {
        let s = a[i] + b[i];
        let t = s + c;
        c = select(0u, 1u, s < a[i]) + select(0u, 1u, t < s);
        o[i] = t;
    }
    return o;
}

// a − b for a ≥ b.
fn sub(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    var o = vec4<u32>(0u);
    var c = 0u;
    for (var i = 0; i < 4; i = i + 1) {
        let d = a[i] - b[i];
        o[i] = d - c;
        c = select(0u, 1u, a[i] < b[i]) + select(0u, 1u, d < c);
    }
    return o;
}

// −1, 0 or 1 as a <, = or > b.
fn cmp(a: vec4<u32>, b: vec4<u32>) -> i32 {
    for (var j = 0; j < 4; j = j + 1) {
        let i = 3 - j;
        if (a[i] != b[i]) {
            return select(-1, 1, a[i] > b[i]);
        }
    }
    return 0;
}

// Bits up to the highest set one (0 for 0).
fn bits(v: vec4<u32>) -> i32 {
    for (var j = 0; j < 4; j = j + 1) {
        let i = 3 - j;
        if (v[i] != 0u) {
            return 32 * i + 32 - i32(countLeadingZeros(v[i]));
        }
    }
    return 0;
}

// The full 64-bit product of two words, as (low, high).
fn mul32(a: u32, b: u32) -> vec2<u32> {
    let al = a & 0xffffu;
    let ah = a >> 16u;
    let bl = b & 0xffffu;
    let bh = b >> 16u;
    let ll = al * bl;
    let lh = al * bh;
    let hl = ah * bl;
    let mid = (ll >> 16u) + (lh & 0xffffu) + (hl & 0xffffu);
    return vec2<u32>((ll & 0xffffu) | (mid << 16u), ah * bh + (lh >> 16u) + (hl >> 16u) + (mid >> 16u));
}

// The f64 nearest (ties to even) to p·2^k: subnormal below 2^−1022, +∞ past the largest
// finite.
fn round_f64(p: vec4<u32>, k: i32) -> vec2<u32> {
    let l = bits(p);
    if (l == 0) {
        return vec2<u32>(0u, 0u);
    }
    let top = l - 1 + k;
    if (top > 1023) {
        return INF;
    }
    // Bits dropped: those past 53 significant ones, or below the subnormals' 2^−1074.
    let s = max(l - 53, -1074 - k);
    if (s > l) {
        // Below half the smallest subnormal.
        return vec2<u32>(0u, 0u);
    }
    var q: vec4<u32>;
    if (s <= 0) {
        q = shl(p, u32(-s));
    } else {
        q = shr(p, u32(s));
        let c = cmp(sub(p, shl(q, u32(s))), shl(ONE, u32(s - 1)));
        if (c > 0 || (c == 0 && (q.x & 1u) == 1u)) {
            q = add(q, ONE);
        }
    }
    if (top < -1022) {
        // A subnormal; rounded up to 2^52, the smallest normal (its exponent field is 1).
        return vec2<u32>(q.y, q.x);
    }
    // The significand's leading bit (2^52) adds 1 to the exponent field, a carry to 2^53 one
    // more (up to +∞).
    return vec2<u32>((u32(top + 1022) << 20u) + q.y, q.x);
}

// A finite f64 of bits (high, low), sign ignored, as m·2^(e − 1075), m < 2^53.
struct Unpacked {
    m: vec4<u32>,
    e: i32,
};

fn unpack(b: vec2<u32>) -> Unpacked {
    let f = (b.x >> 20u) & 0x7ffu;
    let hi = b.x & 0xfffffu;
    if (f == 0u) {
        return Unpacked(vec4<u32>(b.y, hi, 0u, 0u), 1);
    }
    return Unpacked(vec4<u32>(b.y, hi | 0x100000u, 0u, 0u), i32(f));
}

// x² rounded to f64, x an f64 of bits (high, low).
fn square64(b: vec2<u32>) -> vec2<u32> {
    let a = vec2<u32>(b.x & 0x7fffffffu, b.y);
    if (a.x >= INF.x) {
        return select(QNAN, INF, a.x == INF.x && a.y == 0u);
    }
    let u = unpack(a);
    let lo = mul32(u.m.x, u.m.x);
    let mid = mul32(u.m.x, u.m.y);
    let hi = mul32(u.m.y, u.m.y);
    let p = add(vec4<u32>(lo.x, lo.y, hi.x, hi.y), shl(vec4<u32>(mid.x, mid.y, 0u, 0u), 33u));
    return round_f64(p, 2 * u.e - 2150);
}

// x² as an f64 (exact), x an f32 of bits `w`.
fn square32(w: u32) -> vec2<u32> {
    let a = w & 0x7fffffffu;
    if (a >= 0x7f800000u) {
        return select(QNAN, INF, a == 0x7f800000u);
    }
    let f = a >> 23u;
    var m = a & 0x7fffffu;
    var e = 1;
    if (f != 0u) {
        m = m | 0x800000u;
        e = i32(f);
    }
    let p = mul32(m, m);
    return round_f64(vec4<u32>(p.x, p.y, 0u, 0u), 2 * e - 300);
}

fn above(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.x > b.x || (a.x == b.x && a.y > b.y);
}

// x + y rounded to f64, both ≥ 0 (f64 bits): NaN if either is, else +∞ if either is.
fn add64(x: vec2<u32>, y: vec2<u32>) -> vec2<u32> {
    var a = x;
    var b = y;
    if (above(b, a)) {
        a = y;
        b = x;
    }
    // Non-negative values order as their bits, NaNs above +∞.
    if (above(a, INF)) {
        return QNAN;
    }
    if (a.x == INF.x && a.y == 0u) {
        return INF;
    }
    if (b.x == 0u && b.y == 0u) {
        return a;
    }
    let ua = unpack(a);
    let ub = unpack(b);
    let d = ua.e - ub.e;
    if (d > 54) {
        // b < 2^(53 − d) ulp(a) ≤ ulp(a)/4: the sum rounds to a.
        return a;
    }
    return round_f64(add(shl(ua.m, u32(d)), ub.m), ub.e - 1075);
}

// Component j (flat index) of the velocities, squared, as f64 bits.
fn square(j: u32) -> vec2<u32> {
    if (F64) {
        return square64(vec2<u32>(vel[2u * j + 1u], vel[2u * j]));
    }
    return square32(vel[j]);
}

// |v|² of particle k as the host sums it: ((v₀² + v₁²) + v₂²), in f64.
fn speed2(k: u32) -> vec2<u32> {
    let d = P.dim;
    var s = square(d * k);
    for (var a = 1u; a < d; a = a + 1u) {
        s = add64(s, square(d * k + a));
    }
    return s;
}

// The extra real of particle k as bits (f32: 0, its bits), 0 for a NaN or a negative value
// (the host's fold from 0 with `f64::max` passes them over).
fn extra_of(k: u32) -> vec2<u32> {
    if (P.extra_at == NONE) {
        return vec2<u32>(0u, 0u);
    }
    var b: vec2<u32>;
    var inf: vec2<u32>;
    if (F64) {
        b = vec2<u32>(extra[P.extra_at + 2u * k + 1u], extra[P.extra_at + 2u * k]);
        inf = INF;
    } else {
        b = vec2<u32>(0u, extra[P.extra_at + k]);
        inf = vec2<u32>(0u, 0x7f800000u);
    }
    let sign = select(b.y, b.x, F64) >> 31u;
    if (sign != 0u || above(b, inf)) {
        return vec2<u32>(0u, 0u);
    }
    return b;
}

fn larger(a: vec4<u32>, b: vec4<u32>) -> vec4<u32> {
    return vec4<u32>(select(a.xy, b.xy, above(b.xy, a.xy)), select(a.zw, b.zw, above(b.zw, a.zw)));
}

// The tree over `best` (every thread of the workgroup calls it); the maxima end in best[0].
fn reduce(t: u32) {
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if (t < s) {
            best[t] = larger(best[t], best[t + s]);
        }
        workgroupBarrier();
    }
}

// The exact |v|² costs some hundred integer operations, so `partial` computes it only where it
// may be the workgroup's largest, as bounds from f32 tell: each component with its significand
// truncated to 23 bits (within 2^−23 of it; 0 below 2^−60), squared and summed in f32 (fused
// or not, within 2^−21 of the exact sum s), gives [s(1 − δ) − τ, s(1 + δ) + τ] ∋ the host's
// |v|², δ = 2^−16 and τ = 2^−116 (more than the components taken as 0 add) leaving room for the
// bounds' own rounding. A particle whose upper bound is below another's lower bound does not
// hold the maximum.
const DELTA: f32 = 0.0000152587890625;

struct Bounds {
    lo: f32,
    hi: f32,
    // A component from 2^63 up (its square may pass f32's largest), ∞ or NaN: no bounds (the
    // exact value decides; a NaN |v|² counts as 0).
    open: bool,
    // Every component ±0: |v|² is +0.
    zero: bool,
};

fn bounds(k: u32) -> Bounds {
    let d = P.dim;
    var s: f32 = 0.0;
    var open = false;
    var zero = true;
    for (var a = 0u; a < d; a = a + 1u) {
        let j = d * k + a;
        var e: i32;
        var top: u32;
        if (F64) {
            let hi = vel[2u * j + 1u] & 0x7fffffffu;
            let lo = vel[2u * j];
            e = i32(hi >> 20u) - 1023;
            top = ((hi & 0xfffffu) << 3u) | (lo >> 29u);
            zero = zero && (hi | lo) == 0u;
        } else {
            let b = vel[j] & 0x7fffffffu;
            e = i32(b >> 23u) - 127;
            top = b & 0x7fffffu;
            zero = zero && b == 0u;
        }
        open = open || e >= 63;
        if (e >= -60 && e < 63) {
            let c = bitcast<f32>((u32(e + 127) << 23u) | top);
            s = s + c * c;
        }
    }
    if (open) {
        return Bounds(0.0, 0.0, true, false);
    }
    let tau = bitcast<f32>(0x05800000u);
    return Bounds(max(s * (1.0 - DELTA) - tau, 0.0), s * (1.0 + DELTA) + tau, false, zero);
}

var<workgroup> lows: array<f32, WG>;

// Workgroup g: the maxima over particles [WG PER g, WG PER (g + 1)), thread t taking those
// t apart by WG (its lower bounds, then, where they may hold the maximum, the exact |v|²); a NaN
// |v|² counts as 0, as on the host.
@compute @workgroup_size(WG)
fn partial(
    @builtin(local_invocation_index) t: u32,
    @builtin(workgroup_id) w: vec3<u32>,
    @builtin(num_workgroups) nw: vec3<u32>,
) {
    let g = w.x + nw.x * w.y;
    let first = WG * PER * g + t;
    var lo: f32 = 0.0;
    // Per particle: its upper bound, +∞ without bounds, −1 at rest or past the end.
    var hi: array<f32, PER>;
    for (var i = 0u; i < PER; i = i + 1u) {
        let k = first + WG * i;
        hi[i] = -1.0;
        if (k < P.n) {
            let b = bounds(k);
            lo = max(lo, b.lo);
            if (b.open) {
                hi[i] = bitcast<f32>(0x7f800000u);
            } else if (!b.zero) {
                hi[i] = b.hi;
            }
        }
    }
    lows[t] = lo;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if (t < s) {
            lows[t] = max(lows[t], lows[t + s]);
        }
        workgroupBarrier();
    }
    let cut = lows[0];
    var m = vec4<u32>(0u);
    for (var i = 0u; i < PER; i = i + 1u) {
        let k = first + WG * i;
        if (k < P.n) {
            var v = vec2<u32>(0u, 0u);
            if (hi[i] >= 0.0 && hi[i] >= cut) {
                v = speed2(k);
                if (above(v, INF)) {
                    v = vec2<u32>(0u, 0u);
                }
            }
            m = larger(m, vec4<u32>(v, extra_of(k)));
        }
    }
    best[t] = m;
    reduce(t);
    if (t == 0u) {
        part[g] = best[0];
    }
}

// One workgroup: the maxima over the partial ones.
@compute @workgroup_size(WG)
fn total(@builtin(local_invocation_index) t: u32) {
    var m = vec4<u32>(0u);
    for (var g = t; g < P.groups; g = g + WG) {
        m = larger(m, part[g]);
    }
    best[t] = m;
    reduce(t);
    if (t == 0u) {
        result[0] = best[0];
    }
}
