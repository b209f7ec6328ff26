// The stable fluid's stages on the device, node for node the CPU's `grids::fluid` (stages.rs,
// lanes.rs): ghost fills, semi-Lagrangian and MacCormack advection (RK2 backtrace, bilinear
// interpolation, Selle et al.'s clamp), sources, buoyancy and vorticity confinement, the
// incremental projection's half kick, the divergence and the pressure gradient, the viscous
// solve's right-hand sides, the energy books' sums and the finiteness check.
//
// Storage (slabs of one layout each, at offsets the host gives in the parameter block):
// U: the u layout, (nx+1) × (ny+2), index i + (nx+1)(j+1); slab 0 is u itself.
// V: the v layout, (nx+2) × (ny+1), index (i+1) + (nx+2) j; slab 0 is v itself.
// C: cells, nx × ny: density, temperature, scratch, the fluid mask, the inflow column.
// S: the solver's padded arrays (pressure, its right-hand side and unknown, viscosity's).
// Gather only: each thread writes its own node. The sources are applied per location in the
// CPU's order of entries (the host groups them by location).

@group(0) @binding(3) var<storage, read_write> U: array<real>;
@group(0) @binding(4) var<storage, read_write> V: array<real>;
@group(0) @binding(5) var<storage, read_write> C: array<real>;
@group(0) @binding(6) var<storage, read_write> S: array<real>;
// The sources' groups: per group, its location, the first of its weights and their count.
@group(0) @binding(7) var<storage, read> ops: array<u32>;
@group(0) @binding(8) var<storage, read> opw: array<real>;
// The solvers' ints and the finiteness flags (at `o7` of `check`'s block): atomics here.
@group(0) @binding(9) var<storage, read_write> flags: array<atomic<u32>>;

// The tracers (x0, y0, x1, …, m) and the first source's cells (where they are re-seeded; none:
// anywhere in the fluid).
@group(0) @binding(10) var<storage, read_write> TR: array<real>;
@group(0) @binding(11) var<storage, read> seeds: array<u32>;

// ---- sampling (`Lay::sample`): layout 0 u, 1 v, 2 cells.

struct Lay {
    w: u32,
    h: u32,
    ox: real,
    oy: real,
};

fn lay(k: u32) -> Lay {
    if (k == 0u) {
        return Lay(P.nx + 1u, P.ny + 2u, 0.0, -0.5);
    }
    if (k == 1u) {
        return Lay(P.nx + 2u, P.ny + 1u, -0.5, 0.0);
    }
    return Lay(P.nx, P.ny, 0.5, 0.5);
}

// The first tap and the weights of bilinear interpolation at (x, y) (m).
struct Taps {
    k: u32,
    tx: real,
    ty: real,
};

fn cl(x: real, lo: real, hi: real) -> real {
    // `f64::clamp`'s choice (and the lanes' order: below first).
    let a = select(x, lo, x < lo);
    return select(a, hi, a > hi);
}

fn taps(l: Lay, x: real, y: real, inv_dx: real) -> Taps {
    let wm = real(l.w - 1u);
    let hm = real(l.h - 1u);
    let fx = cl(x * inv_dx - l.ox, 0.0, wm);
    let fy = cl(y * inv_dx - l.oy, 0.0, hm);
    let i = min(u32(fx), l.w - 2u);
    let j = min(u32(fy), l.h - 2u);
    return Taps(min(i + l.w * j, l.w * l.h - l.w - 2u), fx - real(i), fy - real(j));
}

fn lerp4(t: Taps, a00: real, a10: real, a01: real, a11: real) -> real {
    return (1.0 - t.ty) * ((1.0 - t.tx) * a00 + t.tx * a10) + t.ty * ((1.0 - t.tx) * a01 + t.tx * a11);
}

// Four corners of a layout's slab at `base`, in one of the buffers.
struct Four {
    a00: real,
    a10: real,
    a01: real,
    a11: real,
};

fn four_u(base: u32, t: Taps) -> Four {
    let w = P.nx + 1u;
    let k = base + t.k;
    return Four(U[k], U[k + 1u], U[k + w], U[k + w + 1u]);
}

fn four_v(base: u32, t: Taps) -> Four {
    let w = P.nx + 2u;
    let k = base + t.k;
    return Four(V[k], V[k + 1u], V[k + w], V[k + w + 1u]);
}

fn four_c(base: u32, t: Taps) -> Four {
    let w = P.nx;
    let k = base + t.k;
    return Four(C[k], C[k + 1u], C[k + w], C[k + w + 1u]);
}

fn lerp(t: Taps, f: Four) -> real {
    return lerp4(t, f.a00, f.a10, f.a01, f.a11);
}

// The corners' min and max by plain compares, in `Lay::sample`'s order.
fn lo4(f: Four) -> real {
    let a = select(f.a10, f.a00, f.a00 < f.a10);
    let b = select(f.a11, f.a01, f.a01 < f.a11);
    return select(b, a, a < b);
}

fn hi4(f: Four) -> real {
    let a = select(f.a10, f.a00, f.a00 > f.a10);
    let b = select(f.a11, f.a01, f.a01 > f.a11);
    return select(b, a, a > b);
}

// The velocity (slab 0 of U and V) at (x, y): `Vel::at`. r2 is 1/dx in every advection block.
fn vel_at(x: real, y: real) -> vec2<real> {
    let tu = taps(lay(0u), x, y, P.r2);
    let tv = taps(lay(1u), x, y, P.r2);
    return vec2<real>(lerp(tu, four_u(0u, tu)), lerp(tv, four_v(0u, tv)));
}

// Where the point at p moving at a was dt ago (RK2, midpoint), clamped to the domain
// (r4, r5: its extent): `Vel::trace_from`.
fn trace(p: vec2<real>, a: vec2<real>, dt: real) -> vec2<real> {
    let h = 0.5 * dt;
    let m = vec2<real>(cl(p.x - h * a.x, 0.0, P.r4), cl(p.y - h * a.y, 0.0, P.r5));
    let b = vel_at(m.x, m.y);
    return vec2<real>(cl(p.x - dt * b.x, 0.0, P.r4), cl(p.y - dt * b.y, 0.0, P.r5));
}

// The velocity at node (a, b) of a layout (`Vel::node`).
fn node_vel(kind: u32, a: u32, b: u32) -> vec2<real> {
    let wu = P.nx + 1u;
    let wv = P.nx + 2u;
    if (kind == 2u) {
        return vec2<real>(0.5 * (U[a + wu * (b + 1u)] + U[a + 1u + wu * (b + 1u)]),
                          0.5 * (V[(a + 1u) + wv * b] + V[(a + 1u) + wv * (b + 1u)]));
    }
    if (kind == 0u) {
        return vec2<real>(U[a + wu * b],
                          0.25 * ((V[a + wv * (b - 1u)] + V[a + 1u + wv * (b - 1u)]) + (V[a + wv * b] + V[a + 1u + wv * b])));
    }
    return vec2<real>(0.25 * ((U[a - 1u + wu * b] + U[a + wu * b]) + (U[a - 1u + wu * (b + 1u)] + U[a + wu * (b + 1u)])),
                      V[a + wv * b]);
}

fn node_pos(l: Lay, a: u32, b: u32) -> vec2<real> {
    let dx = P.r1;
    return vec2<real>((real(a) + l.ox) * dx, (real(b) + l.oy) * dx);
}

// ---- advection. Block: r0 dt, r1 dx, r2 1/dx, r3 the ambient temperature, r4, r5 the extent;
// flags bit 0: MacCormack.

// Density and temperature of each cell along one backtrace (`SmokeRow`): o0, o1 the sources,
// o2, o3 the semi-Lagrangian pass (MacCormack's second pass), o4, o5 the results; o6 the fluid
// mask.
@compute @workgroup_size(WG)
fn smoke(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let l = lay(2u);
    let p = node_pos(l, i, j);
    let v0 = node_vel(2u, i, j);
    let back = trace(p, v0, P.r0);
    let tb = taps(l, back.x, back.y, P.r2);
    let cd = four_c(P.o0, tb);
    let ct = four_c(P.o1, tb);
    var dv = lerp(tb, cd);
    var tv = lerp(tb, ct);
    let k = i + P.nx * j;
    if ((P.flags & 1u) != 0u) {
        let fwd = trace(p, v0, -P.r0);
        let tf = taps(l, fwd.x, fwd.y, P.r2);
        let db = lerp(tf, four_c(P.o2, tf));
        let tbk = lerp(tf, four_c(P.o3, tf));
        dv = cl(C[P.o2 + k] + 0.5 * (C[P.o0 + k] - db), lo4(cd), hi4(cd));
        tv = cl(C[P.o3 + k] + 0.5 * (C[P.o1 + k] - tbk), lo4(ct), hi4(ct));
    }
    let fluid = C[P.o6 + k] > 0.0;
    C[P.o4 + k] = select(0.0, dv, fluid);
    C[P.o5 + k] = select(P.r3, tv, fluid);
}

// One face component along the backtrace (`FaceRow`), u (`faces_u`) or v (`faces_v`): o0 the
// source, o1 the semi-Lagrangian pass (MacCormack's second pass), o2 the result, o3 the open
// mask (closed faces get 0); nodes a0..a1 (o4, o5) of rows b0..b1 (o6, o7).
fn face_value(kind: u32, a: u32, b: u32) -> real {
    let l = lay(kind);
    let p = node_pos(l, a, b);
    let v0 = node_vel(kind, a, b);
    let back = trace(p, v0, P.r0);
    let tb = taps(l, back.x, back.y, P.r2);
    var cb: Four;
    if (kind == 0u) {
        cb = four_u(P.o0, tb);
    } else {
        cb = four_v(P.o0, tb);
    }
    if ((P.flags & 1u) == 0u) {
        return lerp(tb, cb);
    }
    let fwd = trace(p, v0, -P.r0);
    let tf = taps(l, fwd.x, fwd.y, P.r2);
    let k = a + l.w * b;
    if (kind == 0u) {
        let bk = lerp(tf, four_u(P.o1, tf));
        return cl(U[P.o1 + k] + 0.5 * (U[P.o0 + k] - bk), lo4(cb), hi4(cb));
    }
    let bk = lerp(tf, four_v(P.o1, tf));
    return cl(V[P.o1 + k] + 0.5 * (V[P.o0 + k] - bk), lo4(cb), hi4(cb));
}

@compute @workgroup_size(WG)
fn faces_u(@builtin(global_invocation_id) g: vec3<u32>) {
    let a = P.o4 + g.x;
    let b = P.o6 + g.y;
    if (a >= P.o5 || b >= P.o7) {
        return;
    }
    let k = a + (P.nx + 1u) * b;
    let val = face_value(0u, a, b);
    U[P.o2 + k] = select(0.0, val, U[P.o3 + k] > 0.0);
}

@compute @workgroup_size(WG)
fn faces_v(@builtin(global_invocation_id) g: vec3<u32>) {
    let a = P.o4 + g.x;
    let b = P.o6 + g.y;
    if (a >= P.o5 || b >= P.o7) {
        return;
    }
    let k = a + (P.nx + 2u) * b;
    let val = face_value(1u, a, b);
    V[P.o2 + k] = select(0.0, val, V[P.o3 + k] > 0.0);
}

// ---- ghosts (`fill_u_ghosts`, `fill_v_ghosts`). Block: o0 the u slab, o1 the v slab, o2 the
// inflow column (in C); flags bit 0 u, bit 1 v, bit 2 no slip, bit 3 an inflow; r0 the lid.

// The inflow column of u, held at its values (before `ghosts`).
@compute @workgroup_size(WG)
fn inflow(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x < P.ny) {
        U[P.o0 + (P.nx + 1u) * (g.x + 1u)] = C[P.o2 + g.x];
    }
}

@compute @workgroup_size(WG)
fn ghosts(@builtin(global_invocation_id) g: vec3<u32>) {
    let t = g.x;
    let no_slip = (P.flags & 4u) != 0u;
    if ((P.flags & 1u) != 0u && t <= P.nx) {
        let w = P.nx + 1u;
        let bottom = U[P.o0 + t + w];
        let top = U[P.o0 + t + w * P.ny];
        if (no_slip) {
            U[P.o0 + t] = -bottom;
            U[P.o0 + t + w * (P.ny + 1u)] = 2.0 * P.r0 - top;
        } else {
            U[P.o0 + t] = bottom;
            U[P.o0 + t + w * (P.ny + 1u)] = top;
        }
    }
    if ((P.flags & 2u) != 0u && t <= P.ny) {
        let w = P.nx + 2u;
        var fw = select(real(1.0), real(-1.0), no_slip);
        var fe = fw;
        if ((P.flags & 8u) != 0u) {
            fw = -1.0;
            fe = 1.0;
        }
        V[P.o1 + w * t] = fw * V[P.o1 + 1u + w * t];
        V[P.o1 + P.nx + 1u + w * t] = fe * V[P.o1 + P.nx + w * t];
    }
}

// ---- copies: `lnx` × `lny` values of row length `lw` from o0 to o1 in buffer flags (0 U, 1 V,
// 2 C, 3 S).
@compute @workgroup_size(WG)
fn copy(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x >= P.lnx || g.y >= P.lny) {
        return;
    }
    let k = g.x + P.lw * g.y;
    switch P.flags {
        case 0u: {
            U[P.o1 + k] = U[P.o0 + k];
        }
        case 1u: {
            V[P.o1 + k] = V[P.o0 + k];
        }
        case 2u: {
            C[P.o1 + k] = C[P.o0 + k];
        }
        default: {
            S[P.o1 + k] = S[P.o0 + k];
        }
    }
}

// ---- sources (`apply_sources`), one dispatch per source: thread t takes group t of its cells
// (o0 the first, o1 how many), then of its u faces (o2, o3), then of its v faces (o4, o5), and
// blends its location towards the source's values by each weight of the group in turn. r0..r3
// the source's density, temperature, vx, vy; r4 the cell area. o6, o7: the density and
// temperature slabs. A cell group's Σ Δρ·dA goes to part[t] (the injected amount's partials).
@compute @workgroup_size(WG)
fn sources(@builtin(global_invocation_id) g: vec3<u32>) {
    let t = g.x + 65535u * WG * g.y;
    let n = P.o1 + P.o3 + P.o5;
    if (t >= n) {
        return;
    }
    var q = t;
    var first = P.o0;
    var kind = 0u;
    if (q >= P.o1) {
        q = q - P.o1;
        first = P.o2;
        kind = 1u;
        if (q >= P.o3) {
            q = q - P.o3;
            first = P.o4;
            kind = 2u;
        }
    }
    let e = 3u * (first + q);
    let loc = ops[e];
    let w0 = ops[e + 1u];
    let count = ops[e + 2u];
    if (kind == 0u) {
        var d = C[P.o6 + loc];
        var tt = C[P.o7 + loc];
        var inj: real = 0.0;
        for (var m = 0u; m < count; m = m + 1u) {
            let w = opw[w0 + m];
            let dd = w * (P.r0 - d);
            d = d + dd;
            inj = inj + dd * P.r4;
            tt = tt + w * (P.r1 - tt);
        }
        C[P.o6 + loc] = d;
        C[P.o7 + loc] = tt;
        part[q] = inj;
    } else if (kind == 1u) {
        var u = U[loc];
        let m = U[4u * (P.nx + 1u) * (P.ny + 2u) + loc];
        for (var k = 0u; k < count; k = k + 1u) {
            u = u + m * opw[w0 + k] * (P.r2 - u);
        }
        U[loc] = u;
    } else {
        var v = V[loc];
        let m = V[4u * (P.nx + 2u) * (P.ny + 1u) + loc];
        for (var k = 0u; k < count; k = k + 1u) {
            v = v + m * opw[w0 + k] * (P.r3 - v);
        }
        V[loc] = v;
    }
}

// ---- forces (`apply_forces`). Block: r0 dt, r1 dx, r2 ε, r3 α, r4 β, r5 the ambient
// temperature; o0 the vorticity slab, o1, o2 the confinement force's slabs, o3, o4 density and
// temperature; o5, o6 the open masks (in U, V); flags bit 0: confinement.

fn uc(i: u32, j: u32) -> real {
    let w = P.nx + 1u;
    return 0.5 * (U[i + w * (j + 1u)] + U[i + 1u + w * (j + 1u)]);
}

fn vc(i: u32, j: u32) -> real {
    let w = P.nx + 2u;
    return 0.5 * (V[(i + 1u) + w * j] + V[(i + 1u) + w * (j + 1u)]);
}

// The reciprocal of a difference's span (2: centred, else one-sided).
fn inv_span(d: u32) -> real {
    return select(1.0 / P.r1, 0.5 / P.r1, d == 2u);
}

@compute @workgroup_size(WG)
fn vorticity(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let j0 = select(j - 1u, 0u, j == 0u);
    let j1 = min(j + 1u, P.ny - 1u);
    let i0 = select(i - 1u, 0u, i == 0u);
    let i1 = min(i + 1u, P.nx - 1u);
    C[P.o0 + i + P.nx * j] = (vc(i1, j) - vc(i0, j)) * inv_span(i1 - i0) - (uc(i, j1) - uc(i, j0)) * inv_span(j1 - j0);
}

@compute @workgroup_size(WG)
fn confine(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let nx = P.nx;
    let j0 = select(j - 1u, 0u, j == 0u);
    let j1 = min(j + 1u, P.ny - 1u);
    let i0 = select(i - 1u, 0u, i == 0u);
    let i1 = min(i + 1u, nx - 1u);
    let wz = P.o0;
    let ex = (abs(C[wz + i1 + nx * j]) - abs(C[wz + i0 + nx * j])) * inv_span(i1 - i0);
    let ey = (abs(C[wz + i + nx * j1]) - abs(C[wz + i + nx * j0])) * inv_span(j1 - j0);
    let k = P.r2 * P.r1 * C[wz + i + nx * j] / (sqrt(ex * ex + ey * ey) + TINY);
    C[P.o1 + i + nx * j] = k * ey;
    C[P.o2 + i + nx * j] = -k * ex;
}

// u faces i in 1..nx of rows j: += open · dt · ½(f_x left + right).
@compute @workgroup_size(WG)
fn force_u(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x + 1u;
    let j = g.y;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let k = i + (P.nx + 1u) * (j + 1u);
    let f = P.o1 + P.nx * j;
    U[k] = U[k] + U[P.o5 + k] * P.r0 * 0.5 * (C[f + i - 1u] + C[f + i]);
}

// v faces of rows j in 1..ny: += open · dt · (buoyancy + ½(f_y below + above)).
@compute @workgroup_size(WG)
fn force_v(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y + 1u;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let nx = P.nx;
    let k = (i + 1u) + (nx + 2u) * j;
    let m = V[P.o6 + k];
    let c0 = i + nx * (j - 1u);
    let c1 = i + nx * j;
    let b = -P.r3 * 0.5 * (C[P.o3 + c0] + C[P.o3 + c1]) + P.r4 * (0.5 * (C[P.o4 + c0] + C[P.o4 + c1]) - P.r5);
    var v = V[k] + m * P.r0 * b;
    if ((P.flags & 1u) != 0u) {
        v = v + m * P.r0 * 0.5 * (C[P.o2 + c0] + C[P.o2 + c1]);
    }
    V[k] = v;
}

// ---- the projection. Pressure and its relatives are padded (nx+2) × (ny+2) arrays in S.

// The half kick (`kick_faces`): ku (U slab o1) = u − open·h·Δp, kv (V slab o2) likewise, p at
// o0 in S, h = r0; the opens at o5 (U) and o6 (V). Rows beyond the interior are copied.
@compute @workgroup_size(WG)
fn kick_u(@builtin(global_invocation_id) g: vec3<u32>) {
    let wu = P.nx + 1u;
    let a = g.x;
    let b = g.y;
    if (a >= wu || b >= P.ny + 2u) {
        return;
    }
    let k = a + wu * b;
    if (b == 0u || b > P.ny) {
        U[P.o1 + k] = U[k];
        return;
    }
    let w = P.nx + 2u;
    U[P.o1 + k] = U[k] - U[P.o5 + k] * P.r0 * (S[P.o0 + w * b + a + 1u] - S[P.o0 + w * b + a]);
}

@compute @workgroup_size(WG)
fn kick_v(@builtin(global_invocation_id) g: vec3<u32>) {
    let w = P.nx + 2u;
    let a = g.x;
    let j = g.y;
    if (a >= w || j > P.ny) {
        return;
    }
    let k = a + w * j;
    if (j == 0u || j == P.ny) {
        V[P.o2 + k] = V[k];
        return;
    }
    V[P.o2 + k] = V[k] - V[P.o6 + k] * P.r0 * (S[P.o0 + w * (j + 1u) + a] - S[P.o0 + w * j + a]);
}

// rhs (o0 in S) = −fluid · (unnormalised divergence), the fluid mask at o6 (in C).
@compute @workgroup_size(WG)
fn divergence(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i >= P.nx || j >= P.ny) {
        return;
    }
    let wu = P.nx + 1u;
    let w = P.nx + 2u;
    let du = U[wu * (j + 1u) + i + 1u] - U[wu * (j + 1u) + i];
    let dv = V[w * (j + 1u) + i + 1u] - V[w * j + i + 1u];
    S[P.o0 + w * (j + 1u) + i + 1u] = -C[P.o6 + i + P.nx * j] * (du + dv);
}

// Over the padded array (lw × lny): q (o1) = p (o0) · r0 (`start`), or with flags bit 0,
// p = r1 · p + q · r0 (the pressure kept).
@compute @workgroup_size(WG)
fn pressure(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x >= P.lw || g.y >= P.lny) {
        return;
    }
    let k = g.x + P.lw * g.y;
    if ((P.flags & 1u) != 0u) {
        S[P.o0 + k] = P.r1 * S[P.o0 + k] + S[P.o1 + k] * P.r0;
    } else {
        S[P.o1 + k] = S[P.o0 + k] * P.r0;
    }
}

// u −= Δq on its faces of the interior rows (open at o5), q at o1 in S.
@compute @workgroup_size(WG)
fn gradient_u(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i > P.nx || j >= P.ny) {
        return;
    }
    let k = i + (P.nx + 1u) * (j + 1u);
    let q = P.o1 + (P.nx + 2u) * (j + 1u) + i;
    U[k] = U[P.o5 + k] * (U[k] - (S[q + 1u] - S[q]));
}

// v −= Δq on rows 1..ny, columns 1..=nx of its layout (open at o6).
@compute @workgroup_size(WG)
fn gradient_v(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x + 1u;
    let j = g.y + 1u;
    if (i > P.nx || j >= P.ny) {
        return;
    }
    let w = P.nx + 2u;
    let k = i + w * j;
    V[k] = V[P.o6 + k] * (V[k] - (S[P.o1 + w * (j + 1u) + i] - S[P.o1 + w * j + i]));
}

// ---- viscosity's right-hand sides and results (`diffuse`). u: unknowns (nx+1) × ny at padded
// width nx+3 in S: x at o0, b at o1; the open mask at o5 and the no-slip walls along each face
// at o6 (U); the pressure at o2 (S); r0 the scale s, r1 the lid's term, r2 the slip term per
// wall and unit pressure difference (`slip_scale`: u*'s wall value (1 − share)·dt·∂p/∂τ, from
// the face's row); flags bit 0: an inflow (its held face feeds the next face's b), bit 1: back
// (u = x).
@compute @workgroup_size(WG)
fn visc_u(@builtin(global_invocation_id) g: vec3<u32>) {
    let wu = P.nx + 1u;
    let i = g.x;
    let j = g.y;
    if (i >= wu || j >= P.ny) {
        return;
    }
    let w = P.nx + 3u;
    let k = wu * (j + 1u) + i;
    let c = w * (j + 1u) + 1u + i;
    if ((P.flags & 2u) != 0u) {
        U[k] = S[P.o0 + c];
        return;
    }
    let u = U[k];
    S[P.o0 + c] = u;
    var b = u;
    if ((P.flags & 1u) != 0u && i == 1u) {
        b = b + U[P.o5 + k] * P.r0 * U[wu * (j + 1u)];
    }
    let pr = P.o2 + (P.nx + 2u) * (j + 1u) + i;
    b = b + U[P.o6 + k] * P.r2 * (S[pr + 1u] - S[pr]);
    if (j == P.ny - 1u) {
        b = b + U[P.o5 + k] * P.r1;
    }
    S[P.o1 + c] = b;
}

// v: unknowns nx × (ny+1) at padded width nx+2: x at o0, b at o1; the no-slip walls along each
// face at o6 (V), the pressure at o2 (S); r2 the slip term (as u's); flags bit 1: back.
@compute @workgroup_size(WG)
fn visc_v(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = g.x;
    let j = g.y;
    if (i >= P.nx || j > P.ny) {
        return;
    }
    let w = P.nx + 2u;
    let k = w * j + 1u + i;
    let c = w * (j + 1u) + 1u + i;
    if ((P.flags & 2u) != 0u) {
        V[k] = S[P.o0 + c];
        return;
    }
    S[P.o0 + c] = V[k];
    var b = V[k];
    if (j > 0u && j < P.ny) {
        let pr = P.o2 + w * j + i + 1u;
        b = b + V[P.o6 + k] * P.r2 * (S[pr + w] - S[pr]);
    }
    S[P.o1 + c] = b;
}

// ---- books. Partial sums over a region of a slab: nodes o1..o2 of rows o3..o3 + lny of row
// length lw at o0, in buffer (flags & 3) (0 U, 1 V, 2 C); squared with flags bit 2; into
// part[o4 + slot].
@compute @workgroup_size(WG)
fn sums(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
        @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    let a = P.o1 + g.x;
    if (a < P.o2 && g.y < P.lny) {
        let k = P.o0 + a + P.lw * (P.o3 + g.y);
        var x: real;
        switch (P.flags & 3u) {
            case 0u: {
                x = U[k];
            }
            case 1u: {
                x = V[k];
            }
            default: {
                x = C[k];
            }
        }
        s = select(x, x * x, (P.flags & 4u) != 0u);
    }
    put_part(P.o4 + slot(wid), s, l.x);
}

// Partial maxima of |x| over a region, as `sums` (the same block), into part[o4 + slot].
@compute @workgroup_size(WG)
fn maxima(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
          @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    let a = P.o1 + g.x;
    if (a < P.o2 && g.y < P.lny) {
        let k = P.o0 + a + P.lw * (P.o3 + g.y);
        if ((P.flags & 3u) == 0u) {
            s = abs(U[k]);
        } else {
            s = abs(V[k]);
        }
    }
    let m = wg_max(s, l.x, WG);
    if (l.x == 0u) {
        part[P.o4 + slot(wid)] = m;
    }
}

// The largest v over a workgroup of `n` threads (a power of two, at most RW), in a fixed tree
// order (`wg_sum`'s with max).
fn wg_max(v: real, lid: u32, n: u32) -> real {
    red[lid] = v;
    workgroupBarrier();
    for (var w = n / 2u; w > 0u; w = w / 2u) {
        if (lid < w) {
            red[lid] = max(red[lid], red[lid + w]);
        }
        workgroupBarrier();
    }
    let s = red[0];
    workgroupBarrier();
    return s;
}

// One workgroup: sc[9] = the largest of part[o0 .. o0 + o1) (the fastest face, for the step's
// CFL limit).
@compute @workgroup_size(RW)
fn fastest(@builtin(local_invocation_id) l: vec3<u32>) {
    var m: real = 0.0;
    for (var k = l.x; k < P.o1; k = k + RW) {
        m = max(m, part[P.o0 + k]);
    }
    let most = wg_max(m, l.x, RW);
    if (l.x == 0u) {
        sc[9] = most;
    }
}

// One workgroup: a = Σ part[o0 .. o0 + o1), b = Σ part[o2 .. o2 + o3); r0 the cell area.
// Mode (flags): 0 the kinetic energy (sc[7] = ½(a + b)·dA); 1 a stage's book (sc[id] += sc[7] −
// now, sc[7] = now); 2 the smoke before advection (sc[8] = a·dA); 3 after it (sc[6] += a·dA −
// sc[8]); 4 injected (sc[5] += a).
@compute @workgroup_size(RW)
fn book(@builtin(local_invocation_id) l: vec3<u32>) {
    let a = sum_parts(P.o0, P.o1, l.x);
    let b = sum_parts(P.o2, P.o3, l.x);
    if (l.x != 0u) {
        return;
    }
    let dx = P.r1;
    switch P.flags {
        case 0u: {
            sc[7] = 0.5 * (a + b) * dx * dx;
        }
        case 1u: {
            let now = 0.5 * (a + b) * dx * dx;
            sc[P.id] = sc[P.id] + (sc[7] - now);
            sc[7] = now;
        }
        case 2u: {
            sc[8] = a * dx * dx;
        }
        case 3u: {
            sc[6] = sc[6] + (a * dx * dx - sc[8]);
        }
        default: {
            sc[5] = sc[5] + a;
        }
    }
}

// The first node (by index) whose value is not finite, of u, v, density and temperature
// (flags[o7 + 0..4]): over rows of the widest layout. A kinetic energy past the range (finite
// velocities whose squares are not: the CPU's test) counts as u's node 0.
@compute @workgroup_size(WG)
fn check(@builtin(global_invocation_id) g: vec3<u32>) {
    let a = g.x;
    let b = g.y;
    let wu = P.nx + 1u;
    let wv = P.nx + 2u;
    if (a == 0u && b == 0u && bad(sc[7])) {
        atomicMin(&flags[P.o7], 0u);
    }
    if (a < wu && b < P.ny + 2u && bad(U[a + wu * b])) {
        atomicMin(&flags[P.o7], a + wu * b);
    }
    if (a < wv && b <= P.ny && bad(V[a + wv * b])) {
        atomicMin(&flags[P.o7 + 1u], a + wv * b);
    }
    if (a < P.nx && b < P.ny) {
        let c = a + P.nx * b;
        if (bad(C[c])) {
            atomicMin(&flags[P.o7 + 2u], c);
        }
        if (bad(C[P.nx * P.ny + c])) {
            atomicMin(&flags[P.o7 + 3u], c);
        }
    }
}

// ---- tracers (`move_tracers`, `seed`). u64 values as vec2<u32> (low, high): WGSL has no 64-bit
// integers, and the re-seeding hash is the CPU's splitmix64, so that a tracer that leaves lands
// where the CPU's does.

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// a >> s for 0 < s < 32.
fn shr64(a: vec2<u32>, s: u32) -> vec2<u32> {
    return vec2<u32>((a.x >> s) | (a.y << (32u - s)), a.y >> s);
}

// The full 64-bit product of two u32, in 16-bit halves.
fn mul32(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let mid = p01 + p10;
    let mid_carry = select(0u, 1u, mid < p01);
    let lo = p00 + (mid << 16u);
    let carry = select(0u, 1u, lo < p00);
    return vec2<u32>(lo, a1 * b1 + (mid >> 16u) + (mid_carry << 16u) + carry);
}

// a·b mod 2⁶⁴.
fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let p = mul32(a.x, b.x);
    return vec2<u32>(p.x, p.y + a.x * b.y + a.y * b.x);
}

// splitmix64 (`fluid::hash`).
fn mix(z0: vec2<u32>) -> vec2<u32> {
    var z = add64(z0, vec2<u32>(0x7F4A7C15u, 0x9E3779B9u));
    z = mul64(z ^ shr64(z, 30u), vec2<u32>(0x1CE4E5B9u, 0xBF58476Du));
    z = mul64(z ^ shr64(z, 27u), vec2<u32>(0x133111EBu, 0x94D049BBu));
    return z ^ shr64(z, 31u);
}

// a mod m (m > 0), by long division a bit at a time.
fn mod64(a: vec2<u32>, m: u32) -> u32 {
    var r = 0u;
    for (var k = 0u; k < 64u; k = k + 1u) {
        var bit: u32;
        if (k < 32u) {
            bit = (a.y >> (31u - k)) & 1u;
        } else {
            bit = (a.x >> (63u - k)) & 1u;
        }
        var r2 = (r << 1u) | bit;
        if ((r >> 31u) != 0u || r2 >= m) {
            r2 = r2 - m;
        }
        r = r2;
    }
    return r;
}

// (h >> 11) / 2⁵³ (`fluid::unit`): exact in f64.
fn unit(h: vec2<u32>) -> real {
    let s = shr64(h, 11u);
    return (real(s.y) * 4294967296.0 + real(s.x)) / 9007199254740992.0;
}

// Where tracer k re-enters at a step (`StableFluid::seed`): a hash of both picks a cell of the
// first source (`o0` of them; none: any cell) and a point in it, up to 64 tries for a fluid
// cell. The fluid mask at o6.
fn seed(k: u32, step: vec2<u32>) -> vec2<real> {
    let dx = P.r1;
    var h = mix(vec2<u32>(k, 0u) ^ mix(step));
    var pick = vec2<real>(0.5 * dx, 0.5 * dx);
    for (var t = 0u; t < 64u; t = t + 1u) {
        var c: u32;
        if (P.o0 > 0u) {
            c = seeds[mod64(h, P.o0)];
        } else {
            c = mod64(h, P.nx * P.ny);
        }
        let h1 = mix(h ^ vec2<u32>(1u, 0u));
        let h2 = mix(h ^ vec2<u32>(2u, 0u));
        pick = vec2<real>((real(c % P.nx) + unit(h1)) * dx, (real(c / P.nx) + unit(h2)) * dx);
        if (C[P.o6 + c] > 0.0) {
            break;
        }
        h = mix(h);
    }
    return pick;
}

// Each tracer moved by RK2 through the velocity; one that leaves the domain or enters a solid
// is re-seeded. Block: the advection's reals (r0 dt, r1 dx, r2 1/dx, r4, r5 the extent); o0 the
// seeds, o1 the tracers, o6 the fluid mask, o7 the step counter's place in `flags`.
@compute @workgroup_size(WG)
fn tracers(@builtin(global_invocation_id) g: vec3<u32>) {
    let k = g.x + 65535u * WG * g.y;
    if (k >= P.o1) {
        return;
    }
    let x = TR[2u * k];
    let y = TR[2u * k + 1u];
    let dt = P.r0;
    let a = vel_at(x, y);
    let xm = cl(x + 0.5 * dt * a.x, 0.0, P.r4);
    let ym = cl(y + 0.5 * dt * a.y, 0.0, P.r5);
    let b = vel_at(xm, ym);
    var xn = x + dt * b.x;
    var yn = y + dt * b.y;
    var ok = xn >= 0.0 && yn >= 0.0 && xn < P.r4 && yn < P.r5;
    if (ok) {
        let i = min(u32(xn * P.r2), P.nx - 1u);
        let j = min(u32(yn * P.r2), P.ny - 1u);
        ok = C[P.o6 + i + P.nx * j] > 0.0;
    }
    if (!ok) {
        let step = vec2<u32>(atomicLoad(&flags[P.o7]), atomicLoad(&flags[P.o7 + 1u]));
        let p = seed(k, step);
        xn = p.x;
        yn = p.y;
    }
    TR[2u * k] = xn;
    TR[2u * k + 1u] = yn;
}

// The step counter (at flags[o7], low then high) counts one more step (after `tracers`).
@compute @workgroup_size(1)
fn count_step() {
    let lo = atomicLoad(&flags[P.o7]) + 1u;
    atomicStore(&flags[P.o7], lo);
    if (lo == 0u) {
        atomicStore(&flags[P.o7 + 1u], atomicLoad(&flags[P.o7 + 1u]) + 1u);
    }
}
