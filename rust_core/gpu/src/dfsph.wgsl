// Divergence-free SPH on the device (dfsph.rs; the CPU's rust_core/src/sph/dfsph). One step is
// the cell list (cells.wgsl, its own bind group), then here: `gather`, `build`, the divergence
// solve (`div_err0`/`div_err`, `check_div`, `div_apply`), `normals` (with cohesion), `forces`,
// the density solve
// (`den_err`, `check_den`, `den_apply`, after one warm-start push `den_warm` + `den_apply`) and
// `drift`. Threads run over the particles in cell order (slot k of `order`) and write only slot
// k (or particle order[k] in the caller's order): no float atomics. Every neighbour sum runs
// over the 3^d cells around the particle's own (z, y, x, then each cell's slots in order; a
// row's three cells along x are consecutive, so each row is one run of slots), the fluid's then
// the walls'. The solves' mean errors are reduced on the device: a tree per
// workgroup into `partial`, then one workgroup over the partials in a fixed order (`check`),
// which also decides whether the solve goes on and, when it stops, empties the indirect
// dispatch `args` of the iterations recorded after it. The host prepends the precision header.

struct Params {
    // Particles, dimension, cells along x, y, z (z = 1 in 2D), kernel (0 cubic spline, 1
    // Wendland C2), neighbours for the divergence solve, workgroups of a particle dispatch
    // (the partial sums), most iterations, workgroups along x and y of a particle dispatch.
    n: u32,
    dim: u32,
    cx: u32,
    cy: u32,
    cz: u32,
    kernel: u32,
    n_min: u32,
    groups: u32,
    max_it: u32,
    gx: u32,
    gy: u32,
    // Entries of each slot's neighbour list (`nbr`; 0: no lists, every pass reads the cells).
    cap: u32,
    // 1/h, mass, σ_d, σ_d/h², α c0 h, 0.01 h², 4h² (the pairs), the r² floor, ρ0, dt, 1/dt,
    // 1/dt².
    inv_h: real,
    mass: real,
    sigma: real,
    gscale: real,
    visc: real,
    eps_h2: real,
    reach: real,
    tiny: real,
    rho0: real,
    dt: real,
    inv_dt: real,
    inv_dt2: real,
    // Gravity, the box's corners, its restitution and friction.
    gx_: real,
    gy_: real,
    gz_: real,
    lo_x: real,
    lo_y: real,
    lo_z: real,
    hi_x: real,
    hi_y: real,
    hi_z: real,
    restitution: real,
    friction: real,
    // Tolerances, the warm starts' shares, the errors' norms: dt/(n ρ0) and 1/(n ρ0).
    tol_div: real,
    tol_den: real,
    warm_div: real,
    warm_den: real,
    norm_div: real,
    norm_den: real,
    // Akinci et al. 2013 (`surface`): cohesion γ (0: off), adhesion β (0: off), the curvature
    // weight c, H = 2h, C's normalisation, H⁶/64, A's factor 0.007/H^3.25.
    gamma: real,
    beta: real,
    curv: real,
    big_h: real,
    coh_norm: real,
    h6_64: real,
    adh_k: real,
    // The solves' Jacobi relaxation ω, folded into the factor (ω/D_k; the core's `relaxation`).
    omega: real,
};

const WG: u32 = 64u;
const RW: u32 = 256u;

// Fields of `sv` (sorted vectors, n·dim reals each): positions, the divergence solve's
// velocities (its result after it), the step's start velocities, the kicked velocities, the
// density solve's velocities, the term's own acceleration (viscosity), Σ_b Ψ_b ∇W_kb, and
// Σ_b Ψ_b (g·(x_k − x_b)) ∇W_kb.
const X: u32 = 0u;
const V: u32 = 1u;
const V0: u32 = 2u;
const VK: u32 = 3u;
const VD: u32 = 4u;
const AF: u32 = 5u;
const GW: u32 = 6u;
const HW: u32 = 7u;
// With cohesion only (the buffer has the field then): the step's normals n_k.
const NRM: u32 = 8u;
// Fields of `ss` (sorted scalars, n each): density, 1/D, whether the neighbourhood is full
// enough (1) or not (0), κ/ρ of the pass, its sum over the density solve and over the
// divergence solve.
const RHO: u32 = 0u;
const DINV: u32 = 1u;
const INNER: u32 = 2u;
const K: u32 = 3u;
const KSUM: u32 = 4u;
const KSUMV: u32 = 5u;
// With cohesion only: the surface forces' virial pressure.
const VIR: u32 = 6u;
// Words of `ctl`: whether the running solve goes on, its iterations so far, the last step's
// divergence and density iterations, their totals, solves stopped unconverged, steps, the
// first particle (caller's index) whose state stopped being finite (u32::MAX: none), the most
// iterations of each solve within the submission, and whether a solve outran the iterations
// recorded for it (`seal`).
const ACTIVE: u32 = 0u;
const ITER: u32 = 1u;
const LAST_DIV: u32 = 2u;
const LAST_DEN: u32 = 3u;
const TOTAL_DIV: u32 = 4u;
const TOTAL_DEN: u32 = 5u;
const UNCONVERGED: u32 = 6u;
const STEPS: u32 = 7u;
const FLAG: u32 = 8u;
const MOST_DIV: u32 = 9u;
const TRUNCATED: u32 = 11u;

@group(0) @binding(0) var<uniform> P: Params;
// The state in the caller's order: positions and velocities (`dim` per particle), densities.
@group(0) @binding(1) var<storage, read_write> pos: array<real>;
@group(0) @binding(2) var<storage, read_write> vel: array<real>;
@group(0) @binding(3) var<storage, read_write> rho: array<real>;
// The cell list (cells.wgsl): each particle's cell, each cell's first slot, the particles by cell.
@group(0) @binding(4) var<storage, read> cell_of: array<u32>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> order: array<u32>;
@group(0) @binding(7) var<storage, read_write> sv: array<real>;
@group(0) @binding(8) var<storage, read_write> ss: array<real>;
// The caller's order, 3n: Σκ/ρ of the last density solve, of the last divergence solve (the
// warm starts), and the last step's pressure.
@group(0) @binding(9) var<storage, read_write> hist: array<real>;
// The books of each particle (caller's order), J: the divergence solve's, the density
// solve's, the viscosity's work, the box's (4n).
@group(0) @binding(10) var<storage, read_write> books: array<real>;
// The static wall particles sorted by (cell, index) on the host: `dim` coordinates then Ψ_b.
@group(0) @binding(11) var<storage, read> wall: array<real>;
@group(0) @binding(12) var<storage, read> wall_start: array<u32>;
// One partial sum of the errors per workgroup.
@group(0) @binding(13) var<storage, read_write> partial: array<real>;
@group(0) @binding(14) var<storage, read_write> ctl: array<atomic<u32>>;
// The step's neighbour lists, made by `build` for the passes after it: slot k's fluid
// neighbours within 2h (itself left out) in the order the cells give them, the j-th at
// nbr[j n + k] (a warp's threads read consecutive words), and how many there are (`nlen`). A
// slot with more than `cap` reads the cells instead, so the lists never change a sum: the same
// pairs in the same order, each evaluated by the same expression.
@group(0) @binding(15) var<storage, read_write> nbr: array<u32>;
@group(0) @binding(16) var<storage, read_write> nlen: array<u32>;

// Sorted vector field f of slot s (z = 0 in 2D).
fn vget(f: u32, s: u32) -> vec3<real> {
    let d = P.dim;
    let o = f * P.n * d + d * s;
    var r = vec3<real>(0.0, 0.0, 0.0);
    for (var a = 0u; a < d; a = a + 1u) {
        r[a] = sv[o + a];
    }
    return r;
}

fn vset(f: u32, s: u32, v: vec3<real>) {
    let d = P.dim;
    let o = f * P.n * d + d * s;
    for (var a = 0u; a < d; a = a + 1u) {
        sv[o + a] = v[a];
    }
}

fn sget(f: u32, s: u32) -> real {
    return ss[f * P.n + s];
}

fn sset(f: u32, s: u32, v: real) {
    ss[f * P.n + s] = v;
}

fn wall_at(s: u32) -> vec4<real> {
    let d = P.dim;
    var r = vec4<real>(0.0, 0.0, 0.0, 0.0);
    for (var k = 0u; k < d; k = k + 1u) {
        r[k] = wall[(d + 1u) * s + k];
    }
    r.w = wall[(d + 1u) * s + d];
    return r;
}

fn dot3(a: vec3<real>, b: vec3<real>) -> real {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// w(q) and g(q) = w'(q)/q (kernels.rs `w`, `g`; as sph.wgsl).
fn w(q: real) -> real {
    if (P.kernel == 0u) {
        let a = max(2.0 - q, 0.0);
        let b = max(1.0 - q, 0.0);
        return 0.25 * a * a * a - b * b * b;
    }
    let t = max(1.0 - 0.5 * q, 0.0);
    let t2 = t * t;
    return t2 * t2 * (2.0 * q + 1.0);
}

fn g(q: real) -> real {
    if (P.kernel == 0u) {
        let a = max(2.0 - q, 0.0);
        let inner = -3.0 + 2.25 * q;
        let outer = -0.75 * a * a / max(q, 1.0);
        return select(outer, inner, q < 1.0);
    }
    let t = max(1.0 - 0.5 * q, 0.0);
    return -5.0 * t * t * t;
}

// The cells around slot k's: z range (one cell in 2D).
fn zr(c: vec3<u32>) -> vec2<u32> {
    if (P.dim == 3u) {
        return vec2<u32>(lo_of(c.z), hi_of(c.z, P.cz));
    }
    return vec2<u32>(0u, 0u);
}

// Slot k: the state of particle order[k] in cell order; the start velocities kept for the
// books; the divergence solve's sum of κ^v/ρ zeroed.
@compute @workgroup_size(WG)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let d = P.dim;
    let i = order[k];
    var x = vec3<real>(0.0, 0.0, 0.0);
    var v = vec3<real>(0.0, 0.0, 0.0);
    for (var a = 0u; a < d; a = a + 1u) {
        x[a] = pos[d * i + a];
        v[a] = vel[d * i + a];
    }
    vset(X, k, x);
    vset(V, k, v);
    vset(V0, k, v);
    sset(KSUMV, k, 0.0);
}

// Step 1 (the CPU's `BuildChunk`): ρ_k = σ [Σ_j m w_kj + Σ_b Ψ_b w_kb] (self included), the
// factor 1/D_k with D_k = |Σ_j m∇W_kj + Σ_b Ψ_b∇W_kb|² + Σ_j |m∇W_kj|² (Bender & Koschier 2017,
// eq. 9, as α_k = ρ_k/D_k), with the walls' own push doubled (they mirror the pressure):
// D_k = max((s + 2 gw)·(s + gw) + Σ|m∇W|², Σ|m∇W|²); whether at least n_min neighbours (fluid
// and walls) are within 2h; Σ_b Ψ_b ∇W_kb and its hydrostatic sum Σ_b Ψ_b (g·(x_k − x_b)) ∇W_kb.
@compute @workgroup_size(WG)
fn build(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let c = coords(cell_of[order[k]]);
    let z = zr(c);
    let xi = vget(X, k);
    var acc: real = 0.0;
    var sum = vec3<real>(0.0, 0.0, 0.0);
    var sq: real = 0.0;
    var count = 0u;
    var listed = 0u;
    for (var cz = z.x; cz <= z.y; cz = cz + 1u) {
        for (var cy = lo_of(c.y); cy <= hi_of(c.y, P.cy); cy = cy + 1u) {
            let row = flat(vec3<u32>(0u, cy, cz));
            for (var s = start[row + lo_of(c.x)]; s < start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                let e = xi - vget(X, s);
                let r2 = dot3(e, e);
                if (r2 < P.reach) {
                    let q = sqrt(max(r2, P.tiny)) * P.inv_h;
                    acc = acc + w(q) * P.mass;
                    if (s != k) {
                        let gr = e * (P.mass * P.gscale * g(q));
                        sum = sum + gr;
                        sq = sq + dot3(gr, gr);
                        count = count + 1u;
                        if (listed < P.cap) {
                            nbr[listed * P.n + k] = s;
                        }
                        listed = listed + 1u;
                    }
                }
            }
        }
    }
    let grav = vec3<real>(P.gx_, P.gy_, P.gz_);
    var gw = vec3<real>(0.0, 0.0, 0.0);
    var hw = vec3<real>(0.0, 0.0, 0.0);
    for (var cz = z.x; cz <= z.y; cz = cz + 1u) {
        for (var cy = lo_of(c.y); cy <= hi_of(c.y, P.cy); cy = cy + 1u) {
            let row = flat(vec3<u32>(0u, cy, cz));
            for (var s = wall_start[row + lo_of(c.x)]; s < wall_start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                let wb = wall_at(s);
                let e = xi - wb.xyz;
                let r2 = dot3(e, e);
                if (r2 < P.reach) {
                    let q = sqrt(max(r2, P.tiny)) * P.inv_h;
                    acc = acc + w(q) * wb.w;
                    let gb = e * (wb.w * P.gscale * g(q));
                    gw = gw + gb;
                    hw = hw + gb * dot3(grav, e);
                    count = count + 1u;
                }
            }
        }
    }
    let dd = max(dot3(sum + gw * 2.0, sum + gw) + sq, sq);
    var dinv: real = 0.0;
    if (dd > 0.0) {
        dinv = P.omega / dd;
    }
    let r = P.sigma * acc;
    sset(RHO, k, r);
    sset(DINV, k, dinv);
    sset(INNER, k, select(real(0.0), real(1.0), count >= P.n_min));
    nlen[k] = listed;
    vset(GW, k, gw);
    vset(HW, k, hw);
    rho[order[k]] = r;
}

var<workgroup> red: array<real, WG>;

// Whether slot s is a neighbour of slot k (at x_k = xi) in the lists' sense: within 2h, not k.
fn near(xi: vec3<real>, s: u32, k: u32) -> bool {
    let e = xi - vget(X, s);
    return dot3(e, e) < P.reach && s != k;
}

// The cells' walk for a slot whose neighbours outran its list (or with no lists): slot k's
// fluid neighbours (`near`) one per call of `next_near`, in the order `build` lists them (z, y,
// then a row's run of slots), END after the last.
const END: u32 = 0xffffffffu;

struct Walk {
    k: u32,
    xi: vec3<real>,
    c: vec3<u32>,
    z1: u32,
    cz: u32,
    cy: u32,
    s: u32,
    end: u32,
}

// The run of slots of the walk's row (cy, cz): cells x − 1..x + 1, consecutive in `order`.
fn walk_row(w: ptr<function, Walk>) {
    let row = flat(vec3<u32>(0u, (*w).cy, (*w).cz));
    (*w).s = start[row + lo_of((*w).c.x)];
    (*w).end = start[row + hi_of((*w).c.x, P.cx) + 1u];
}

fn walk(k: u32, xi: vec3<real>) -> Walk {
    let c = coords(cell_of[order[k]]);
    let z = zr(c);
    var w = Walk(k, xi, c, z.y, z.x, lo_of(c.y), 0u, 0u);
    walk_row(&w);
    return w;
}

fn next_near(w: ptr<function, Walk>) -> u32 {
    loop {
        if ((*w).s < (*w).end) {
            let s = (*w).s;
            (*w).s = s + 1u;
            if (near((*w).xi, s, (*w).k)) {
                return s;
            }
            continue;
        }
        if ((*w).cy < hi_of((*w).c.y, P.cy)) {
            (*w).cy = (*w).cy + 1u;
        } else if ((*w).cz < (*w).z1) {
            (*w).cz = (*w).cz + 1u;
            (*w).cy = lo_of((*w).c.y);
        } else {
            return END;
        }
        walk_row(w);
    }
    return END;
}

// A neighbour s's share of Dρ_k/Dt: m (v_k − v_s)·∇W_ks at the velocities of field f.
fn div_pair(xi: vec3<real>, vi: vec3<real>, f: u32, s: u32) -> real {
    let e = xi - vget(X, s);
    let q = sqrt(max(dot3(e, e), P.tiny)) * P.inv_h;
    return dot3(vi - vget(f, s), e) * (P.mass * P.gscale * g(q));
}

// Dρ_k/Dt at the velocities of field f: Σ_j m (v_k − v_j)·∇W_kj + Σ_b Ψ_b v_k·∇W_kb.
fn divergence(f: u32, k: u32) -> real {
    let xi = vget(X, k);
    let vi = vget(f, k);
    var div: real = 0.0;
    let m = nlen[k];
    if (m <= P.cap) {
        for (var j = 0u; j < m; j = j + 1u) {
            div = div + div_pair(xi, vi, f, nbr[j * P.n + k]);
        }
    } else {
        var w = walk(k, xi);
        for (var s = next_near(&w); s != END; s = next_near(&w)) {
            div = div + div_pair(xi, vi, f, s);
        }
    }
    return div + dot3(vi, vget(GW, k));
}

// One error pass (the CPU's `Solver::errors`) of the divergence solve (den = false: e_k =
// (Dρ_k/Dt)₊ where the neighbourhood is full enough, κ^v_k/ρ_k = e_k/(dt D_k)) or the density
// solve (den = true: e_k = (ρ_k + dt Dρ_k/Dt − ρ0)₊, κ_k/ρ_k = e_k/(dt² D_k)) into K, with a
// warm start `warm` (0 none; 1 the divergence solve's first iteration: the larger of κ/ρ and
// its share of the last step's sum, where κ/ρ > 0; 2 the density solve's: the share alone,
// where κ/ρ > 0), and the workgroup's Σ e_k into `partial` (a tree, the same order each run).
fn errors(gid: vec3<u32>, lid: u32, wid: vec3<u32>, den: bool, warm: u32) {
    let k = index(gid);
    var e: real = 0.0;
    if (k < P.n) {
        var kap: real = 0.0;
        if (den) {
            let div = divergence(VD, k);
            e = max(sget(RHO, k) + P.dt * div - P.rho0, 0.0);
            kap = e * sget(DINV, k) * P.inv_dt2;
        } else {
            if (sget(INNER, k) > 0.0) {
                e = max(divergence(V, k), 0.0);
            }
            kap = e * sget(DINV, k) * P.inv_dt;
        }
        if (warm == 1u) {
            if (kap > 0.0) {
                kap = max(kap, hist[P.n + order[k]] * P.warm_div);
            } else {
                kap = 0.0;
            }
        } else if (warm == 2u) {
            if (kap > 0.0) {
                kap = hist[order[k]] * P.warm_den;
            } else {
                kap = 0.0;
            }
        }
        sset(K, k, kap);
    }
    red[lid] = e;
    workgroupBarrier();
    for (var h = WG / 2u; h > 0u; h = h / 2u) {
        if (lid < h) {
            red[lid] = red[lid] + red[lid + h];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        partial[wid.x + 65535u * wid.y] = red[0];
    }
}

@compute @workgroup_size(WG)
fn div_err0(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) l: u32,
            @builtin(workgroup_id) wid: vec3<u32>) {
    errors(gid, l, wid, false, 1u);
}

@compute @workgroup_size(WG)
fn div_err(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) l: u32,
           @builtin(workgroup_id) wid: vec3<u32>) {
    errors(gid, l, wid, false, 0u);
}

@compute @workgroup_size(WG)
fn den_warm(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) l: u32,
            @builtin(workgroup_id) wid: vec3<u32>) {
    errors(gid, l, wid, true, 2u);
}

@compute @workgroup_size(WG)
fn den_err(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) l: u32,
           @builtin(workgroup_id) wid: vec3<u32>) {
    errors(gid, l, wid, true, 0u);
}

// A neighbour s's share of the Jacobi update: m (κ_k/ρ_k + κ_s/ρ_s) ∇W_ks.
fn apply_pair(xi: vec3<real>, ki: real, s: u32) -> vec3<real> {
    let e = xi - vget(X, s);
    let q = sqrt(max(dot3(e, e), P.tiny)) * P.inv_h;
    return e * ((ki + sget(K, s)) * (P.mass * P.gscale * g(q)));
}

// One Jacobi velocity update of field f with κ/ρ in K (the CPU's `Solver::apply`; paper eq.
// 10–11): v_k −= dt [Σ_j m (κ_k/ρ_k + κ_j/ρ_j) ∇W_kj + 2 (κ_k/ρ_k) Σ_b Ψ_b ∇W_kb] (a wall
// mirrors the particle's pressure), and the solve's sum of κ/ρ (field ks) += κ_k/ρ_k.
fn apply(k: u32, f: u32, ks: u32) {
    if (k >= P.n) {
        return;
    }
    let xi = vget(X, k);
    let ki = sget(K, k);
    var a = vget(GW, k) * (2.0 * ki);
    let m = nlen[k];
    if (m <= P.cap) {
        for (var j = 0u; j < m; j = j + 1u) {
            a = a + apply_pair(xi, ki, nbr[j * P.n + k]);
        }
    } else {
        var w = walk(k, xi);
        for (var s = next_near(&w); s != END; s = next_near(&w)) {
            a = a + apply_pair(xi, ki, s);
        }
    }
    vset(f, k, vget(f, k) - a * P.dt);
    sset(ks, k, sget(ks, k) + ki);
}

@compute @workgroup_size(WG)
fn div_apply(@builtin(global_invocation_id) gid: vec3<u32>) {
    apply(index(gid), V, KSUMV);
}

@compute @workgroup_size(WG)
fn den_apply(@builtin(global_invocation_id) gid: vec3<u32>) {
    apply(index(gid), VD, KSUM);
}

// A neighbour s's share of the normal: m/ρ_s ∇W_ks.
fn normal_pair(xi: vec3<real>, s: u32) -> vec3<real> {
    let e = xi - vget(X, s);
    let q = sqrt(max(dot3(e, e), P.tiny)) * P.inv_h;
    let gr = e * (P.mass * P.gscale * g(q));
    return gr * (1.0 / sget(RHO, s));
}

// The step's normals n_k = H Σ_j m/ρ_j ∇W_kj (Akinci 2013, eq. 4; fluid neighbours only; the
// CPU's `compute_normals`), after the build (every density known).
@compute @workgroup_size(WG)
fn normals(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let xi = vget(X, k);
    var sum = vec3<real>(0.0, 0.0, 0.0);
    let m = nlen[k];
    if (m <= P.cap) {
        for (var j = 0u; j < m; j = j + 1u) {
            sum = sum + normal_pair(xi, nbr[j * P.n + k]);
        }
    } else {
        var w = walk(k, xi);
        for (var s = next_near(&w); s != END; s = next_near(&w)) {
            sum = sum + normal_pair(xi, s);
        }
    }
    vset(NRM, k, sum * P.big_h);
}

// Akinci's cohesion spline C(r) = k · shape (paper eq. 2; the CPU's `Surface::cohesion`):
// shape = (H − r)³ r³ for H/2 < r ≤ H, 2 (H − r)³ r³ − H⁶/64 for 0 < r ≤ H/2, 0 beyond H.
fn cohesion(r: real) -> real {
    if (r >= P.big_h) {
        return 0.0;
    }
    let a = max(P.big_h - r, 0.0);
    let b = a * a * a * r * r * r;
    return P.coh_norm * select(2.0 * b - P.h6_64, b, 2.0 * r > P.big_h);
}

// A neighbour s's share of the surface tension (before −γ): K_ks [m C(r) x̂_ks + c (n_k − n_s)].
fn tension_pair(xi: vec3<real>, ri: real, ni: vec3<real>, s: u32) -> vec3<real> {
    let e = xi - vget(X, s);
    let r = sqrt(dot3(e, e));
    let k_ij = 2.0 * P.rho0 / (ri + sget(RHO, s));
    // Coincident particles have no direction: no cohesion (as the CPU).
    var coh = vec3<real>(0.0, 0.0, 0.0);
    if (r > 0.0) {
        coh = e * (P.mass * cohesion(r) / r);
    }
    return (coh + (ni - vget(NRM, s)) * P.curv) * k_ij;
}

// Slot k's acceleration by surface tension and adhesion (the CPU's `surface_acceleration`):
// −γ Σ_j K_kj [m C(r) x̂_kj + c (n_k − n_j)] − β Σ_b Ψ_b A(r) x̂_kb, K_kj = 2ρ0/(ρ_k + ρ_j), with
// A(r) = 0.007/H^3.25 (−4r²/H + 6r − 2H)^¼ for H/2 < r ≤ H (eq. 7); the fluid pairs' virial
// pressure −γ ρ_k/(2d) Σ_j x_kj·K_kj[…] into VIR (with cohesion).
fn surface(k: u32, xi: vec3<real>, ri: real) -> vec3<real> {
    let c = coords(cell_of[order[k]]);
    let z = zr(c);
    var a = vec3<real>(0.0, 0.0, 0.0);
    if (P.gamma > 0.0) {
        let ni = vget(NRM, k);
        var st = vec3<real>(0.0, 0.0, 0.0);
        var vir: real = 0.0;
        let m = nlen[k];
        if (m <= P.cap) {
            for (var j = 0u; j < m; j = j + 1u) {
                let s = nbr[j * P.n + k];
                let pair = tension_pair(xi, ri, ni, s);
                st = st + pair;
                vir = vir + dot3(xi - vget(X, s), pair);
            }
        } else {
            var w = walk(k, xi);
            for (var s = next_near(&w); s != END; s = next_near(&w)) {
                let pair = tension_pair(xi, ri, ni, s);
                st = st + pair;
                vir = vir + dot3(xi - vget(X, s), pair);
            }
        }
        a = a - st * P.gamma;
        sset(VIR, k, -P.gamma * vir * ri / (2.0 * real(P.dim)));
    }
    if (P.beta > 0.0) {
        var ad = vec3<real>(0.0, 0.0, 0.0);
        for (var cz = z.x; cz <= z.y; cz = cz + 1u) {
            for (var cy = lo_of(c.y); cy <= hi_of(c.y, P.cy); cy = cy + 1u) {
                let row = flat(vec3<u32>(0u, cy, cz));
                for (var s = wall_start[row + lo_of(c.x)]; s < wall_start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                    let wb = wall_at(s);
                    let e = xi - wb.xyz;
                    let r = sqrt(dot3(e, e));
                    if (2.0 * r > P.big_h && r <= P.big_h) {
                        let t = max(-4.0 * r * r / P.big_h + 6.0 * r - 2.0 * P.big_h, 0.0);
                        let kb = P.adh_k * sqrt(sqrt(t));
                        if (kb > 0.0) {
                            ad = ad + e * (wb.w * kb / r);
                        }
                    }
                }
            }
        }
        a = a - ad * P.beta;
    }
    return a;
}

// A neighbour s's share of the viscous acceleration: m Π_ks ∇W_ks (Monaghan 1992, below).
fn visc_pair(xi: vec3<real>, vi: vec3<real>, ri: real, s: u32) -> vec3<real> {
    let e = xi - vget(X, s);
    let r2 = dot3(e, e);
    let q = sqrt(max(r2, P.tiny)) * P.inv_h;
    let vr = min(dot3(vi - vget(V, s), e), 0.0);
    let pi = P.visc * vr / ((r2 + P.eps_h2) * (0.5 * (ri + sget(RHO, s))));
    return e * (pi * (P.mass * P.gscale * g(q)));
}

// Step 3: the term's own acceleration at (x, v after the divergence solve), Monaghan (1992)
// viscosity a_k = −Σ_j m Π_kj ∇W_kj, Π_kj = −α c0 h min(v_kj·x_kj, 0) / ((r² + 0.01h²) ρ̄_kj)
// plus `surface` if on (the CPU's `add_forces`), the kick v* = v + dt (a + g), and the start of the density solve:
// its velocities v* + dt Σ_b Ψ_b (g·(x_k − x_b)/ρ_k) ∇W_kb (the walls' hydrostatic pressure,
// Adami, Hu & Adams 2012, eq. 27: the CPU's `hydrostatic_walls`), its sum of κ/ρ zeroed.
@compute @workgroup_size(WG)
fn forces(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let xi = vget(X, k);
    let vi = vget(V, k);
    let ri = sget(RHO, k);
    var a = vec3<real>(0.0, 0.0, 0.0);
    if (P.visc > 0.0) {
        let m = nlen[k];
        if (m <= P.cap) {
            for (var j = 0u; j < m; j = j + 1u) {
                a = a + visc_pair(xi, vi, ri, nbr[j * P.n + k]);
            }
        } else {
            var w = walk(k, xi);
            for (var s = next_near(&w); s != END; s = next_near(&w)) {
                a = a + visc_pair(xi, vi, ri, s);
            }
        }
    }
    if (P.gamma > 0.0 || P.beta > 0.0) {
        a = a + surface(k, xi, ri);
    }
    let grav = vec3<real>(P.gx_, P.gy_, P.gz_);
    let vk = vi + (a + grav) * P.dt;
    vset(AF, k, a);
    vset(VK, k, vk);
    var vd = vk;
    if (ri > 0.0) {
        vd = vk + vget(HW, k) * (P.dt / ri);
    }
    vset(VD, k, vd);
    sset(KSUM, k, 0.0);
}

// Step 5: the drift x' = x + dt v (v the density solve's result), the box (`box_faces`, as
// sph.wgsl's `integrate`: onto the face crossed, −e v_n, friction), written back in the caller's order;
// the warm starts and the pressure p = ρ² (Σκ/ρ + Σκ^v/ρ) (the CPU's `solve`); the books: each
// velocity change's work over the step's mean velocity v̄ = (v0 + v1)/2 (the CPU's
// `books_step`): −m (v_div − v0)·v̄, −m (v1 − v*)·v̄, −m dt a·v̄, and the box's.
@compute @workgroup_size(WG)
fn drift(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let d = P.dim;
    let n = P.n;
    let i = order[k];
    let xi = vget(X, k);
    let v0 = vget(V0, k);
    let vdiv = vget(V, k);
    let vk = vget(VK, k);
    let v1 = vget(VD, k);
    let mean = (v0 + v1) * 0.5;
    let m = P.mass;
    books[i] = books[i] - m * dot3(vdiv - v0, mean);
    books[n + i] = books[n + i] - m * dot3(v1 - vk, mean);
    books[2u * n + i] = books[2u * n + i] - m * P.dt * dot3(vget(AF, k), mean);
    let ks = sget(KSUM, k);
    let kv = sget(KSUMV, k);
    let r = sget(RHO, k);
    hist[i] = ks;
    hist[n + i] = kv;
    var p = (ks + kv) * r * r;
    if (P.gamma > 0.0) {
        p = p + sget(VIR, k);
    }
    hist[2u * n + i] = p;
    let grav = vec3<real>(P.gx_, P.gy_, P.gz_);
    let lo = vec3<real>(P.lo_x, P.lo_y, P.lo_z);
    let hi = vec3<real>(P.hi_x, P.hi_y, P.hi_z);
    var xn = xi;
    var vn = v1;
    var outside = false;
    for (var a = 0u; a < d; a = a + 1u) {
        xn[a] = xi[a] + v1[a] * P.dt;
        outside = outside || xn[a] < lo[a] || xn[a] > hi[a];
    }
    if (outside) {
        let x0 = xn;
        let vb = vn;
        box_faces(&xn, &vn);
        // The kinetic energy the faces took, and gravity's work over the projection (the
        // potential −m g·x changes by it: the books stay balanced).
        // And semi-implicit Euler's share of the velocity change (the CPU's `projection_kick`).
        books[3u * n + i] = books[3u * n + i] + (0.5 * m * (dot3(vb, vb) - dot3(vn, vn)) + m * dot3(grav, xn - x0))
            - 0.5 * P.dt * m * dot3(grav, vn - vb);
    }
    var broken = false;
    for (var a = 0u; a < d; a = a + 1u) {
        pos[d * i + a] = xn[a];
        vel[d * i + a] = vn[a];
        broken = broken || bad(xn[a]) || bad(vn[a]);
    }
    if (broken) {
        atomicMin(&ctl[FLAG], i);
    }
}

// The control kernels (one workgroup each, dispatched directly): their bind group adds the
// errors and the indirect dispatch counts of the solves' particle passes, which the particle
// passes' own bind group leaves out (a buffer is either an indirect count or written storage
// within one dispatch).
// The mean errors of the last solves and the largest of all steps: divergence, density, then
// their maxima.
@group(0) @binding(17) var<storage, read_write> errs: array<real>;
// The workgroups (x, y, z) of the running solve's particle passes: the particle dispatch's
// while it goes on, none once it stopped.
@group(0) @binding(18) var<storage, read_write> args: array<u32>;

fn arm() {
    atomicStore(&ctl[ACTIVE], 1u);
    atomicStore(&ctl[ITER], 0u);
    args[0] = P.gx;
    args[1] = P.gy;
    args[2] = 1u;
}

@compute @workgroup_size(1)
fn init_div() {
    arm();
}

@compute @workgroup_size(1)
fn init_den() {
    arm();
}

var<workgroup> tot: array<real, RW>;

// The stopping test after an error pass of solve s (0 divergence, 1 density): the mean error
// Σ e_k · norm (partials summed in a fixed order: thread t over t, t + 256, …, then a tree); the
// solve stops once it is within the tolerance after at least `least` iterations (the CPU's
// 1 and 2) or after max_it, and its iterations and error are booked; else it counts one more
// iteration, whose velocity update follows.
fn check(l: u32, s: u32, tol: real, norm: real, least: u32) {
    var acc: real = 0.0;
    for (var j = l; j < P.groups; j = j + RW) {
        acc = acc + partial[j];
    }
    tot[l] = acc;
    workgroupBarrier();
    for (var h = RW / 2u; h > 0u; h = h / 2u) {
        if (l < h) {
            tot[l] = tot[l] + tot[l + h];
        }
        workgroupBarrier();
    }
    if (l != 0u || atomicLoad(&ctl[ACTIVE]) == 0u) {
        return;
    }
    let err = tot[0] * norm;
    let it = atomicLoad(&ctl[ITER]);
    let done = err <= tol && it >= min(least, P.max_it);
    if (done || it >= P.max_it) {
        atomicStore(&ctl[ACTIVE], 0u);
        args[0] = 0u;
        args[1] = 0u;
        atomicStore(&ctl[LAST_DIV + s], it);
        atomicMax(&ctl[MOST_DIV + s], it);
        atomicAdd(&ctl[TOTAL_DIV + s], it);
        if (!(err <= tol)) {
            atomicAdd(&ctl[UNCONVERGED], 1u);
        }
        if (s == 1u) {
            atomicAdd(&ctl[STEPS], 1u);
        }
        errs[s] = err;
        errs[2u + s] = max(errs[2u + s], err);
    } else {
        atomicStore(&ctl[ITER], it + 1u);
    }
}

@compute @workgroup_size(RW)
fn check_div(@builtin(local_invocation_index) l: u32) {
    check(l, 0u, P.tol_div, P.norm_div, 1u);
}

@compute @workgroup_size(RW)
fn check_den(@builtin(local_invocation_index) l: u32) {
    check(l, 1u, P.tol_den, P.norm_den, 2u);
}

// After the iterations recorded for a solve, when fewer than max_it: a solve still running
// has outran them; it is marked (the host then reruns the submission from its start with
// max_it recorded) and stopped, so that the rest of the submission runs on without it.
@compute @workgroup_size(1)
fn seal() {
    if (atomicLoad(&ctl[ACTIVE]) != 0u) {
        atomicStore(&ctl[TRUNCATED], 1u);
        atomicStore(&ctl[ACTIVE], 0u);
        args[0] = 0u;
        args[1] = 0u;
    }
}
