// Weakly compressible SPH on the device (sph.rs): one step is the cell list (cells.wgsl, its own
// bind group), then `gather`, `density` and `integrate` here. Threads run over the particles in
// cell order (slot k of `order`), read the cell-ordered copies made by `gather`, and write the
// state back in the caller's order, so `integrate` never reads what it writes. Every sum runs
// over the 3^d cells around the particle's own (z, y, x, then each cell's particles by index;
// a row's three cells along x are consecutive in `order`, so each row is one run of slots):
// no float atomics, the same bits on every run. The expressions follow the CPU's scalar kernels
// (rust_core/src/sph/kernels.rs `w`, `g`), passes (passes.rs) and the semi-implicit Euler step
// with the box collider (integrators/semi_implicit_euler.rs, constraints/aabb.rs) operation for
// operation, but without fused multiply-adds. The host prepends the precision header.

struct Params {
    // Particles, dimension, cells along x, y, z (z = 1 in 2D), kernel (0 cubic spline, 1
    // Wendland C2), Tait γ, whether p is clamped to ≥ 0, entries of each slot's neighbour list
    // (`nbr`; 0: no lists).
    n: u32,
    dim: u32,
    cx: u32,
    cy: u32,
    cz: u32,
    kernel: u32,
    gamma: u32,
    clamp: u32,
    cap: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    // 1/h, particle mass and 1/mass, σ_d, −σ_d/h², 2 α c0 h, 0.01 h², 4.0001 h² (the pairs
    // looked at), the r² floor, B, 1/ρ0, dt.
    inv_h: real,
    mass: real,
    inv_mass: real,
    sigma: real,
    scale: real,
    visc: real,
    eps_h2: real,
    reach: real,
    tiny: real,
    b: real,
    inv_rho0: real,
    dt: real,
    // Gravity, the box's corners, restitution and friction of its walls.
    gx: real,
    gy: real,
    gz: real,
    lo_x: real,
    lo_y: real,
    lo_z: real,
    hi_x: real,
    hi_y: real,
    hi_z: real,
    restitution: real,
    friction: real,
};

const WG: u32 = 64u;

@group(0) @binding(0) var<uniform> P: Params;
// The state in the caller's order: positions and velocities (`dim` per particle), densities.
@group(0) @binding(1) var<storage, read_write> pos: array<real>;
@group(0) @binding(2) var<storage, read_write> vel: array<real>;
@group(0) @binding(3) var<storage, read_write> rho: array<real>;
// The cell list (cells.wgsl): each particle's cell, each cell's first slot, the particles by cell.
@group(0) @binding(4) var<storage, read> cell_of: array<u32>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> order: array<u32>;
// In cell order: positions, velocities, densities and p/ρ².
@group(0) @binding(7) var<storage, read_write> spos: array<real>;
@group(0) @binding(8) var<storage, read_write> svel: array<real>;
@group(0) @binding(9) var<storage, read_write> srho: array<real>;
@group(0) @binding(10) var<storage, read_write> spr: array<real>;
// The first particle (caller's index) whose state stopped being finite (u32::MAX: none).
@group(0) @binding(11) var<storage, read_write> flag: array<atomic<u32>>;
// The energy books of each particle (caller's order), J: [0, n) the viscous dissipation,
// [n, 2n) what the box's walls removed; [2n, 3n) the squared pressure and viscous acceleration
// of the last step (m²/s⁴). Each written only by the thread that owns the particle.
@group(0) @binding(12) var<storage, read_write> books: array<real>;
// The static wall particles (Akinci et al. 2012), sorted by (cell, index) on the host over the
// fluid's cells (those just outside the grid clamped into its outer cells): `dim` coordinates
// then Ψ_b (kg) per wall particle; and per cell c the first wall of the cell (wall_start[cells]
// = the walls' count).
@group(0) @binding(13) var<storage, read> wall: array<real>;
@group(0) @binding(14) var<storage, read> wall_start: array<u32>;
// The step's neighbour lists, made by `density` for `integrate`: slot k's fluid neighbours
// within 2h (itself included, as the sums include it) in the order the cells give them, the
// j-th at nbr[j n + k] (a warp's threads read consecutive words), and how many (`nlen`). A slot
// with more than `cap` reads the cells instead, so the lists never change a sum: the same pairs
// in the same order, each evaluated by the same expression.
@group(0) @binding(15) var<storage, read_write> nbr: array<u32>;
@group(0) @binding(16) var<storage, read_write> nlen: array<u32>;
// Per slot (cell order), `dim` reals: the walls' Σ_b Ψ_b g(q) (x_k − x_b), made by `density`
// in the same walk as their density share, for `integrate` (one walk of the walls' cells a step).
@group(0) @binding(17) var<storage, read_write> swall: array<real>;

// Cell-ordered position (or velocity) of slot s, z = 0 in 2D.
fn at(a: u32, s: u32) -> vec3<real> {
    let d = P.dim;
    var r = vec3<real>(0.0, 0.0, 0.0);
    for (var k = 0u; k < d; k = k + 1u) {
        if (a == 0u) {
            r[k] = spos[d * s + k];
        } else {
            r[k] = svel[d * s + k];
        }
    }
    return r;
}

// Position of wall particle s (z = 0 in 2D) and its Ψ_b.
fn wall_at(s: u32) -> vec4<real> {
    let d = P.dim;
    var r = vec4<real>(0.0, 0.0, 0.0, 0.0);
    for (var k = 0u; k < d; k = k + 1u) {
        r[k] = wall[(d + 1u) * s + k];
    }
    r.w = wall[(d + 1u) * s + d];
    return r;
}

// w(q), zero for q ≥ 2: cubic spline ¼(2−q)₊³ − (1−q)₊³ (Monaghan & Lattanzio 1985), Wendland
// C2 (1 − q/2)₊⁴ (2q + 1) (Wendland 1995; Dehnen & Aly 2012). kernels.rs `w`.
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

// g(q) = w'(q)/q (finite at q = 0). kernels.rs `g`.
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

// s^γ: passes.rs `powi` (a fixed chain for γ = 7).
fn powi(s: real) -> real {
    if (P.gamma == 7u) {
        let s2 = s * s;
        let s4 = s2 * s2;
        return s4 * s2 * s;
    }
    var r = s;
    for (var k = 1u; k < P.gamma; k = k + 1u) {
        r = r * s;
    }
    return r;
}

// Slot k: the state of particle order[k], copied into cell order.
@compute @workgroup_size(WG)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let d = P.dim;
    let i = order[k];
    for (var a = 0u; a < d; a = a + 1u) {
        spos[d * k + a] = pos[d * i + a];
        svel[d * k + a] = vel[d * i + a];
    }
}

// Summation density ρ_k = σ [Σ_j m w(|x_k − x_j|/h) (self included) + Σ_b Ψ_b w(|x_k − x_b|/h)
// (the walls, Akinci et al. 2012, eq. 4–5)] and p_k/ρ_k² by the Tait
// equation of state p = B((ρ/ρ0)^γ − 1), clamped to ≥ 0 if asked: passes.rs `Density`.
@compute @workgroup_size(WG)
fn density(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let d = P.dim;
    let c = coords(cell_of[order[k]]);
    let xi = at(0u, k);
    var acc: real = 0.0;
    var listed = 0u;
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
                let e = xi - at(0u, s);
                var r2 = e.x * e.x + e.y * e.y;
                if (d == 3u) {
                    r2 = e.z * e.z + r2;
                }
                // Pairs past the support add exactly 0 (the margin: rounding of q near 2).
                if (r2 < P.reach) {
                    acc = acc + w(sqrt(max(r2, P.tiny)) * P.inv_h) * P.mass;
                    if (listed < P.cap) {
                        nbr[listed * P.n + k] = s;
                    }
                    listed = listed + 1u;
                }
            }
        }
    }
    nlen[k] = listed;
    // The walls' share Σ_b Ψ_b w(|x_k − x_b|/h), added to the same sum after the fluid's (as
    // passes.rs `Density` adds them to its accumulator); in the same walk, the sum of their
    // pressure push Σ_b Ψ_b g(q) (x_k − x_b) that `integrate` takes (the same expressions).
    var wacc = vec3<real>(0.0, 0.0, 0.0);
    for (var z = z0; z <= z1; z = z + 1u) {
        for (var y = lo_of(c.y); y <= hi_of(c.y, P.cy); y = y + 1u) {
            let row = flat(vec3<u32>(0u, y, z));
            for (var s = wall_start[row + lo_of(c.x)]; s < wall_start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                let wb = wall_at(s);
                let e = xi - wb.xyz;
                var r2 = e.x * e.x + e.y * e.y;
                if (d == 3u) {
                    r2 = e.z * e.z + r2;
                }
                if (r2 < P.reach) {
                    let q = sqrt(max(r2, P.tiny)) * P.inv_h;
                    acc = acc + w(q) * wb.w;
                    let cf = wb.w * g(q);
                    for (var a = 0u; a < d; a = a + 1u) {
                        wacc[a] = cf * e[a] + wacc[a];
                    }
                }
            }
        }
    }
    for (var a = 0u; a < d; a = a + 1u) {
        swall[d * k + a] = wacc[a];
    }
    let r = P.sigma * acc;
    var p = P.b * (powi(r * P.inv_rho0) - 1.0);
    if (P.clamp != 0u) {
        p = max(p, 0.0);
    }
    srho[k] = r;
    spr[k] = p / (r * r);
    rho[order[k]] = r;
}

// Neighbour slot s's share of slot k's pressure and viscosity acceleration, added to acc, and
// of its viscous power, added to pw (the sums of `integrate`, below).
fn force_pair(s: u32, xi: vec3<real>, vi: vec3<real>, rho_i: real, pr_i: real, acc: ptr<function, vec3<real>>,
              pw: ptr<function, real>) {
    let d = P.dim;
    let e = xi - at(0u, s);
    let u = vi - at(1u, s);
    var r2 = e.x * e.x + e.y * e.y;
    var vr = u.x * e.x + u.y * e.y;
    if (d == 3u) {
        r2 = e.z * e.z + r2;
        vr = u.z * e.z + vr;
    }
    let gq = g(sqrt(max(r2, P.tiny)) * P.inv_h);
    let approach = max(0.0 - vr, 0.0);
    let pi = P.visc * approach / ((r2 + P.eps_h2) * (rho_i + srho[s]));
    let mg = P.mass * gq;
    let cf = mg * (pr_i + spr[s] + pi);
    var t = *acc;
    for (var a = 0u; a < d; a = a + 1u) {
        t[a] = cf * e[a] + t[a];
    }
    *acc = t;
    *pw = (mg * pi) * vr + *pw;
}

// Slot k: the pressure and viscosity acceleration (passes.rs `Forces`)
//   a_i = −(σ/h²) [Σ_j m (p_i/ρ_i² + p_j/ρ_j² + Π_ij) g(q) (x_i − x_j)
//                  + p_i/ρ_i² Σ_b Ψ_b g(q) (x_i − x_b)]   (walls b: Akinci et al. 2012),
//   Π_ij = 2 α c0 h max(−v_ij·x_ij, 0) / ((r² + 0.01h²)(ρ_i + ρ_j))   (Monaghan 1992),
// then the semi-implicit Euler step v += dt (f/m + g), x += dt v (f = m a, as the CPU's force
// term and integrator), then the box: a coordinate outside is put on the face it crossed; moving
// outward, its velocity there becomes −e v_n and the tangential speed drops by μ (1 + e)|v_n|,
// never past 0 (constraints/aabb.rs).
// The books, as the CPU keeps them: the viscous power at the step's start (the state the forces
// see), ½ m_i (σ/h²) Σ_j m g(q) Π_ij v_ij·x_ij ≥ 0 (passes.rs `Forces`, POWER), times dt
// (semi_implicit_euler.rs `book_power(dt)`); a particle the walls move books
// (KE before − KE after) + F·(x_after − x_before), F the step's SPH force plus m g (aabb.rs).
@compute @workgroup_size(WG)
fn integrate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = index(gid);
    if (k >= P.n) {
        return;
    }
    let d = P.dim;
    let i = order[k];
    let c = coords(cell_of[i]);
    let xi = at(0u, k);
    let vi = at(1u, k);
    let rho_i = srho[k];
    let pr_i = spr[k];
    var acc = vec3<real>(0.0, 0.0, 0.0);
    var pw: real = 0.0;
    var z0 = 0u;
    var z1 = 0u;
    if (d == 3u) {
        z0 = lo_of(c.z);
        z1 = hi_of(c.z, P.cz);
    }
    let m = nlen[k];
    if (m <= P.cap) {
        for (var j = 0u; j < m; j = j + 1u) {
            force_pair(nbr[j * P.n + k], xi, vi, rho_i, pr_i, &acc, &pw);
        }
    } else {
        for (var z = z0; z <= z1; z = z + 1u) {
            for (var y = lo_of(c.y); y <= hi_of(c.y, P.cy); y = y + 1u) {
                let row = flat(vec3<u32>(0u, y, z));
                for (var s = start[row + lo_of(c.x)]; s < start[row + hi_of(c.x, P.cx) + 1u]; s = s + 1u) {
                    let e = xi - at(0u, s);
                    var r2 = e.x * e.x + e.y * e.y;
                    if (d == 3u) {
                        r2 = e.z * e.z + r2;
                    }
                    if (r2 < P.reach) {
                        force_pair(s, xi, vi, rho_i, pr_i, &acc, &pw);
                    }
                }
            }
        }
    }
    // The walls' pressure (Akinci et al. 2012, eq. 10, the fluid's own pressure mirrored; no
    // viscosity against them): Σ_b Ψ_b g(q) (x_i − x_b) (summed by `density`), times p_i/ρ_i²
    // below (passes.rs `Forces`).
    var wacc = vec3<real>(0.0, 0.0, 0.0);
    for (var a = 0u; a < d; a = a + 1u) {
        wacc[a] = swall[d * k + a];
    }
    let grav = vec3<real>(P.gx, P.gy, P.gz);
    let lo = vec3<real>(P.lo_x, P.lo_y, P.lo_z);
    let hi = vec3<real>(P.hi_x, P.hi_y, P.hi_z);
    var xn = xi;
    var vn = vi;
    var fs = vec3<real>(0.0, 0.0, 0.0);
    var outside = false;
    var a2: real = 0.0;
    for (var a = 0u; a < d; a = a + 1u) {
        let asph = P.scale * (acc[a] + pr_i * wacc[a]);
        a2 = a2 + asph * asph;
        let f = P.mass * asph;
        fs[a] = f;
        vn[a] = vi[a] + (f * P.inv_mass + grav[a]) * P.dt;
        xn[a] = xi[a] + vn[a] * P.dt;
        outside = outside || xn[a] < lo[a] || xn[a] > hi[a];
    }
    books[i] = books[i] + (0.5 * P.mass * (0.0 - P.scale) * pw) * P.dt;
    // |a|² of the pressure and viscous acceleration, the step limit's force criterion.
    books[2u * P.n + i] = a2;
    if (outside) {
        let x0 = xn;
        let v0 = vn;
        box_faces(&xn, &vn);
        var ke0: real = 0.0;
        var ke1: real = 0.0;
        var work: real = 0.0;
        var kicked: real = 0.0;
        for (var a = 0u; a < d; a = a + 1u) {
            ke0 = ke0 + v0[a] * v0[a];
            ke1 = ke1 + vn[a] * vn[a];
            work = work + (fs[a] + grav[a] * P.mass) * (xn[a] - x0[a]);
            kicked = kicked + grav[a] * P.mass * (vn[a] - v0[a]);
        }
        let du = 0.0 - work;
        // And semi-implicit Euler's share of the velocity change (the CPU's `projection_kick`).
        books[P.n + i] = books[P.n + i] + ((0.5 * P.mass * ke0 - 0.5 * P.mass * ke1) - du) - 0.5 * P.dt * kicked;
    }
    var broken = false;
    for (var a = 0u; a < d; a = a + 1u) {
        pos[d * i + a] = xn[a];
        vel[d * i + a] = vn[a];
        broken = broken || bad(xn[a]) || bad(vn[a]);
    }
    if (broken) {
        atomicMin(&flag[0], i);
    }
}
