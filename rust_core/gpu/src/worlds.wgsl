// A batch of small worlds fused (appended to particles.wgsl, after `const W: u32 = …;`, by
// `Particles::set_worlds` for worlds of at most 16 particles): thread w steps world w's W
// particles `P.steps` steps with its state in registers, one dispatch for a chunk of steps,
// where the general path takes three dispatches a substep. Pairwise gravity and Coulomb inside
// the world plus the uniform field; no drag, springs or colliders (those take the general path).
// Each operation is the general kernels' (`eval_forces`, `kick_drift`, `kick`) on the same
// values in the same order, so it is the same method; the sums are short, in index order.

// A world's accelerations at positions x (charges q, 1/masses in v.w: 0 pinned).
fn world_acc(x: ptr<function, array<vec4<real>, W>>, v: ptr<function, array<vec4<real>, W>>,
             q: ptr<function, array<real, W>>, a: ptr<function, array<vec3<real>, W>>) {
    for (var i = 0u; i < W; i++) {
        let xi = (*x)[i];
        var s = vec3<real>(0.0, 0.0, 0.0);
        if (P.pair != 0u) {
            for (var j = 0u; j < W; j++) {
                let xj = (*x)[j];
                let d = xj.xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                s += d * (xj.w * inv * inv * inv);
            }
            s *= P.big_g;
        }
        var fc = vec3<real>(0.0, 0.0, 0.0);
        if (P.coul != 0u) {
            for (var j = 0u; j < W; j++) {
                let d = (*x)[j].xyz - xi.xyz;
                let r2 = dot(d, d) + P.eps2c;
                let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
                fc -= d * ((*q)[j] * inv * inv * inv);
            }
            fc *= P.kc * (*q)[i];
        }
        var ai = vec3<real>(0.0, 0.0, 0.0);
        let w = (*v)[i].w;
        if (w != 0.0) {
            ai = s + vec3<real>(P.gx, P.gy, P.gz) + fc * w;
        }
        (*a)[i] = ai;
    }
}

// Velocity Verlet's kick and drift of substep length h (the general `kick_drift`).
fn world_kick_drift(x: ptr<function, array<vec4<real>, W>>, v: ptr<function, array<vec4<real>, W>>,
                    a: ptr<function, array<vec3<real>, W>>, hk: real, h: real) {
    for (var i = 0u; i < W; i++) {
        let vi = (*v)[i];
        if (vi.w != 0.0) {
            let nv = vi.xyz + (*a)[i] * hk;
            (*v)[i] = vec4<real>(nv, vi.w);
            let xi = (*x)[i];
            (*x)[i] = vec4<real>(xi.xyz + nv * h, xi.w);
        }
    }
}

// The second kick (the general `kick`).
fn world_kick(v: ptr<function, array<vec4<real>, W>>, a: ptr<function, array<vec3<real>, W>>, hk: real) {
    for (var i = 0u; i < W; i++) {
        let vi = (*v)[i];
        if (vi.w != 0.0) {
            (*v)[i] = vec4<real>(vi.xyz + (*a)[i] * hk, vi.w);
        }
    }
}

@compute @workgroup_size(64)
fn worlds(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x * W;
    if (b >= P.n) {
        return;
    }
    var x: array<vec4<real>, W>;
    var v: array<vec4<real>, W>;
    var a: array<vec3<real>, W>;
    var q: array<real, W>;
    for (var i = 0u; i < W; i++) {
        x[i] = pos[b + i];
        v[i] = vel[b + i];
        a[i] = acc[b + i].xyz;
        q[i] = 0.0;
        if (P.coul != 0u) {
            q[i] = charge[b + i];
        }
    }
    // P.scheme: 0 semi-implicit Euler, 1 velocity Verlet, 2 Yoshida 4 (substeps h0, h1, h0).
    for (var s = 0u; s < P.steps; s++) {
        if (P.scheme == 0u) {
            world_acc(&x, &v, &q, &a);
            world_kick_drift(&x, &v, &a, P.h_a, P.h_a);
        } else {
            let subs = select(1u, 3u, P.scheme == 2u);
            for (var k = 0u; k < subs; k++) {
                let h = select(P.h_a, P.h_b, k == 1u);
                let hk = 0.5 * h;
                world_kick_drift(&x, &v, &a, hk, h);
                world_acc(&x, &v, &q, &a);
                world_kick(&v, &a, hk);
            }
        }
    }
    for (var i = 0u; i < W; i++) {
        pos[b + i] = x[i];
        vel[b + i] = v[i];
        acc[b + i] = vec4<real>(a[i], 0.0);
    }
}
