// DEM grains on the device (dem.rs): discs (2D) and spheres (3D) with the CPU's contact laws
// (rust_core/src/terms/contacts: Material::normal, onset, pair, commit). One step is the cell
// list (cells.wgsl, its own bind group), then `contacts`, `integrate` and `commit` here;
// `energy` runs only when the books are read.
//
// Deterministic gather, no float atomics: the thread of grain i computes only grain i's force
// and torque, over the 3^d cells around its own (z, y, x, each cell's grains by index; a row's
// three cells along x are consecutive in `order`, so each row is one run of slots), then the
// walls in order. A pair is always evaluated with its lower index as the first grain (the
// same inputs, the same code site, so the same bits at both ends), and the second grain takes
// the negated force: Σ F = 0 up to the rounding of each grain's own sum.
//
// Tangential history by pair key: each grain keeps up to `cap` entries (partner: a grain
// index, or n + w for wall w) with the spring ξ seen from the pair's first grain, so both ends
// hold the same ξ, bit for bit. `keys` and `vals` hold two halves: the committed history
// (after a step: ξ ← ξ_capped + dt·v_t(new), and the energy ½k_t|ξ|² it stores), read by
// `contacts`; and what `contacts` leaves for `commit` (ξ capped, the tangential force, the
// normal force). Three vectors are kept as `dim` components each.
// The host prepends the precision header.

struct Params {
    // Grains, dimension, cells along x, y, z (z = 1 in 2D), history capacity per grain, the
    // normal law (0 linear, 1 Hertz), walls, rolling resistance (0 off, 1 on), axial components
    // (1 in 2D, 3 in 3D), and the books' flag below.
    n: u32,
    dim: u32,
    cx: u32,
    cy: u32,
    cz: u32,
    cap: u32,
    hertz: u32,
    walls: u32,
    roll: u32,
    ad: u32,
    // 1: a contact's first evaluation leaves out its normal spring's energy (see `contacts`);
    // 0 on the first step after `Dem::new`, whose overlaps the books counted from the start.
    primed: u32,
    pad: u32,
    // k_n, the damping ratio ζ, friction μ, k_t/k_n, γ_t/γ_n (√ratio linear, √(1.5 ratio)
    // Hertz), β of I = β m r², dt, gravity, rolling friction μ_r and rolling damping η_r, drag.
    kn: real,
    zeta: real,
    mu: real,
    ratio: real,
    tdamp: real,
    beta: real,
    dt: real,
    gx: real,
    gy: real,
    gz: real,
    mu_r: real,
    eta_r: real,
    // Linear drag b (kg/s; 0: none): F = −b v on the free grains.
    drag: real,
};

const WG: u32 = 64u;

@group(0) @binding(0) var<uniform> P: Params;
// The state in the caller's order: positions and velocities (`dim` each), ω (1 in 2D, 3 in 3D);
// in 2D `omg` then holds the n rotation angles after the n spins.
@group(0) @binding(1) var<storage, read_write> pos: array<real>;
@group(0) @binding(2) var<storage, read_write> vel: array<real>;
@group(0) @binding(3) var<storage, read_write> omg: array<real>;
// Per grain: radius, mass, and 1 for a free grain, 0 for a pinned one (a fixed obstacle).
@group(0) @binding(4) var<storage, read> props: array<real>;
// Per wall, WS values (shape.rs's `Shape::row`, as particles.wgsl reads its colliders): kind
// (0 plane, 2 sphere, 3 capsule, 4 oriented box; no 1, a box), ζ, μ, a capsule's radius; two
// points padded to 4 (a plane's point and unit normal, a sphere's centre then its radius and
// `inside`, a capsule's ends, a box's centre and half extents); a box's three unit axes.
@group(0) @binding(5) var<storage, read> walls: array<real>;
// The cell list (cells.wgsl): each grain's cell, each cell's first slot, the grains by cell.
@group(0) @binding(6) var<storage, read> cell_of: array<u32>;
@group(0) @binding(7) var<storage, read> start: array<u32>;
@group(0) @binding(8) var<storage, read> order: array<u32>;
// Per grain: force (3) and torque (3) of this step's evaluation.
@group(0) @binding(9) var<storage, read_write> load: array<real>;
// Contact keys: [0, n(cap+1)) committed, [n(cap+1), 2n(cap+1)) evaluated; per grain its count
// then `cap` partners.
@group(0) @binding(10) var<storage, read_write> keys: array<u32>;
// Contact values: committed (ξ, its energy; with rolling resistance also θ_r, its energy) for
// n·cap entries, then evaluated (ξ capped, f_t, the normal n, f_n, the overlap δ; with rolling
// resistance also θ_r capped and the rolling torque on the first grain). `stride_in` and
// `stride_out` give their sizes; axial vectors take 1 value in 2D (z), 3 in 3D.
@group(0) @binding(11) var<storage, read_write> vals: array<real>;
// [0]: the first grain whose state stopped being finite; [1]: the first grain with more contacts
// than `cap` (u32::MAX: none); [2]: the contacts `tally` counted.
@group(0) @binding(12) var<storage, read_write> flag: array<atomic<u32>>;
// Per grain, J: [0, n) dissipated by the normal dashpots, [n, 2n) by friction (sliding, and the
// springs of contacts that ended), [2n, 3n) the contact potential (written by `energy`), [3n, 4n)
// dissipated by drag. A pair's books go to its first grain (pinned or not); each entry written
// only by the thread that owns it.
@group(0) @binding(13) var<storage, read_write> books: array<real>;

fn rad(i: u32) -> real {
    return props[3u * i];
}

fn free(i: u32) -> bool {
    return props[3u * i + 2u] != 0.0;
}

// 1/m, 0 for a pinned grain (the CPU's `inv_mass`): a pair with one has m* = m of the free one.
fn inv_mass(i: u32) -> real {
    if (free(i)) {
        return 1.0 / props[3u * i + 1u];
    }
    return 0.0;
}

fn zero3() -> vec3<real> {
    return vec3<real>(0.0, 0.0, 0.0);
}

fn xat(i: u32) -> vec3<real> {
    if (P.dim == 2u) {
        return vec3<real>(pos[2u * i], pos[2u * i + 1u], 0.0);
    }
    return vec3<real>(pos[3u * i], pos[3u * i + 1u], pos[3u * i + 2u]);
}

fn vat(i: u32) -> vec3<real> {
    if (P.dim == 2u) {
        return vec3<real>(vel[2u * i], vel[2u * i + 1u], 0.0);
    }
    return vec3<real>(vel[3u * i], vel[3u * i + 1u], vel[3u * i + 2u]);
}

// ω of grain i (2D: about z).
fn wat(i: u32) -> vec3<real> {
    if (P.dim == 2u) {
        return vec3<real>(0.0, 0.0, omg[i]);
    }
    return vec3<real>(omg[3u * i], omg[3u * i + 1u], omg[3u * i + 2u]);
}

// `dim` components of vals from offset o.
fn vec_at(o: u32) -> vec3<real> {
    if (P.dim == 2u) {
        return vec3<real>(vals[o], vals[o + 1u], 0.0);
    }
    return vec3<real>(vals[o], vals[o + 1u], vals[o + 2u]);
}

fn put(o: u32, v: vec3<real>) {
    vals[o] = v.x;
    vals[o + 1u] = v.y;
    if (P.dim == 3u) {
        vals[o + 2u] = v.z;
    }
}

// An axial vector at vals[o] (2D: along z).
fn ax_at(o: u32) -> vec3<real> {
    if (P.dim == 2u) {
        return vec3<real>(0.0, 0.0, vals[o]);
    }
    return vec3<real>(vals[o], vals[o + 1u], vals[o + 2u]);
}

fn put_ax(o: u32, v: vec3<real>) {
    if (P.dim == 2u) {
        vals[o] = v.z;
    } else {
        vals[o] = v.x;
        vals[o + 1u] = v.y;
        vals[o + 2u] = v.z;
    }
}

// Values per committed and per evaluated history entry.
fn stride_in() -> u32 {
    return P.dim + 1u + P.roll * (P.ad + 1u);
}

fn stride_out() -> u32 {
    return 3u * P.dim + 2u + P.roll * 2u * P.ad;
}

const WS: u32 = 24u;
// False (set by the host) when every wall is a plane: the other shapes' code is dead then.
const SHAPED: bool = true;

fn wall_vec(w: u32, o: u32) -> vec3<real> {
    let b = WS * w + o;
    return vec3<real>(walls[b], walls[b + 1u], walls[b + 2u]);
}

// A wall's surface seen from a grain's centre: the unit normal into the allowed side and the
// signed distance (the CPU's `Shape::closest`, expression by expression).
struct Surf {
    u: vec3<real>,
    s: real,
}

// The round rule of the ball and the capsule (the CPU's `round_surface`): about c at radius r,
// radial u = (x − c)/|x − c| (up at c itself); outside kept s = l − r, a bowl s = r − l, −u.
fn round_surface(x: vec3<real>, c: vec3<real>, r: real, inside: bool) -> Surf {
    let rel = x - c;
    let l = sqrt(dot(rel, rel));
    var u = zero3();
    if (l > 0.0) {
        u = rel / l;
    } else if (P.dim == 2u) {
        u.y = 1.0;
    } else {
        u.z = 1.0;
    }
    if (inside) {
        return Surf(zero3() - u, r - l);
    }
    return Surf(u, l - r);
}

fn wall_surface(w: u32, x: vec3<real>) -> Surf {
    let kind = walls[WS * w];
    let a = wall_vec(w, 4u);
    let b = wall_vec(w, 8u);
    if (!SHAPED || kind == 0.0) {
        return Surf(b, dot(x - a, b));
    }
    if (kind == 2.0) {
        return round_surface(x, a, b.x, b.y != 0.0);
    }
    if (kind == 3.0) {
        // The axis point nearest x: a + t (b − a), t clamped to [0, 1].
        let ab = b - a;
        let l2 = dot(ab, ab);
        var t: real = 0.0;
        if (l2 > 0.0) {
            t = clamp(dot(x - a, ab) / l2, 0.0, 1.0);
        }
        return round_surface(x, a + ab * t, walls[WS * w + 3u], false);
    }
    // The oriented box: local coordinates q_j = (x − c)·u_j; inside, the least-deep face
    // (the first on a tie); outside across one face, that face; else the clamped point.
    let rel = x - a;
    var q = zero3();
    var outside = 0u;
    var across = 0u;
    var least: real = 0.0;
    var lj = 0u;
    for (var j = 0u; j < P.dim; j = j + 1u) {
        q[j] = dot(rel, wall_vec(w, 12u + 4u * j));
        let depth = b[j] - abs(q[j]);
        // Outside on this axis (NaN included: the distance comes out NaN).
        if (!(depth >= 0.0)) {
            outside = outside + 1u;
            across = j;
        }
        if (j == 0u || depth < least) {
            least = depth;
            lj = j;
        }
    }
    if (outside <= 1u) {
        let j = select(lj, across, outside == 1u);
        var u = wall_vec(w, 12u + 4u * j);
        if (q[j] < 0.0) {
            u = zero3() - u;
        }
        if (outside == 0u) {
            return Surf(u, -least);
        }
        return Surf(u, abs(q[j]) - b[j]);
    }
    var p = a;
    for (var j = 0u; j < P.dim; j = j + 1u) {
        p = p + wall_vec(w, 12u + 4u * j) * clamp(q[j], -b[j], b[j]);
    }
    let off = x - p;
    let dist = sqrt(dot(off, off));
    return Surf(off / dist, dist);
}

// Tangential stiffness k_t at overlap d: ratio·k_n (linear), ratio·(3/2)k_n√δ (Hertz).
fn kt_of(d: real) -> real {
    if (P.hertz != 0u) {
        return P.ratio * 1.5 * P.kn * sqrt(d);
    }
    return P.ratio * P.kn;
}

// Normal spring energy: ½k_n δ² (linear), ⅖k_n δ^{5/2} (Hertz).
fn un_of(d: real) -> real {
    if (P.hertz != 0u) {
        return 0.4 * P.kn * d * d * sqrt(d);
    }
    return 0.5 * P.kn * d * d;
}

// A contact's coefficients (Material::coef): ½dt/m*, γ_n = 2ζ√(k_n m*) (Hertz: to be times
// δ^{1/4}), γ_t = γ_n·tdamp, μ.
struct Coef {
    h: real,
    gn: real,
    gt: real,
    mu: real,
};

fn coef(inv_m: real, zeta: real, mu: real) -> Coef {
    let gn = 2.0 * zeta * sqrt(P.kn / inv_m);
    return Coef(0.5 * P.dt * inv_m, gn, gn * P.tdamp, mu);
}

// Normal force (clamped at 0) at overlap d and approach speed vn, the dashpot fed the mid-step
// approach speed v_n − ½dt f/m* solved in closed form (Material::normal).
fn normal_force(d: real, vn: real, c: Coef) -> real {
    if (P.hertz != 0u) {
        let sd = sqrt(d);
        let el = P.kn * d * sd;
        let g = c.gn * sqrt(sd);
        let vm = (vn - c.h * el) / (1.0 + c.h * g);
        return max(el + g * vm, 0.0);
    }
    let el = P.kn * d;
    let vm = (vn - c.h * el) * (1.0 / (1.0 + c.h * c.gn));
    return max(el + c.gn * vm, 0.0);
}

// A contact that began during the last step, approaching at vn > 0 with δ ≤ 1.5 vn dt: the
// step's kick corrected for when it began (Material::onset; exact for δ = vn u).
fn onset(f: real, d: real, vn: real, gn: real) -> real {
    let o = P.dt;
    let tau = min(d / vn, o);
    let t = tau + 0.5 * o;
    let k = P.kn;
    var el_j: real;
    var damp_j: real;
    if (P.hertz != 0u) {
        let v15 = vn * sqrt(vn);
        let v125 = vn * sqrt(sqrt(vn));
        el_j = k * v15 * (t * t * sqrt(t) / 2.5 - tau * sqrt(tau) * o);
        damp_j = gn * v125 * (t * sqrt(sqrt(t)) / 1.25 - sqrt(sqrt(tau)) * o);
    } else {
        el_j = k * vn * (0.5 * t * t - tau * o);
        damp_j = gn * vn * (t - o);
    }
    return max(f + (el_j + damp_j) / o, 0.0);
}

// One contact seen from its first grain (Material::pair).
struct Out {
    // Force on the first grain, tangential force, the spring capped, n × f_t.
    f: vec3<real>,
    ft: vec3<real>,
    xi: vec3<real>,
    t: vec3<real>,
    fn_: real,
    // Power the normal and tangential forces draw from the relative motion now (W).
    wn: real,
    wt: real,
};

// Normal n (first grain to the other), overlap d, contact-point relative velocity vc, the
// committed spring xi; `fresh`: the contact formed during the last step.
fn contact(n: vec3<real>, d: real, vc: vec3<real>, c: Coef, xi: vec3<real>, fresh: bool) -> Out {
    let vn = dot(vc, n);
    var f = normal_force(d, vn, c);
    if (fresh && vn > 0.0 && d <= 1.5 * vn * P.dt) {
        f = onset(f, d, vn, c.gn);
    }
    let vt = vc - n * vn;
    let kt = kt_of(d);
    // The spring rotated into the tangent plane, keeping its length.
    var xp = xi;
    let xn = dot(xi, n);
    if (P.dim == 2u) {
        // The tangent line t = n × ẑ: ξ' = ±|ξ| t.
        let t = vec3<real>(n.y, 0.0 - n.x, 0.0);
        let s = dot(xi, t);
        if (xn != 0.0) {
            let l = sqrt(dot(xi, xi));
            xp = select(zero3(), t * select(l, 0.0 - l, s < 0.0), s != 0.0);
        }
    } else if (xn != 0.0) {
        xp = xi - n * xn;
        let l0 = dot(xi, xi);
        let l1 = dot(xp, xp);
        if (l1 > 0.0) {
            xp = xp * sqrt(l0 / l1);
        }
    }
    var gt = c.gt;
    if (P.hertz != 0u) {
        gt = c.gt * sqrt(sqrt(d));
    }
    var ft = xp * (0.0 - kt) - vt * gt;
    let cap = c.mu * f;
    let f2 = dot(ft, ft);
    var xc = xp;
    if (f2 > cap * cap) {
        // Coulomb: the force on the cone, the spring slipped to it.
        ft = ft * (cap / sqrt(f2));
        var inv_kt: real = 0.0;
        if (kt > 0.0) {
            inv_kt = 1.0 / kt;
        }
        // Linear: less the dashpot's share; Hertz: the capped force alone (Material::pair).
        var damp = gt;
        if (P.hertz != 0u) {
            damp = 0.0;
        }
        xc = (ft + vt * damp) * (0.0 - inv_kt);
    }
    return Out(ft - n * f, ft, xc, cross(n, ft), f, f * vn, 0.0 - dot(ft, vc));
}

// Rolling stiffness k_r = 2.25 k_c μ_r² R*² (Ai, Chen, Rotter & Ooi 2011, model C), k_c the
// normal contact stiffness: k_n (linear), (3/2)k_n√δ (Hertz) (Material::kr).
fn kr_of(d: real, reff: real) -> real {
    var kc = P.kn;
    if (P.hertz != 0u) {
        kc = 1.5 * P.kn * sqrt(d);
    }
    return 2.25 * kc * P.mu_r * P.mu_r * reff * reff;
}

// The rolling part of a relative angular velocity: all of it in 2D, less its twist about n in 3D.
fn rolling_part(w: vec3<real>, n: vec3<real>) -> vec3<real> {
    if (P.dim == 2u) {
        return w;
    }
    return w - n * dot(w, n);
}

struct Roll {
    theta: vec3<real>,
    m: vec3<real>,
};

// A contact's rolling resistance (Material::roll_evaluate): the spring θ_r turned into the
// tangent plane keeping its length, −k_r θ_r capped at μ_r R* f_n (it slips, the dashpot off);
// below the cap the dashpot −η_r 2√(I_r k_r) ω_r added, the sum capped again. Returns the spring
// and the torque on the first grain.
fn roll_eval(n: vec3<real>, d: real, wr: vec3<real>, f: real, reff: real, inv_ir: real, theta_in: vec3<real>) -> Roll {
    let kr = kr_of(d, reff);
    var th = theta_in;
    if (P.dim == 3u) {
        let p = rolling_part(th, n);
        let l0 = dot(th, th);
        let l1 = dot(p, p);
        th = p;
        if (l1 > 0.0 && l1 != l0) {
            th = p * sqrt(l0 / l1);
        }
    }
    let ms = th * (0.0 - kr);
    let cap = P.mu_r * reff * f;
    let m2 = dot(ms, ms);
    if (m2 > cap * cap) {
        let k = cap / sqrt(m2);
        return Roll(th * k, ms * k);
    }
    let cr = 2.0 * P.eta_r * sqrt(kr / inv_ir);
    var m = ms - wr * cr;
    let t2 = dot(m, m);
    if (t2 > cap * cap) {
        m = m * (cap / sqrt(t2));
    }
    return Roll(th, m);
}

// 1/(I + m r²) of grain i (0 pinned: it never turns): the rolling dashpot's inertia I_r = 1/(Σ of
// these).
fn inv_ic(i: u32) -> real {
    if (!free(i)) {
        return 0.0;
    }
    let r = rad(i);
    return 1.0 / ((P.beta + 1.0) * props[3u * i + 1u] * r * r);
}

// A pair's geometry at the current state, first grain a < b: normal, overlap, levers and the
// contact-point relative velocity v_a − v_b + (a_a ω_a + a_b ω_b) × n.
struct Geom {
    n: vec3<real>,
    d: real,
    aa: real,
    ab: real,
    vc: vec3<real>,
};

fn geom(a: u32, b: u32, dx: vec3<real>, d2: real) -> Geom {
    let ra = rad(a);
    let rb = rad(b);
    let dist = sqrt(d2);
    var n = zero3();
    if (d2 > 0.0) {
        n = dx * (1.0 / dist);
    }
    let d = (ra + rb) - dist;
    let aa = ra - 0.5 * d;
    let ab = rb - 0.5 * d;
    let vc = vat(a) - vat(b) + cross(wat(a) * aa + wat(b) * ab, n);
    return Geom(n, d, aa, ab, vc);
}

// A grain and wall w whose surface `sf` is: normal (grain to wall) −u, overlap r − s, lever
// r − δ/2, contact-point velocity v + a ω × n (the wall neither moves nor turns).
fn wall_geom(i: u32, sf: Surf) -> Geom {
    let r = rad(i);
    let n = zero3() - sf.u;
    let d = r - sf.s;
    let a = r - 0.5 * d;
    return Geom(n, d, a, 0.0, vat(i) + cross(wat(i) * a, n));
}

// The slot of partner `key` among grain i's committed entries (their count if absent).
fn find(base: u32, count: u32, key: u32) -> u32 {
    var q = 0u;
    for (; q < count; q = q + 1u) {
        if (keys[base + 1u + q] == key) {
            break;
        }
    }
    return q;
}

// Evaluates grain i's contacts at the step's start: force and torque into `load`, the capped
// springs and forces into the evaluated half of the history, the books of the contacts it is
// first of: ½dt·(power now) + the energy its springs store now (the commit closes them), and
// the stored energy of springs whose contact ended. A contact's first evaluation leaves out
// the normal spring's energy: that overlap formed within the last step with no force doing
// work on it (the potential of the books counts it from then on), so leaving it out here books
// that energy, which the scheme made, against dissipation and the totals stay balanced. (The
// CPU books it at the commit of the step that made it.) Not on the first
// step after `Dem::new`: those overlaps were there when the books began.
@compute @workgroup_size(WG)
fn contacts(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let i = order[k];
    let d = P.dim;
    let cap = P.cap;
    let sv = stride_in();
    let sc = stride_out();
    let kin = i * (cap + 1u);
    let kout = P.n * (cap + 1u) + kin;
    let vin = i * cap * sv;
    let vout = P.n * cap * sv + i * cap * sc;
    let count = keys[kin];
    let xi = xat(i);
    let ri = rad(i);
    let c = coords(cell_of[i]);
    var force = zero3();
    var torque = zero3();
    var bn: real = 0.0;
    var bt: real = 0.0;
    var matched = 0u;
    var m = 0u;
    var z0 = 0u;
    var z1 = 0u;
    if (d == 3u) {
        z0 = lo_of(c.z);
        z1 = hi_of(c.z, P.cz);
    }
    for (var z = z0; z <= z1; z = z + 1u) {
        for (var y = lo_of(c.y); y <= hi_of(c.y, P.cy); y = y + 1u) {
            let row = flat(vec3<u32>(0u, y, z));
            for (var s = start[row + lo_of(c.x)]; s < start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                let j = order[s];
                // Two pinned grains never meet (the CPU skips the pair).
                if (j == i || !(free(i) || free(j))) {
                    continue;
                }
                let a = min(i, j);
                let b = max(i, j);
                let dx = xat(b) - xat(a);
                let d2 = dot(dx, dx);
                let rs = rad(a) + rad(b);
                if (!(d2 < rs * rs && d2 > 0.0)) {
                    continue;
                }
                let q = find(kin, count, j);
                let fresh = q == count;
                var x0 = zero3();
                var u0: real = 0.0;
                if (!fresh) {
                    matched = matched | (1u << q);
                    x0 = vec_at(vin + q * sv);
                    u0 = vals[vin + q * sv + d];
                }
                let g = geom(a, b, dx, d2);
                let inv_m = inv_mass(a) + inv_mass(b);
                let o = contact(g.n, g.d, g.vc, coef(inv_m, P.zeta, P.mu), x0, fresh);
                var rr = Roll(zero3(), zero3());
                var ur: real = 0.0;
                if (P.roll != 0u) {
                    // Rolling resistance: +M on the first grain, −M on the other (a couple).
                    var th0 = zero3();
                    if (!fresh) {
                        th0 = ax_at(vin + q * sv + d + 1u);
                        ur = vals[vin + q * sv + d + 1u + P.ad];
                    }
                    let wab = wat(a) - wat(b);
                    let ra = rad(a);
                    let rb = rad(b);
                    let reff = ra * rb / (ra + rb);
                    rr = roll_eval(g.n, g.d, rolling_part(wab, g.n), o.fn_, reff, inv_ic(a) + inv_ic(b), th0);
                    ur = ur - 0.5 * P.dt * dot(rr.m, wab);
                }
                if (i == a) {
                    force = force + o.f;
                    torque = torque + o.t * g.aa + rr.m;
                    bn = bn + (select(un_of(g.d), 0.0, fresh && P.primed != 0u) + 0.5 * P.dt * o.wn);
                    bt = bt + (u0 + 0.5 * P.dt * o.wt) + ur;
                } else {
                    force = force - o.f;
                    torque = torque + o.t * g.ab - rr.m;
                }
                if (m == cap) {
                    atomicMin(&flag[1], i);
                } else {
                    keys[kout + 1u + m] = j;
                    put(vout + m * sc, o.xi);
                    put(vout + m * sc + d, o.ft);
                    put(vout + m * sc + 2u * d, g.n);
                    vals[vout + m * sc + 3u * d] = o.fn_;
                    vals[vout + m * sc + 3u * d + 1u] = g.d;
                    if (P.roll != 0u) {
                        put_ax(vout + m * sc + 3u * d + 2u, rr.theta);
                        put_ax(vout + m * sc + 3u * d + 2u + P.ad, rr.m);
                    }
                    m = m + 1u;
                }
            }
        }
    }
    let inv_mi = inv_mass(i);
    // A pinned grain touches no wall (the CPU ends its wall contacts).
    let nw = select(0u, P.walls, free(i));
    for (var w = 0u; w < nw; w = w + 1u) {
        let sf = wall_surface(w, xi);
        if (!(sf.s < ri)) {
            continue;
        }
        let key = P.n + w;
        let q = find(kin, count, key);
        let fresh = q == count;
        var x0 = zero3();
        var u0: real = 0.0;
        if (!fresh) {
            matched = matched | (1u << q);
            x0 = vec_at(vin + q * sv);
            u0 = vals[vin + q * sv + d];
        }
        let g = wall_geom(i, sf);
        let o = contact(g.n, g.d, g.vc, coef(inv_mi, walls[WS * w + 1u], walls[WS * w + 2u]), x0, fresh);
        var rr = Roll(zero3(), zero3());
        var ur: real = 0.0;
        if (P.roll != 0u) {
            // A wall neither turns nor yields: ω_r = the grain's, R* = r, I_r = I + m r².
            var th0 = zero3();
            if (!fresh) {
                th0 = ax_at(vin + q * sv + d + 1u);
                ur = vals[vin + q * sv + d + 1u + P.ad];
            }
            let wi = wat(i);
            rr = roll_eval(g.n, g.d, rolling_part(wi, g.n), o.fn_, ri, inv_ic(i), th0);
            ur = ur - 0.5 * P.dt * dot(rr.m, wi);
        }
        force = force + o.f;
        torque = torque + o.t * g.aa + rr.m;
        bn = bn + (select(un_of(g.d), 0.0, fresh && P.primed != 0u) + 0.5 * P.dt * o.wn);
        bt = bt + (u0 + 0.5 * P.dt * o.wt) + ur;
        if (m == cap) {
            atomicMin(&flag[1], i);
        } else {
            keys[kout + 1u + m] = key;
            put(vout + m * sc, o.xi);
            put(vout + m * sc + d, o.ft);
            put(vout + m * sc + 2u * d, g.n);
            vals[vout + m * sc + 3u * d] = o.fn_;
            vals[vout + m * sc + 3u * d + 1u] = g.d;
            if (P.roll != 0u) {
                put_ax(vout + m * sc + 3u * d + 2u, rr.theta);
                put_ax(vout + m * sc + 3u * d + 2u + P.ad, rr.m);
            }
            m = m + 1u;
        }
    }
    // Contacts that ended: their springs' energy is lost (to friction), booked by the first.
    for (var q = 0u; q < count; q = q + 1u) {
        let key = keys[kin + 1u + q];
        if ((matched & (1u << q)) == 0u && (key >= P.n || i < key)) {
            bt = bt + vals[vin + q * sv + d];
            if (P.roll != 0u) {
                bt = bt + vals[vin + q * sv + d + 1u + P.ad];
            }
        }
    }
    keys[kout] = m;
    for (var a = 0u; a < 3u; a = a + 1u) {
        load[6u * i + a] = force[a];
        load[6u * i + 3u + a] = torque[a];
    }
    books[i] = books[i] + bn;
    books[P.n + i] = books[P.n + i] + bt;
}

// Semi-implicit Euler: v' = v + dt (f/m + g), x' = x + dt v', ω' = ω + τ (dt/I), I = β m r²;
// in 2D also the angle, θ' = θ + dt ω'. f holds the contacts' force and, with drag, −b v at the
// step's start (the CPU's terms, summed before the kick); drag books dt·b|v|² per step, as the
// CPU books a term's power (`Forces::book_power`: the power at the step's start times dt). A
// pinned grain never moves or turns (the CPU's `accel` of inv_mass 0, its `end_step`).
@compute @workgroup_size(WG)
fn integrate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index(gid);
    if (i >= P.n || !free(i)) {
        return;
    }
    let d = P.dim;
    let r = rad(i);
    let m = props[3u * i + 1u];
    let inv_m = 1.0 / m;
    let grav = vec3<real>(P.gx, P.gy, P.gz);
    var broken = false;
    var v2: real = 0.0;
    for (var a = 0u; a < d; a = a + 1u) {
        let v0 = vel[d * i + a];
        var f = load[6u * i + a];
        if (P.drag > 0.0) {
            f = f + v0 * (0.0 - P.drag);
            v2 = v2 + v0 * v0;
        }
        let v = v0 + (f * inv_m + grav[a]) * P.dt;
        let x = pos[d * i + a] + v * P.dt;
        vel[d * i + a] = v;
        pos[d * i + a] = x;
        broken = broken || bad(v) || bad(x);
    }
    if (P.drag > 0.0) {
        books[3u * P.n + i] = books[3u * P.n + i] + P.dt * (P.drag * v2);
    }
    let s = P.dt * (1.0 / (P.beta * m * r * r));
    if (d == 2u) {
        let w = omg[i] + load[6u * i + 5u] * s;
        omg[i] = w;
        // The rotation angle with the new ω (semi-implicit, as x with v'), the CPU's `end_step`.
        let a = omg[P.n + i] + P.dt * w;
        omg[P.n + i] = a;
        broken = broken || bad(w) || bad(a);
    } else {
        for (var a = 0u; a < 3u; a = a + 1u) {
            let w = omg[3u * i + a] + load[6u * i + 3u + a] * s;
            omg[3u * i + a] = w;
            broken = broken || bad(w);
        }
    }
    if (broken) {
        atomicMin(&flag[0], i);
    }
}

// Commits the step for grain i's evaluated contacts at the new state (Material::commit,
// Commit::Full): the spring follows the contact point, ξ ← ξ_capped + dt·v_t (frictionless
// contacts hold none), and the books close with ½dt·(the power the evaluated force draws at the
// step's end) less the energy the springs now store, each force's power through the geometry
// it was evaluated with, as the CPU's. Done now rather than at the next evaluation (as the CPU defers it):
// the same arithmetic on the same state, and the history is whole between calls.
@compute @workgroup_size(WG)
fn commit(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index(gid);
    if (i >= P.n) {
        return;
    }
    let d = P.dim;
    let cap = P.cap;
    let sv = stride_in();
    let sc = stride_out();
    let kin = i * (cap + 1u);
    let kout = P.n * (cap + 1u) + kin;
    let vin = i * cap * sv;
    let vout = P.n * cap * sv + i * cap * sc;
    let count = keys[kout];
    let xi = xat(i);
    var bn: real = 0.0;
    var bt: real = 0.0;
    for (var q = 0u; q < count; q = q + 1u) {
        let key = keys[kout + 1u + q];
        var g: Geom;
        var mu: real;
        var first = true;
        // Relative angular velocity (first grain less the other; a wall's is 0) and R*.
        var wab: vec3<real>;
        var reff: real;
        if (key < P.n) {
            let a = min(i, key);
            let b = max(i, key);
            let dx = xat(b) - xat(a);
            g = geom(a, b, dx, dot(dx, dx));
            mu = P.mu;
            first = i == a;
            wab = wat(a) - wat(b);
            let ra = rad(a);
            let rb = rad(b);
            reff = ra * rb / (ra + rb);
        } else {
            let w = key - P.n;
            g = wall_geom(i, wall_surface(w, xi));
            mu = walls[WS * w + 2u];
            wab = wat(i);
            reff = rad(i);
        }
        let ft = vec_at(vout + q * sc + d);
        let n0 = vec_at(vout + q * sc + 2u * d);
        let f = vals[vout + q * sc + 3u * d];
        let d0 = vals[vout + q * sc + 3u * d + 1u];
        let vn = dot(g.vc, g.n);
        let vt = g.vc - g.n * vn;
        // The contact-point velocity now through the evaluation's geometry (normal n0, levers
        // r − δ0/2): the force it applied then does work at exactly this rate now, so the books
        // take exactly what semi-implicit Euler took from the kinetic energy.
        var v0: vec3<real>;
        if (key < P.n) {
            let a = min(i, key);
            let b = max(i, key);
            let w0 = wat(a) * (rad(a) - 0.5 * d0) + wat(b) * (rad(b) - 0.5 * d0);
            v0 = vat(a) - vat(b) + cross(w0, n0);
        } else {
            v0 = vat(i) + cross(wat(i) * (rad(i) - 0.5 * d0), n0);
        }
        var x1 = zero3();
        if (mu > 0.0) {
            x1 = vec_at(vout + q * sc) + vt * P.dt;
        }
        let d1 = max(g.d, 0.0);
        // The spring's energy, at most that of the force it can hold, μ f_n of the evaluation
        // (`Material::spring_energy`).
        let kt1 = kt_of(d1);
        let x2 = dot(x1, x1);
        let cap = mu * f;
        let held = kt1 * kt1 * x2 <= cap * cap;
        let u1 = select(0.5 * cap * cap / select(kt1, 1.0, held), 0.5 * kt1 * x2, held);
        keys[kin + 1u + q] = key;
        put(vin + q * sv, x1);
        vals[vin + q * sv + d] = u1;
        var ur: real = 0.0;
        if (P.roll != 0u) {
            // The rolling spring follows too, θ_r ← θ_r + dt·ω_r(new) (Material::roll_commit).
            let th = ax_at(vout + q * sc + 3u * d + 2u) + rolling_part(wab, g.n) * P.dt;
            let mr = ax_at(vout + q * sc + 3u * d + 2u + P.ad);
            let u = 0.5 * kr_of(d1, reff) * dot(th, th);
            put_ax(vin + q * sv + d + 1u, th);
            vals[vin + q * sv + d + 1u + P.ad] = u;
            ur = 0.0 - 0.5 * P.dt * dot(mr, wab) - u;
        }
        if (first) {
            bn = bn + (0.5 * P.dt * f * dot(v0, n0) - un_of(d1));
            bt = bt + (0.0 - 0.5 * P.dt * dot(ft, v0) - u1) + ur;
        }
    }
    keys[kin] = count;
    books[i] = books[i] + bn;
    books[P.n + i] = books[P.n + i] + bt;
}

// The contact potential now, for the books: the normal springs of the overlaps grain i is first
// of (pairs i < j, its walls), and the committed tangential springs' energy.
@compute @workgroup_size(WG)
fn energy(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let i = order[k];
    let d = P.dim;
    let cap = P.cap;
    let sv = stride_in();
    let kin = i * (cap + 1u);
    let vin = i * cap * sv;
    let xi = xat(i);
    let ri = rad(i);
    let c = coords(cell_of[i]);
    var u: real = 0.0;
    var z0 = 0u;
    var z1 = 0u;
    if (d == 3u) {
        z0 = lo_of(c.z);
        z1 = hi_of(c.z, P.cz);
    }
    for (var z = z0; z <= z1; z = z + 1u) {
        for (var y = lo_of(c.y); y <= hi_of(c.y, P.cy); y = y + 1u) {
            let row = flat(vec3<u32>(0u, y, z));
            for (var s = start[row + lo_of(c.x)]; s < start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                let j = order[s];
                if (j <= i || !(free(i) || free(j))) {
                    continue;
                }
                let dx = xat(j) - xi;
                let d2 = dot(dx, dx);
                let rs = ri + rad(j);
                if (d2 < rs * rs && d2 > 0.0) {
                    u = u + un_of(rs - sqrt(d2));
                }
            }
        }
    }
    for (var w = 0u; w < select(0u, P.walls, free(i)); w = w + 1u) {
        let sd = wall_surface(w, xi).s;
        if (sd < ri) {
            u = u + un_of(ri - sd);
        }
    }
    let count = keys[kin];
    for (var q = 0u; q < count; q = q + 1u) {
        let key = keys[kin + 1u + q];
        if (key >= P.n || i < key) {
            u = u + vals[vin + q * sv + d];
            if (P.roll != 0u) {
                u = u + vals[vin + q * sv + d + 1u + P.ad];
            }
        }
    }
    books[2u * P.n + i] = u;
}

var<workgroup> tallied: atomic<u32>;

// The committed history's contacts counted once, as the CPU's contacts term counts them: each
// grain's walls and its partners of a higher index, summed into flag[2] (integer atomics: the
// same count in any order).
@compute @workgroup_size(WG)
fn tally(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    if (t == 0u) {
        atomicStore(&tallied, 0u);
    }
    workgroupBarrier();
    let i = index(gid);
    if (i < P.n) {
        let kin = i * (P.cap + 1u);
        let count = min(keys[kin], P.cap);
        var c = 0u;
        for (var q = 0u; q < count; q = q + 1u) {
            let key = keys[kin + 1u + q];
            if (key >= P.n || i < key) {
                c = c + 1u;
            }
        }
        atomicAdd(&tallied, c);
    }
    workgroupBarrier();
    if (t == 0u) {
        atomicAdd(&flag[2], atomicLoad(&tallied));
    }
}
