// The stable fluid's solves on the device: the CPU's `grids::poisson` (preconditioned conjugate
// gradients, with one multigrid V-cycle of damped Jacobi sweeps (MGPCG: McAdams, Sifakis &
// Teran, SCA 2010) for the pressure, the diagonal for viscosity), on padded arrays of one buffer
// `S` at offsets the host gives. The stencils' coefficients (east and north links, the scaled
// diagonal and its inverse, per level) are the CPU's, built on the host.
//
// No read-back per iteration: the control kernels (one workgroup) reduce the partial sums in a
// fixed order, take the CG scalars and the stopping test as the CPU does, and once a solve is
// done set the counts of its indirect dispatches to zero, so the iterations recorded past the
// end cost next to nothing. The host reads a solve's ints once per budget of iterations.

@group(0) @binding(3) var<storage, read_write> S: array<real>;
// Per solver s, at 16·s: [0] done, [1] iterations, [2] iterations since the residual last fell
// by 10 %, [3] converged, [4] x to be zeroed (b = 0), [5] the most iterations.
@group(0) @binding(4) var<storage, read_write> I: array<u32>;
// The indirect dispatches' counts (3 per level of each solver) and their templates, at offsets
// the host gives. Bound only by the control kernels (a buffer read by an indirect dispatch
// cannot be bound for writing in it): the vector kernels are compiled from this same source
// against a layout without I and IND, which they do not use.
@group(0) @binding(5) var<storage, read_write> IND: array<u32>;

// Damped-Jacobi weight, sweeps (the CPU's OMEGA; poisson.rs).
const OMEGA: real = 0.8;
// Iterations without the residual falling by 10 % after which a solve gives up (STALLED).
const STALLED: u32 = 100u;

// Level kernels: lw the padded width, lnx × lny the unknowns; o0 east links, o1 north links,
// o2 the scaled diagonal, o3 its inverse, r0 the scale.
fn at(i: u32, j: u32) -> u32 {
    return (i + 1u) + P.lw * (j + 1u);
}

// (A x)_c, x at offset `x`.
fn ax(x: u32, c: u32) -> real {
    let w = P.lw;
    return S[P.o2 + c] * S[x + c]
        - P.r0 * (S[P.o0 + c] * S[x + c + 1u] + S[P.o0 + c - 1u] * S[x + c - 1u] + S[P.o1 + c] * S[x + c + w]
            + S[P.o1 + c - w] * S[x + c - w]);
}

// out (o6) = A x (o4); partial sums of out·x.
@compute @workgroup_size(WG)
fn apply(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
         @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        let o = ax(P.o4, c);
        S[P.o6 + c] = o;
        s = o * S[P.o4 + c];
    }
    put_part(slot(wid), s, l.x);
}

// out (o6) = b (o5) − A x (o4); partial sums of |out|².
@compute @workgroup_size(WG)
fn residual(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
            @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        let o = S[P.o5 + c] - ax(P.o4, c);
        S[P.o6 + c] = o;
        s = o * o;
    }
    put_part(slot(wid), s, l.x);
}

// |b|² partial sums (b at o5).
@compute @workgroup_size(WG)
fn norm(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
        @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let b = S[P.o5 + at(g.x, g.y)];
        s = b * b;
    }
    put_part(slot(wid), s, l.x);
}

// One damped-Jacobi sweep from x (o4) into out (o6) for b (o5): out = x + ω D⁻¹ (b − A x), or
// from x = 0 (flags bit 0): out = ω D⁻¹ b. Flags bit 1: partial sums of out·b.
@compute @workgroup_size(WG)
fn jacobi(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
          @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        let b = S[P.o5 + c];
        var o: real;
        if ((P.flags & 1u) != 0u) {
            o = OMEGA * S[P.o3 + c] * b;
        } else {
            o = S[P.o4 + c] + OMEGA * S[P.o3 + c] * (b - ax(P.o4, c));
        }
        S[P.o6 + c] = o;
        s = o * b;
    }
    if ((P.flags & 2u) != 0u) {
        put_part(slot(wid), s, l.x);
    }
}

// The coarsest level's sweeps in one workgroup (its unknowns are few: a side of at most 4 and
// at most `COARSE_MOST` in all): `P.id` damped-Jacobi sweeps from x = 0 alternating between x
// (o4) and tmp (o6), which leaves the result in x for an even count; the workgroup's threads
// take the unknowns in turn, a barrier on storage between sweeps. The CPU's arithmetic per
// value (`jacobi` above), in one dispatch instead of one per sweep.
@compute @workgroup_size(RW)
fn coarsest(@builtin(local_invocation_id) l: vec3<u32>) {
    let n = P.lnx * P.lny;
    for (var k = 0u; k < P.id; k = k + 1u) {
        let from_x = k % 2u == 0u;
        for (var q = l.x; q < n; q = q + RW) {
            let c = at(q % P.lnx, q / P.lnx);
            let b = S[P.o5 + c];
            var o: real;
            if (k == 0u) {
                o = OMEGA * S[P.o3 + c] * b;
            } else if (from_x) {
                o = S[P.o4 + c] + OMEGA * S[P.o3 + c] * (b - ax(P.o4, c));
            } else {
                o = S[P.o6 + c] + OMEGA * S[P.o3 + c] * (b - ax(P.o6, c));
            }
            if (from_x) {
                S[P.o6 + c] = o;
            } else {
                S[P.o4 + c] = o;
            }
        }
        storageBarrier();
    }
}

// The coarse right-hand side (o6; coarse padded width o7, coarse unknowns id & 0xffff by
// id >> 16) as the fine residual b − A x summed over each coarse cell's children, in the CPU's
// order (each row's pair, then the rows). Here nx × ny are the fine level's unknowns, lw its
// padded width, o0..o5 and r0 its coefficients as above. Dispatched over the coarse unknowns.
@compute @workgroup_size(WG)
fn restrict_residual(@builtin(global_invocation_id) g: vec3<u32>) {
    let cnx = P.id & 0xffffu;
    let cny = P.id >> 16u;
    if (g.x >= cnx || g.y >= cny) {
        return;
    }
    var o: real = 0.0;
    let i0 = 2u * g.x;
    for (var jf = 2u * g.y; jf < min(2u * g.y + 2u, P.ny); jf = jf + 1u) {
        let c0 = at(i0, jf);
        let r0 = S[P.o5 + c0] - ax(P.o4, c0);
        if (i0 + 1u < P.nx) {
            let c1 = c0 + 1u;
            o = o + (r0 + (S[P.o5 + c1] - ax(P.o4, c1)));
        } else {
            o = o + r0;
        }
    }
    S[P.o6 + (g.x + 1u) + P.o7 * (g.y + 1u)] = o;
}

// x (o4, fine) += e (o6, coarse padded width o7) at the coarse cell over each fine unknown.
@compute @workgroup_size(WG)
fn prolong(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x >= P.lnx || g.y >= P.lny) {
        return;
    }
    let c = at(g.x, g.y);
    S[P.o4 + c] = S[P.o4 + c] + S[P.o6 + (g.x / 2u + 1u) + P.o7 * (g.y / 2u + 1u)];
}

// CG's update (alpha at sc[r-slot o0]): x (o1) += α p (o2), r (o3) −= α Ap (o4); partial sums
// of |r|². Flags bit 0 (the diagonal preconditioner): also z (o5) = D⁻¹ r (D⁻¹ at o6) and the
// partial sums of z·r after the first ones, at slot + o7.
@compute @workgroup_size(WG)
fn update(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
          @builtin(workgroup_id) wid: vec3<u32>) {
    let alpha = sc[P.o0];
    var rr: real = 0.0;
    var rz: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        S[P.o1 + c] = S[P.o1 + c] + alpha * S[P.o2 + c];
        let r = S[P.o3 + c] - alpha * S[P.o4 + c];
        S[P.o3 + c] = r;
        rr = r * r;
        if ((P.flags & 1u) != 0u) {
            let z = S[P.o6 + c] * r;
            S[P.o5 + c] = z;
            rz = z * r;
        }
    }
    put_part(slot(wid), rr, l.x);
    if ((P.flags & 1u) != 0u) {
        put_part(P.o7 + slot(wid), rz, l.x);
    }
}

// z (o5) = D⁻¹ r (D⁻¹ at o6, r at o3); partial sums of z·r (the diagonal preconditioner's first
// application).
@compute @workgroup_size(WG)
fn diagonal(@builtin(global_invocation_id) g: vec3<u32>, @builtin(local_invocation_id) l: vec3<u32>,
            @builtin(workgroup_id) wid: vec3<u32>) {
    var s: real = 0.0;
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        let r = S[P.o3 + c];
        let z = S[P.o6 + c] * r;
        S[P.o5 + c] = z;
        s = z * r;
    }
    put_part(slot(wid), s, l.x);
}

// p (o2) = z (o5) + β p, β at sc[o0]; with flags bit 0, p = z (the first direction).
@compute @workgroup_size(WG)
fn direction(@builtin(global_invocation_id) g: vec3<u32>) {
    if (g.x < P.lnx && g.y < P.lny) {
        let c = at(g.x, g.y);
        if ((P.flags & 1u) != 0u) {
            S[P.o2 + c] = S[P.o5 + c];
        } else {
            S[P.o2 + c] = S[P.o5 + c] + sc[P.o0] * S[P.o2 + c];
        }
    }
}

// x (o1) = 0 where the solve found b = 0 (its ints' [4]).
@compute @workgroup_size(WG)
fn zero_x(@builtin(global_invocation_id) g: vec3<u32>) {
    if (I[16u * P.id + 4u] != 0u && g.x < P.lnx && g.y < P.lny) {
        S[P.o1 + at(g.x, g.y)] = 0.0;
    }
}

// ---- control: one workgroup of RW threads. A solver's scalars at sc[o0 ..]: +0 |b|, +1 r·r,
// +2 r·z, +3 α, +4 β, +5 the best r·r, +6 the final relative residual, +7 the tolerance. Its
// ints at I[16·id ..]; its live indirect counts at IND[o1 .. o1 + o2), their templates at IND[o3 ..].

var<workgroup> flag_w: u32;

fn done_now(lid: u32) -> bool {
    if (lid == 0u) {
        flag_w = I[16u * P.id];
    }
    return workgroupUniformLoad(&flag_w) != 0u;
}

// Marks the solve done: its indirect dispatches emptied, the final relative residual kept.
fn finish(converged: bool, rr: real) {
    let b = P.o0;
    let base = 16u * P.id;
    I[base] = 1u;
    I[base + 3u] = select(0u, 1u, converged);
    sc[b + 6u] = sqrt(rr) / sc[b];
    for (var k = 0u; k < P.o2; k = k + 1u) {
        IND[P.o1 + k] = 0u;
    }
}

// Before a solve: its state reset and its indirect counts armed; r7 the tolerance, `lnx` the
// most iterations.
@compute @workgroup_size(1)
fn arm() {
    let base = 16u * P.id;
    I[base] = 0u;
    I[base + 1u] = 0u;
    I[base + 2u] = 0u;
    I[base + 3u] = 0u;
    I[base + 4u] = 0u;
    I[base + 5u] = P.lnx;
    sc[P.o0 + 7u] = P.r7;
    for (var k = 0u; k < P.o2; k = k + 1u) {
        IND[P.o1 + k] = IND[P.o3 + k];
    }
}

// |b|² from the partials (count lw): b = 0 gives x = 0, done and converged at 0 iterations.
@compute @workgroup_size(RW)
fn c_norm(@builtin(local_invocation_id) l: vec3<u32>) {
    let bb = sum_parts(0u, P.lw, l.x);
    if (l.x == 0u) {
        sc[P.o0] = sqrt(bb);
        if (bb == 0.0) {
            I[16u * P.id + 4u] = 1u;
            sc[P.o0] = 1.0;
            finish(true, 0.0);
        }
    }
}

// r·r of the first residual: done at 0 iterations if already within the tolerance.
@compute @workgroup_size(RW)
fn c_start(@builtin(local_invocation_id) l: vec3<u32>) {
    if (done_now(l.x)) {
        return;
    }
    let rr = sum_parts(0u, P.lw, l.x);
    if (l.x == 0u) {
        let b = P.o0;
        sc[b + 1u] = rr;
        sc[b + 5u] = rr;
        if (sqrt(rr) <= sc[b + 7u] * sc[b]) {
            finish(true, rr);
        }
    }
}

// r·z of the first preconditioned residual.
@compute @workgroup_size(RW)
fn c_rz(@builtin(local_invocation_id) l: vec3<u32>) {
    if (done_now(l.x)) {
        return;
    }
    let rz = sum_parts(0u, P.lw, l.x);
    if (l.x == 0u) {
        sc[P.o0 + 2u] = rz;
    }
}

// p·Ap → α = r·z / p·Ap, or the end (not converged) where it is not positive and finite.
@compute @workgroup_size(RW)
fn c_alpha(@builtin(local_invocation_id) l: vec3<u32>) {
    if (done_now(l.x)) {
        return;
    }
    let pap = sum_parts(0u, P.lw, l.x);
    if (l.x == 0u) {
        let b = P.o0;
        let base = 16u * P.id;
        I[base + 1u] = I[base + 1u] + 1u;
        let rz = sc[b + 2u];
        if (!(!bad(pap) && pap > 0.0 && !bad(rz))) {
            finish(false, sc[b + 1u]);
        } else {
            sc[b + 3u] = rz / pap;
        }
    }
}

// The new r·r: the CPU's stopping test (tolerance, the most iterations, not finite, stalled).
@compute @workgroup_size(RW)
fn c_rr(@builtin(local_invocation_id) l: vec3<u32>) {
    if (done_now(l.x)) {
        return;
    }
    let rr = sum_parts(0u, P.lw, l.x);
    if (l.x == 0u) {
        let b = P.o0;
        let base = 16u * P.id;
        sc[b + 1u] = rr;
        if (rr < 0.81 * sc[b + 5u]) {
            sc[b + 5u] = rr;
            I[base + 2u] = 0u;
        } else {
            I[base + 2u] = I[base + 2u] + 1u;
        }
        let k = I[base + 1u];
        let tol = sc[b + 7u];
        if (sqrt(rr) <= tol * sc[b] || k == I[base + 5u] || bad(rr) || I[base + 2u] >= STALLED) {
            let r = sqrt(rr) / sc[b];
            finish(r <= tol, rr);
        }
    }
}

// The new r·z (partials from `lw` on at the offset lnx): β = new / old.
@compute @workgroup_size(RW)
fn c_beta(@builtin(local_invocation_id) l: vec3<u32>) {
    if (done_now(l.x)) {
        return;
    }
    let rz = sum_parts(P.lnx, P.lw, l.x);
    if (l.x == 0u) {
        let b = P.o0;
        sc[b + 4u] = rz / sc[b + 2u];
        sc[b + 2u] = rz;
    }
}
