//! Advection in lanes: the semi-Lagrangian and MacCormack passes of [`super`], written once over
//! the SIMD layer ([`crate::simd::P`]) and compiled per level.
//!
//! Why: a backtrace is a chain of dependent steps (velocity at the node, a midpoint, two bilinear
//! samples there, the foot, one more sample), about a hundred cycles of latency per node when
//! made one node at a time; a 512² smoke step spent a third of its time there. In lanes, one
//! chain serves 4 (AVX2) or 8 (AVX-512) nodes. The gathers stay lane by lane (one bounds check
//! per lane): AVX2's hardware gather measured slower than that elsewhere in the core.
//!
//! Every value is the scalar expression's, operation for operation (the same clamps, no fused
//! multiply–adds), so the fields have the same bits at every SIMD level and for any thread
//! count. Conversions to grid indices go through ⌊x⌋ made with 2⁵² (exact for 0 ≤ x < 2⁵¹) and
//! the index read off the bits of k + 2⁵² (exact for k < 2⁵²): pulp has no float-to-integer
//! conversion. A lane whose position is NaN reads a valid cell (its index is clamped into the
//! array) and gives NaN, as the scalar expression does.
use super::{Active, Lay, Node, Vel};
use crate::simd::{self, Kernel, Simd, P};
use crate::vector::Real;

type V<S> = P<S, Real>;

/// 2⁵²: x + 2⁵² − 2⁵² rounds x ≥ 0 to an integer.
const MAGIC: Real = 4_503_599_627_370_496.0;
/// The mantissa bits of an f64.
const MANTISSA: u64 = (1 << 52) - 1;
/// Most lanes of any level (AVX-512, f64).
const MAX_LANES: usize = 8;

/// `f64::clamp` lane by lane, with its bits: NaN stays NaN, −0 stays −0.
#[inline(always)]
fn clamp<S: Simd>(x: V<S>, lo: V<S>, hi: V<S>) -> V<S> {
    let x = x.lt(lo).select(lo, x);
    x.gt(hi).select(hi, x)
}

/// ⌊x⌋ for 0 ≤ x < 2⁵¹ (NaN stays NaN).
#[inline(always)]
fn floor<S: Simd>(x: V<S>) -> V<S> {
    let m = V::splat(x.s, MAGIC);
    let r = (x + m) - m;
    r.gt(x).select(r - V::splat(x.s, 1.0), r)
}

/// A layout (`Lay`) as lane constants.
#[derive(Clone, Copy)]
struct LaneLay<S: Simd> {
    w: usize,
    /// The largest first tap: the four taps of k are k, k + 1, k + w, k + w + 1.
    kmax: usize,
    wf: V<S>,
    wm: V<S>,
    hm: V<S>,
    wm1: V<S>,
    hm1: V<S>,
    ox: V<S>,
    oy: V<S>,
}

/// The taps of bilinear interpolation at one point per lane: the first tap's index and the
/// weights.
struct Taps<S: Simd> {
    at: [usize; MAX_LANES],
    tx: V<S>,
    ty: V<S>,
}

impl<S: Simd> LaneLay<S> {
    #[inline(always)]
    fn new(s: S, l: Lay) -> Self {
        let sp = |x: Real| V::splat(s, x);
        let (wm, hm) = (l.w as i32 - 1, l.h as i32 - 1);
        LaneLay {
            w: l.w,
            kmax: l.w * l.h - l.w - 2,
            wf: sp(l.w as Real),
            wm: sp(wm as Real),
            hm: sp(hm as Real),
            wm1: sp((wm - 1) as Real),
            hm1: sp((hm - 1) as Real),
            ox: sp(l.ox),
            oy: sp(l.oy),
        }
    }

    /// `Lay::sample`'s index arithmetic at (x, y) (m).
    #[inline(always)]
    fn taps(&self, x: V<S>, y: V<S>, inv_dx: V<S>) -> Taps<S> {
        let s = x.s;
        let zero = V::zero(s);
        let fx = clamp(x * inv_dx - self.ox, zero, self.wm);
        let fy = clamp(y * inv_dx - self.oy, zero, self.hm);
        let (i, j) = (floor(fx), floor(fy));
        let (i, j) = (i.gt(self.wm1).select(self.wm1, i), j.gt(self.hm1).select(self.hm1, j));
        let k = ((i + self.wf * j) + V::splat(s, MAGIC)).to_array();
        let mut at = [0; MAX_LANES];
        for (a, k) in at.iter_mut().zip(&k[..V::<S>::lanes()]) {
            // k + 2⁵² has k in its mantissa bits (exact below 2⁵²; `validate` caps cells at 2³⁴).
            *a = ((k.to_bits() & MANTISSA) as usize).min(self.kmax);
        }
        Taps { at, tx: fx - i, ty: fy - j }
    }

    /// The four values of `a` at the taps: (k, k + 1, k + w, k + w + 1).
    #[inline(always)]
    fn corners(&self, s: S, t: &Taps<S>, a: &[Real]) -> [V<S>; 4] {
        let w = self.w;
        let mut c = [[0.0; MAX_LANES]; 4];
        for l in 0..V::<S>::lanes() {
            let q = &a[t.at[l]..t.at[l] + w + 2];
            c[0][l] = q[0];
            c[1][l] = q[1];
            c[2][l] = q[w];
            c[3][l] = q[w + 1];
        }
        // Not `c.map(..)`: its closure can stay out of line (a call per load) in a build of
        // several codegen units.
        [V::load(s, &c[0]), V::load(s, &c[1]), V::load(s, &c[2]), V::load(s, &c[3])]
    }
}

impl<S: Simd> Taps<S> {
    /// Bilinear interpolation between the corners (`Lay::sample`'s expression).
    #[inline(always)]
    fn lerp(&self, [a00, a10, a01, a11]: [V<S>; 4]) -> V<S> {
        let one = V::splat(self.tx.s, 1.0);
        let (tx, ty) = (self.tx, self.ty);
        (one - ty) * ((one - tx) * a00 + tx * a10) + ty * ((one - tx) * a01 + tx * a11)
    }
}

/// min and max of the corners, by plain compares in `Lay::sample`'s order (the levels' own
/// min/max differ between ±0 and at NaN).
#[inline(always)]
fn bounds<S: Simd>([a00, a10, a01, a11]: [V<S>; 4]) -> (V<S>, V<S>) {
    let min = |a: V<S>, b: V<S>| a.lt(b).select(a, b);
    let max = |a: V<S>, b: V<S>| a.gt(b).select(a, b);
    (min(min(a00, a10), min(a01, a11)), max(max(a00, a10), max(a01, a11)))
}

/// MacCormack's corrected value: hat + ½(src − back), clamped to (lo, hi), the min and max of
/// the values the backtrace interpolated between.
#[inline(always)]
fn maccormack<S: Simd>(hat: V<S>, src: V<S>, back: V<S>, (lo, hi): (V<S>, V<S>)) -> V<S> {
    clamp(hat + V::splat(hat.s, 0.5) * (src - back), lo, hi)
}

/// The velocity field (`Vel`) as lane constants.
struct LaneVel<'a, S: Simd> {
    u: &'a [Real],
    v: &'a [Real],
    lu: LaneLay<S>,
    lv: LaneLay<S>,
    inv_dx: V<S>,
    xmax: V<S>,
    ymax: V<S>,
}

impl<'a, S: Simd> LaneVel<'a, S> {
    #[inline(always)]
    fn new(s: S, vel: &Vel<'a>) -> Self {
        LaneVel {
            u: vel.u,
            v: vel.v,
            lu: LaneLay::new(s, vel.lu),
            lv: LaneLay::new(s, vel.lv),
            inv_dx: V::splat(s, vel.inv_dx),
            xmax: V::splat(s, vel.xmax),
            ymax: V::splat(s, vel.ymax),
        }
    }

    /// `Vel::at`.
    #[inline(always)]
    fn at(&self, s: S, x: V<S>, y: V<S>) -> (V<S>, V<S>) {
        let tu = self.lu.taps(x, y, self.inv_dx);
        let tv = self.lv.taps(x, y, self.inv_dx);
        (tu.lerp(self.lu.corners(s, &tu, self.u)), tv.lerp(self.lv.corners(s, &tv, self.v)))
    }

    /// `Vel::node` at nodes a..a + lanes of row b.
    #[inline(always)]
    fn node(&self, s: S, kind: Node, a: usize, b: usize) -> (V<S>, V<S>) {
        let (wu, wv) = (self.lu.w, self.lv.w);
        let ld = |x: &[Real], k: usize| V::load(s, &x[k..]);
        let (u, v) = (self.u, self.v);
        let (half, quarter) = (V::splat(s, 0.5), V::splat(s, 0.25));
        match kind {
            Node::Cell => (
                half * (ld(u, a + wu * (b + 1)) + ld(u, a + 1 + wu * (b + 1))),
                half * (ld(v, (a + 1) + wv * b) + ld(v, (a + 1) + wv * (b + 1))),
            ),
            Node::U => (
                ld(u, a + wu * b),
                quarter
                    * ((ld(v, a + wv * (b - 1)) + ld(v, a + 1 + wv * (b - 1)))
                        + (ld(v, a + wv * b) + ld(v, a + 1 + wv * b))),
            ),
            Node::V => (
                quarter
                    * ((ld(u, a - 1 + wu * b) + ld(u, a + wu * b))
                        + (ld(u, a - 1 + wu * (b + 1)) + ld(u, a + wu * (b + 1)))),
                ld(v, a + wv * b),
            ),
        }
    }

    /// `Vel::trace_from`: where the points moving at (a, b) were dt ago (RK2, midpoint), clamped.
    #[inline(always)]
    fn trace(&self, s: S, (x, y): (V<S>, V<S>), (a, b): (V<S>, V<S>), dt: Real) -> (V<S>, V<S>) {
        let zero = V::zero(s);
        let (h, d) = (V::splat(s, 0.5 * dt), V::splat(s, dt));
        let (xm, ym) = (clamp(x - h * a, zero, self.xmax), clamp(y - h * b, zero, self.ymax));
        let (a, b) = self.at(s, xm, ym);
        (clamp(x - d * a, zero, self.xmax), clamp(y - d * b, zero, self.ymax))
    }
}

/// The positions (m) of nodes a..a + lanes of row b of a layout.
#[inline(always)]
fn positions<S: Simd>(s: S, lay: Lay, dx: Real, a: usize, b: usize) -> (V<S>, V<S>) {
    let iota = V::from_fn(s, |l| l as Real);
    let x = ((V::splat(s, super::re(a)) + iota) + V::splat(s, lay.ox)) * V::splat(s, dx);
    (x, V::splat(s, (super::re(b) + lay.oy) * dx))
}

/// The column groups of a row a0..a1 at `l` lanes: every full group, then one ending at a1 that
/// overlaps the last (its nodes are made twice, with the same values). Needs a1 − a0 ≥ l.
#[inline(always)]
fn groups(a0: usize, a1: usize, l: usize) -> impl Iterator<Item = usize> {
    let full = (a1 - a0) / l;
    let tail = (!(a1 - a0).is_multiple_of(l)).then_some(a1 - l);
    (0..full).map(move |g| a0 + g * l).chain(tail)
}

/// One row b of `super::advect_faces`: semi-Lagrangian (`hat` = None) or MacCormack (`hat` =
/// the semi-Lagrangian result with ghosts filled), into `row`.
pub(super) struct FaceRow<'a> {
    pub vel: &'a Vel<'a>,
    pub dx: Real,
    pub act: &'a Active<'a>,
    pub src: &'a [Real],
    pub hat: Option<&'a [Real]>,
    pub dt: Real,
    pub b: usize,
    pub row: &'a mut [Real],
}

impl Kernel for FaceRow<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let FaceRow { vel, dx, act, src, hat, dt, b, row } = self;
        let l = V::<S>::lanes();
        if act.a1 - act.a0 < l {
            // Narrower than a vector: the same code at one lane.
            return FaceRow { vel, dx, act, src, hat, dt, b, row }.run(pulp::Scalar::new());
        }
        let lay = act.lay;
        let (lv, ll) = (LaneVel::new(s, vel), LaneLay::new(s, lay));
        let fill = V::splat(s, act.fill);
        let mask = &act.mask[lay.w * b..lay.w * (b + 1)];
        for a in groups(act.a0, act.a1, l) {
            let p = positions(s, lay, dx, a, b);
            let v0 = lv.node(s, act.kind, a, b);
            let back = lv.trace(s, p, v0, dt);
            let tb = ll.taps(back.0, back.1, lv.inv_dx);
            let cb = ll.corners(s, &tb, src);
            let val = match hat {
                None => tb.lerp(cb),
                Some(hat) => {
                    let fwd = lv.trace(s, p, v0, -dt);
                    let tf = ll.taps(fwd.0, fwd.1, lv.inv_dx);
                    let back = tf.lerp(ll.corners(s, &tf, hat));
                    let k = lay.w * b + a;
                    maccormack(V::load(s, &hat[k..]), V::load(s, &src[k..]), back, bounds(cb))
                }
            };
            V::load(s, &mask[a..]).gt(V::zero(s)).select(val, fill).store(&mut row[a..]);
        }
    }
}

/// Row j of the smoke's advection (`StableFluid::advect_scalars`): density and temperature
/// along one backtrace per cell, semi-Lagrangian (`hat` = None) or MacCormack (`hat` = the
/// semi-Lagrangian density and temperature).
pub(super) struct SmokeRow<'a> {
    pub vel: &'a Vel<'a>,
    pub dx: Real,
    pub lay: Lay,
    pub fluid: &'a [Real],
    pub ambient: Real,
    pub src: [&'a [Real]; 2],
    pub hat: Option<[&'a [Real]; 2]>,
    pub dt: Real,
    pub j: usize,
    pub out: [&'a mut [Real]; 2],
}

impl Kernel for SmokeRow<'_> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, s: S) {
        let SmokeRow { vel, dx, lay, fluid, ambient, src, hat, dt, j, out } = self;
        let (l, nx) = (V::<S>::lanes(), lay.w);
        if nx < l {
            return SmokeRow { vel, dx, lay, fluid, ambient, src, hat, dt, j, out }.run(pulp::Scalar::new());
        }
        let (lv, lc) = (LaneVel::new(s, vel), LaneLay::new(s, lay));
        let [d, t] = out;
        let (zero, amb) = (V::zero(s), V::splat(s, ambient));
        let f = &fluid[nx * j..nx * (j + 1)];
        for i in groups(0, nx, l) {
            let p = positions(s, lay, dx, i, j);
            let v0 = lv.node(s, Node::Cell, i, j);
            let back = lv.trace(s, p, v0, dt);
            let tb = lc.taps(back.0, back.1, lv.inv_dx);
            let (cd, ct) = (lc.corners(s, &tb, src[0]), lc.corners(s, &tb, src[1]));
            let (dv, tv) = match hat {
                None => (tb.lerp(cd), tb.lerp(ct)),
                Some([dh, th]) => {
                    let fwd = lv.trace(s, p, v0, -dt);
                    let tf = lc.taps(fwd.0, fwd.1, lv.inv_dx);
                    let (db, tb) = (tf.lerp(lc.corners(s, &tf, dh)), tf.lerp(lc.corners(s, &tf, th)));
                    let k = nx * j + i;
                    let ld = |a: &[Real]| V::load(s, &a[k..]);
                    (maccormack(ld(dh), ld(src[0]), db, bounds(cd)), maccormack(ld(th), ld(src[1]), tb, bounds(ct)))
                }
            };
            let m = V::load(s, &f[i..]).gt(zero);
            m.select(dv, zero).store(&mut d[i..]);
            m.select(tv, amb).store(&mut t[i..]);
        }
    }
}

/// Runs a row kernel at the level of the core.
#[inline]
pub(super) fn run<K: Kernel>(k: K) -> K::Output {
    simd::dispatch(simd::level(), k)
}
