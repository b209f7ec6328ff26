// Particles resident on the device: forces, the integrators' updates, the books and a finiteness
// check. The host prepends the precision header (`alias real = f32;` or f64, and `bad`).
//
// Every kernel gathers: thread i writes only particle i, and sums over the others in one fixed
// order (tiles of WG bodies, GPU Gems 3 ch. 31), so a run repeats bit for bit on one adapter.
// The one atomic is an integer min over the index of the first non-finite particle.

struct Params {
    n: u32,
    // 1: pairwise gravity on.
    pair: u32,
    // 1: the forces see the predicted velocity stored in vp (velocity Verlet with velocity-
    // dependent forces: drag, dashpots).
    pred: u32,
    // 0: no springs; 1: springs, entry e's constants at spring[e]; 2: springs of a few kinds,
    // other[e] packs the other end (low 24 bits) and the kind (high 8), the constants at
    // spring[kind] (a small table, read from the cache: 4 bytes an entry instead of 20).
    springs: u32,
    // 2 or 3 (the colliders' axes), and the number of colliders.
    dim: u32,
    ncol: u32,
    // 1: Coulomb on.
    coul: u32,
    // The springs' slice width: particle i's q-th entry is at start[n + 1 + i] + q · sw.
    sw: u32,
    // 0: the pairwise sums (gravity, Coulomb) run over all particles; w > 0: over the world of
    // w consecutive particles that i belongs to (a batch of small worlds, one dispatch for all).
    world: u32,
    // The fused worlds' kernel (worlds.wgsl): steps in this dispatch, and the scheme (0
    // semi-implicit Euler, 1 velocity Verlet, 2 Yoshida 4).
    steps: u32,
    scheme: u32,
    upad2: u32,
    dt: real,
    // kick_drift's kick (dt for semi-implicit Euler, dt/2 for velocity Verlet), kick's kick.
    h1: real,
    h2: real,
    // Weight of the power just evaluated in the dissipation books (dt, dt/2 or 0), and of the
    // power evaluated before it (0 or dt/2: the trapezoidal rule of velocity Verlet).
    w_new: real,
    w_old: real,
    big_g: real,
    eps2: real,
    b: real,
    gx: real,
    gy: real,
    gz: real,
    // The fused worlds' substep lengths: dt (Euler, Verlet), or Yoshida's w₁dt and w₀dt.
    h_a: real,
    // Coulomb's constant k (N·m²/C²) and its softening ε² (m²).
    kc: real,
    eps2c: real,
    h_b: real,
    // The colliders' share of the scheme's energy error (s; the CPU's
    // `IntegratorInfo::projection_kick`): −dt/2 for semi-implicit Euler, else 0.
    kick: real,
};

const WG: u32 = 256u;

@group(0) @binding(0) var<uniform> P: Params;
// xyz: position (m), w: mass (kg).
@group(0) @binding(1) var<storage, read_write> pos: array<vec4<real>>;
// xyz: velocity (m/s), w: 1/mass (0: pinned).
@group(0) @binding(2) var<storage, read_write> vel: array<vec4<real>>;
// xyz: acceleration (m/s²); w unused.
@group(0) @binding(3) var<storage, read_write> acc: array<vec4<real>>;
// x, y: energy dissipated by drag so far (J) and its power at the last force evaluation (W);
// z, w: the same for the springs' dashpots (half of each spring's, from each end).
@group(0) @binding(4) var<storage, read_write> aux: array<vec4<real>>;
// Per particle, two rows: (kinetic, uniform-gravity potential, half its pairwise potential,
// drag dissipated), (half its springs' potential, dashpots dissipated, 0, 0).
@group(0) @binding(5) var<storage, read_write> books: array<vec4<real>>;
// [0]: the smallest index of a particle with a non-finite position or velocity (or 0xffffffff);
// [1]: 1 if a collider moved a particle in the last step (velocity Verlet's carried force is
// then stale and evaluated again at the next step's start, as the CPU's `integrator.reset()`).
@group(0) @binding(6) var<storage, read_write> flag: array<atomic<u32>>;
// The predicted velocity v + dt a (velocity Verlet with velocity-dependent forces).
@group(0) @binding(7) var<storage, read_write> vp: array<vec4<real>>;
// Springs gathered per particle: particle i has start[i + 1] − start[i] entries (CSR counts), its
// q-th at start[n + 1 + i] + q · sw (sliced: a warp's threads read consecutive entries; sw = 1 is
// plain CSR); each names the other end and holds (k, c, L0, 0). Every spring appears once from
// each end, in spring order.
@group(0) @binding(8) var<storage, read> start: array<u32>;
@group(0) @binding(9) var<storage, read> other: array<u32>;
@group(0) @binding(10) var<storage, read> spring: array<vec4<real>>;
// Colliders, three rows each, in the order added: (kind: 0 plane, 1 box; restitution e,
// friction μ, 0), then a plane's point and unit normal, or a box's lower and upper corners.
@group(0) @binding(11) var<storage, read> col: array<vec4<real>>;
// Per particle: the energy the colliders removed from it so far (J).
@group(0) @binding(12) var<storage, read_write> hits: array<real>;
// Per particle: its charge q (C), the Coulomb term's source weight.
@group(0) @binding(13) var<storage, read> charge: array<real>;

var<workgroup> wtouch: u32;

// Entry e's other end and its constants (k, c, L0, 0) from o = other[e], read once, in either
// layout (P.springs 1 or 2).
fn spring_end(o: u32) -> u32 {
    if (P.springs == 2u) {
        return o & 0xffffffu;
    }
    return o;
}

fn spring_constants(e: u32, o: u32) -> vec4<real> {
    if (P.springs == 2u) {
        return spring[o >> 24u];
    }
    return spring[e];
}

var<workgroup> tile: array<vec4<real>, WG>;
var<workgroup> qtile: array<real, WG>;

fn load_tile(t: u32, l: u32) {
    let j = t * WG + l;
    if (j < P.n) {
        tile[l] = pos[j];
    } else {
        // Mass 0: a pad pulls on nothing.
        tile[l] = vec4<real>(0.0, 0.0, 0.0, 0.0);
    }
}

// Positions and charges of tile t (charge 0 past the end: a pad pushes on nothing).
fn load_charges(t: u32, l: u32) {
    let j = t * WG + l;
    if (j < P.n) {
        tile[l] = pos[j];
        qtile[l] = charge[j];
    } else {
        tile[l] = vec4<real>(0.0, 0.0, 0.0, 0.0);
        qtile[l] = 0.0;
    }
}

@compute @workgroup_size(WG)
fn forces(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    eval_forces(gid.x, lid.x, true);
}

// `forces` only if a collider moved a particle in the last step (flag[1]): velocity Verlet's
// evaluation at the start of a step after a projection (the CPU's reset carry).
@compute @workgroup_size(WG)
fn forces_if_touched(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if (touched(lid.x)) {
        eval_forces(gid.x, lid.x, true);
    }
}

// Whether a collider moved a particle in the last step (flag[1]), read once by the workgroup.
fn touched(l: u32) -> bool {
    if (l == 0u) {
        wtouch = atomicLoad(&flag[1]);
    }
    return workgroupUniformLoad(&wtouch) != 0u;
}

// `forces` and `forces_if_touched` for a scene without pairwise gravity or Coulomb (cloth,
// chains, particles in fields): the tiles' code compiled out, so the kernel holds no workgroup
// tile and fewer registers, and more of it fits on the GPU at once.
@compute @workgroup_size(WG)
fn forces_local(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    eval_forces(gid.x, lid.x, false);
}

@compute @workgroup_size(WG)
fn forces_local_if_touched(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if (touched(lid.x)) {
        eval_forces(gid.x, lid.x, false);
    }
}

@compute @workgroup_size(1)
fn clear_touched() {
    atomicStore(&flag[1], 0u);
}

// One spring end's force on i (xyz) and its dashpot's power (w): f = [k (L − L0) + c w] n,
// n = d/L, w = du·n, power ½ c w² (half of the spring's, from each end); nothing at L = 0.
// s = (k, c, L0, 0), d = x_j − x_i, du = u_j − u_i.
fn spring_force(s: vec4<real>, d: vec3<real>, du: vec3<real>) -> vec4<real> {
    let l = length(d);
    if (l > 0.0) {
        let n = d / l;
        let w = dot(du, n);
        return vec4<real>(n * (s.x * (l - s.z) + s.y * w), 0.5 * s.y * w * w);
    }
    return vec4<real>(0.0, 0.0, 0.0, 0.0);
}

// `far`: the pairwise sums (gravity, Coulomb) may be on (a constant at each call: false compiles
// them out of `forces_local`).
fn eval_forces(i: u32, l: u32, far: bool) {
    let live = i < P.n;
    var xi = vec4<real>(0.0, 0.0, 0.0, 0.0);
    if (live) {
        xi = pos[i];
    }
    var a = vec3<real>(0.0, 0.0, 0.0);
    if (far && P.pair != 0u && P.world != 0u) {
        // One small world: its particles read straight from memory (a few, in cache), in index
        // order, r² = 0 only for i itself without softening.
        if (live) {
            let b = (i / P.world) * P.world;
            for (var j = b; j < b + P.world; j++) {
                let s = pos[j];
                let d = s.xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                a += d * (s.w * inv * inv * inv);
            }
            a *= P.big_g;
        }
    }
    if (far && P.pair != 0u && P.world == 0u) {
        let tiles = (P.n + WG - 1u) / WG;
        // Softened (ε² > 0, the usual case), r² > 0 always: the guard below is left out and the
        // loop unrolled by 4, so that four inverse square roots are in flight at once; the sum
        // is still taken pair by pair in the same order (the same bits). The branch is uniform.
        let soft = P.eps2 > 0.0;
        for (var t = 0u; t < tiles; t++) {
            load_tile(t, l);
            workgroupBarrier();
            if (soft) {
                for (var k = 0u; k < WG; k += 4u) {
                    let s0 = tile[k];
                    let s1 = tile[k + 1u];
                    let s2 = tile[k + 2u];
                    let s3 = tile[k + 3u];
                    let d0 = s0.xyz - xi.xyz;
                    let d1 = s1.xyz - xi.xyz;
                    let d2 = s2.xyz - xi.xyz;
                    let d3 = s3.xyz - xi.xyz;
                    let i0 = inverseSqrt(dot(d0, d0) + P.eps2);
                    let i1 = inverseSqrt(dot(d1, d1) + P.eps2);
                    let i2 = inverseSqrt(dot(d2, d2) + P.eps2);
                    let i3 = inverseSqrt(dot(d3, d3) + P.eps2);
                    a += d0 * (s0.w * i0 * i0 * i0);
                    a += d1 * (s1.w * i1 * i1 * i1);
                    a += d2 * (s2.w * i2 * i2 * i2);
                    a += d3 * (s3.w * i3 * i3 * i3);
                }
            } else {
                for (var k = 0u; k < WG; k++) {
                    let s = tile[k];
                    let d = s.xyz - xi.xyz;
                    let r2 = dot(d, d) + P.eps2;
                    // r2 = 0 only for a body with itself without softening: it pulls on nothing.
                    let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                    a += d * (s.w * inv * inv * inv);
                }
            }
            workgroupBarrier();
        }
        a *= P.big_g;
    }
    // Coulomb: F_i = k q_i Σ_j q_j (x_i − x_j) / (|x_i − x_j|² + ε²)^{3/2} (the CPU's
    // `terms::coulomb`), summed over tiles of charges.
    var fc = vec3<real>(0.0, 0.0, 0.0);
    if (far && P.coul != 0u && P.world != 0u) {
        if (live) {
            let b = (i / P.world) * P.world;
            for (var j = b; j < b + P.world; j++) {
                let d = pos[j].xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2c;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                fc -= d * (charge[j] * inv * inv * inv);
            }
        }
    }
    if (far && P.coul != 0u && P.world == 0u) {
        let tiles = (P.n + WG - 1u) / WG;
        for (var t = 0u; t < tiles; t++) {
            load_charges(t, l);
            workgroupBarrier();
            for (var k = 0u; k < WG; k++) {
                let d = tile[k].xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2c;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                fc -= d * (qtile[k] * inv * inv * inv);
            }
            workgroupBarrier();
        }
    }
    if (far && P.coul != 0u && live) {
        fc *= P.kc * charge[i];
    }
    if (!live) {
        return;
    }
    let v = vel[i];
    var u = v.xyz;
    if (P.pred != 0u) {
        u = vp[i].xyz;
    }
    // Hookean springs with dashpots: f = [k (L − L0) + c (u_j − u_i)·n] n, n = (x_j − x_i)/L.
    var fs = vec3<real>(0.0, 0.0, 0.0);
    var ps: real = 0.0;
    if (P.springs != 0u) {
        let deg = start[i + 1u] - start[i];
        let base = start[P.n + 1u + i];
        // Two entries a round, their loads (other end, its position and velocity) issued
        // together before either is summed, so that two gathers are in flight at once; the sums
        // are still taken entry by entry in spring order (the same bits).
        var q = 0u;
        for (; q + 1u < deg; q += 2u) {
            let e0 = base + q * P.sw;
            let e1 = e0 + P.sw;
            let o0 = other[e0];
            let o1 = other[e1];
            let j0 = spring_end(o0);
            let j1 = spring_end(o1);
            let x0 = pos[j0].xyz;
            let x1 = pos[j1].xyz;
            var u0: vec3<real>;
            var u1: vec3<real>;
            if (P.pred != 0u) {
                u0 = vp[j0].xyz;
                u1 = vp[j1].xyz;
            } else {
                u0 = vel[j0].xyz;
                u1 = vel[j1].xyz;
            }
            let r0 = spring_force(spring_constants(e0, o0), x0 - xi.xyz, u0 - u);
            let r1 = spring_force(spring_constants(e1, o1), x1 - xi.xyz, u1 - u);
            fs += r0.xyz;
            ps += r0.w;
            fs += r1.xyz;
            ps += r1.w;
        }
        if (q < deg) {
            let e = base + q * P.sw;
            let o = other[e];
            let j = spring_end(o);
            var uj = vel[j].xyz;
            if (P.pred != 0u) {
                uj = vp[j].xyz;
            }
            let r = spring_force(spring_constants(e, o), pos[j].xyz - xi.xyz, uj - u);
            fs += r.xyz;
            ps += r.w;
        }
    }
    var ai = vec3<real>(0.0, 0.0, 0.0);
    var p: real = 0.0;
    if (v.w != 0.0) {
        ai = a + vec3<real>(P.gx, P.gy, P.gz) + (fs + fc - u * P.b) * v.w;
        p = P.b * dot(u, u);
    }
    acc[i] = vec4<real>(ai, 0.0);
    var x = aux[i];
    x.x += P.w_old * x.y + P.w_new * p;
    x.y = p;
    x.z += P.w_old * x.w + P.w_new * ps;
    x.w = ps;
    aux[i] = x;
}

// v += h1 a; x += dt v (semi-implicit Euler with h1 = dt; velocity Verlet's first kick and drift
// with h1 = dt/2, which also stores the predicted velocity v + dt a in vp when pred = 1).
@compute @workgroup_size(WG)
fn kick_drift(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= P.n) {
        return;
    }
    let v = vel[i];
    if (v.w == 0.0) {
        // Pinned: never moves.
        return;
    }
    let a = acc[i].xyz;
    if (P.pred != 0u) {
        vp[i] = vec4<real>(v.xyz + a * P.dt, 0.0);
    }
    let nv = v.xyz + a * P.h1;
    vel[i] = vec4<real>(nv, v.w);
    let x = pos[i];
    pos[i] = vec4<real>(x.xyz + nv * P.dt, x.w);
}

// Velocity Verlet's second kick: v += h2 a.
@compute @workgroup_size(WG)
fn kick(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= P.n) {
        return;
    }
    let v = vel[i];
    if (v.w == 0.0) {
        return;
    }
    vel[i] = vec4<real>(v.xyz + acc[i].xyz * P.h2, v.w);
}

@compute @workgroup_size(WG)
fn check(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= P.n) {
        return;
    }
    let x = pos[i];
    let v = vel[i];
    if (bad(x.x) || bad(x.y) || bad(x.z) || bad(v.x) || bad(v.y) || bad(v.z)) {
        atomicMin(&flag[0], i);
    }
}

@compute @workgroup_size(WG)
fn energy(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = gid.x;
    let live = i < P.n;
    var xi = vec4<real>(0.0, 0.0, 0.0, 0.0);
    if (live) {
        xi = pos[i];
    }
    var phi: real = 0.0;
    if (P.pair != 0u && P.world != 0u && live) {
        let b = (i / P.world) * P.world;
        for (var j = b; j < b + P.world; j++) {
            let s = pos[j];
            let d = s.xyz - xi.xyz;
            let r2 = dot(d, d) + P.eps2;
            let inv = select(0.0, inverseSqrt(r2), r2 > 0.0 && j != i);
            phi += s.w * inv;
        }
    }
    if (P.pair != 0u && P.world == 0u) {
        let tiles = (P.n + WG - 1u) / WG;
        for (var t = 0u; t < tiles; t++) {
            load_tile(t, lid.x);
            workgroupBarrier();
            for (var k = 0u; k < WG; k++) {
                let j = t * WG + k;
                let s = tile[k];
                let d = s.xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0 && j != i);
                phi += s.w * inv;
            }
            workgroupBarrier();
        }
    }
    var phic: real = 0.0;
    if (P.coul != 0u && P.world != 0u && live) {
        let b = (i / P.world) * P.world;
        for (var j = b; j < b + P.world; j++) {
            let d = pos[j].xyz - xi.xyz;
            let r2 = dot(d, d) + P.eps2c;
            let inv = select(0.0, inverseSqrt(r2), r2 > 0.0 && j != i);
            phic += charge[j] * inv;
        }
    }
    if (P.coul != 0u && P.world == 0u) {
        let tiles = (P.n + WG - 1u) / WG;
        for (var t = 0u; t < tiles; t++) {
            load_charges(t, lid.x);
            workgroupBarrier();
            for (var k = 0u; k < WG; k++) {
                let j = t * WG + k;
                let d = tile[k].xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2c;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0 && j != i);
                phic += qtile[k] * inv;
            }
            workgroupBarrier();
        }
    }
    if (!live) {
        return;
    }
    let v = vel[i];
    var ug: real = 0.0;
    if (v.w != 0.0) {
        ug = -xi.w * dot(vec3<real>(P.gx, P.gy, P.gz), xi.xyz);
    }
    var us: real = 0.0;
    if (P.springs != 0u) {
        let deg = start[i + 1u] - start[i];
        let base = start[P.n + 1u + i];
        for (var q = 0u; q < deg; q++) {
            let e = base + q * P.sw;
            let o = other[e];
            let s = spring_constants(e, o);
            let dl = length(pos[spring_end(o)].xyz - xi.xyz) - s.z;
            us += 0.25 * s.x * dl * dl;
        }
    }
    // Each pair counted from both ends: half each.
    let x = aux[i];
    books[2u * i] = vec4<real>(0.5 * xi.w * dot(v.xyz, v.xyz), ug, -0.5 * P.big_g * xi.w * phi, x.x);
    var uc: real = 0.0;
    if (P.coul != 0u) {
        uc = 0.5 * P.kc * charge[i] * phic;
    }
    books[2u * i + 1u] = vec4<real>(us, x.z, uc, 0.0);
}

// `geometry::ball::onto_round`: x on the wrong side of the round surface at distance r from c
// (inside: kept within it) moved along the radius onto it, with the surface's normal into the
// allowed side; at the centre itself, back the way it came, or up when at rest.
struct Round {
    x: vec3<real>,
    n: vec3<real>,
    hit: bool,
}

fn onto_round(x: vec3<real>, v: vec3<real>, c: vec3<real>, r: real, inside: bool) -> Round {
    let rel = x - c;
    let l2 = dot(rel, rel);
    let r2 = r * r;
    if ((inside && !(l2 > r2)) || (!inside && !(l2 < r2))) {
        return Round(x, vec3<real>(0.0, 0.0, 0.0), false);
    }
    let l = sqrt(l2);
    var u = vec3<real>(0.0, 0.0, 0.0);
    if (l > 0.0) {
        u = rel / l;
    } else if (dot(v, v) > 0.0) {
        u = -v / sqrt(dot(v, v));
    } else {
        u[P.dim - 1u] = 1.0;
    }
    var n = u;
    if (inside) {
        n = -u;
    }
    return Round(c + u * r, n, true);
}

// `Contact::bounce`: moving into the surface of unit normal n (v·n < 0), the normal velocity
// becomes −e v_n and the tangential speed drops by μ(1 + e)|v_n|, never past zero.
fn bounce(v: vec3<real>, n: vec3<real>, e: real, mu: real) -> vec3<real> {
    let vn = dot(v, n);
    if (!(vn < 0.0)) {
        return v;
    }
    let vt = v - n * vn;
    let vt2 = dot(vt, vt);
    let dvn = (1.0 + e) * (-vn);
    var vtn = vt;
    if (mu > 0.0 && vt2 > 0.0) {
        let l = sqrt(vt2);
        vtn = vt * (max(l - mu * dvn, 0.0) / l);
    }
    return vtn + n * (-e * vn);
}

// The colliders (the CPU's `constraints::Collider` with `Contact::bounce`: planes, spheres,
// capsules and oriented boxes; `constraints::Aabb` face by face): a free particle on a forbidden side is moved onto the surface; moving into it,
// its normal velocity becomes −e v_n and its tangential speed drops by μ(1 + e)|v_n|, never past
// zero. The energy removed (ΔKE plus the work F·Δx of the last evaluated force, gravity in it,
// over the move) is booked per particle in `hits`.
@compute @workgroup_size(WG)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= P.n) {
        return;
    }
    let v4 = vel[i];
    if (v4.w == 0.0) {
        return;
    }
    let p4 = pos[i];
    let m = p4.w;
    var x = p4.xyz;
    var v = v4.xyz;
    let f = acc[i].xyz * m;
    var d: real = 0.0;
    var touched = false;
    for (var c = 0u; c < P.ncol; c++) {
        let h = col[6u * c];
        let a = col[6u * c + 1u].xyz;
        let b = col[6u * c + 2u].xyz;
        let e = h.y;
        let mu = h.z;
        let ke0 = 0.5 * m * dot(v, v);
        let vb = v;
        var dx = vec3<real>(0.0, 0.0, 0.0);
        if (h.x == 0.0) {
            // A plane through a with unit normal b into the allowed side.
            let depth = dot(x - a, b);
            if (depth >= 0.0) {
                continue;
            }
            dx = b * (-depth);
            x = x + dx;
            v = bounce(v, b, e, mu);
        } else if (h.x == 2.0 || h.x == 3.0) {
            // A sphere about a of radius b.x, particles kept outside (b.y = 0: a ball) or inside
            // (b.y = 1: a bowl); a capsule, particles kept outside the radius h.w about the
            // segment from a to b, measured from the segment's nearest point
            // (`geometry::Capsule::nearest`).
            var c = a;
            var r = b.x;
            var inside = b.y != 0.0;
            if (h.x == 3.0) {
                let ab = b - a;
                let l2 = dot(ab, ab);
                var t: real = 0.0;
                if (l2 > 0.0) {
                    t = clamp(dot(x - a, ab) / l2, 0.0, 1.0);
                }
                c = a + ab * t;
                r = h.w;
                inside = false;
            }
            let o = onto_round(x, v, c, r, inside);
            if (!o.hit) {
                continue;
            }
            dx = o.x - x;
            x = o.x;
            v = bounce(v, o.n, e, mu);
        } else if (h.x == 4.0) {
            // An oriented box about a, half extents b along the axes in the next three rows,
            // particles kept outside: one inside leaves through the face it is least deep under
            // (the first on a tie), along that axis (`geometry::OrientedBox::project`).
            let rel = x - a;
            var best = 0u;
            var least: real = 0.0;
            var qb: real = 0.0;
            var inside = true;
            for (var j = 0u; j < P.dim; j++) {
                let q = dot(rel, col[6u * c + 3u + j].xyz);
                let depth = b[j] - abs(q);
                if (!(depth > 0.0)) {
                    inside = false;
                    break;
                }
                if (j == 0u || depth < least) {
                    best = j;
                    least = depth;
                    qb = q;
                }
            }
            if (!inside) {
                continue;
            }
            var n = col[6u * c + 3u + best].xyz;
            if (qb < 0.0) {
                n = -n;
            }
            dx = n * least;
            x = x + dx;
            v = bounce(v, n, e, mu);
        } else {
            // A box [a, b]: particles kept inside, bounced face by face.
            var out = false;
            for (var k = 0u; k < P.dim; k++) {
                out = out || x[k] < a[k] || x[k] > b[k];
            }
            if (!out) {
                continue;
            }
            let x0 = x;
            for (var k = 0u; k < P.dim; k++) {
                var o: real = 0.0;
                if (x[k] < a[k]) {
                    x[k] = a[k];
                    o = -1.0;
                } else if (x[k] > b[k]) {
                    x[k] = b[k];
                    o = 1.0;
                } else {
                    continue;
                }
                let vn = v[k] * o;
                if (vn > 0.0) {
                    let dvn = (1.0 + e) * vn;
                    v[k] = v[k] * (-e);
                    if (mu > 0.0) {
                        var vt2: real = 0.0;
                        for (var q = 0u; q < P.dim; q++) {
                            if (q != k) {
                                vt2 += v[q] * v[q];
                            }
                        }
                        if (vt2 > 0.0) {
                            let vt = sqrt(vt2);
                            let sc = max(vt - mu * dvn, 0.0) / vt;
                            for (var q = 0u; q < P.dim; q++) {
                                if (q != k) {
                                    v[q] = v[q] * sc;
                                }
                            }
                        }
                    }
                }
            }
            dx = x - x0;
        }
        touched = true;
        let ke1 = 0.5 * m * dot(v, v);
        d += (ke0 - ke1) + dot(f, dx) + P.kick * dot(vec3<real>(P.gx, P.gy, P.gz) * m, v - vb);
    }
    if (touched) {
        pos[i] = vec4<real>(x, m);
        vel[i] = vec4<real>(v, v4.w);
        hits[i] = hits[i] + d;
        atomicStore(&flag[1], 1u);
    }
}
