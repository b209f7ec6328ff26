// The box's faces of the particle fluids (appended to sph.wgsl and dfsph.wgsl, whose parameter
// blocks both hold `dim`, the corners `lo_*`, `hi_*`, `restitution` and `friction`), as the
// CPU's "box" collider (`constraints::Aabb`): each coordinate past a face is put onto it and,
// where the particle moves outward, its normal velocity becomes −e v_n and its tangential speed
// shrinks by μ (1 + e) v_n (Coulomb friction), to zero at most.
fn box_faces(x: ptr<function, vec3<real>>, v: ptr<function, vec3<real>>) {
    let d = P.dim;
    let lo = vec3<real>(P.lo_x, P.lo_y, P.lo_z);
    let hi = vec3<real>(P.hi_x, P.hi_y, P.hi_z);
    let e = P.restitution;
    let mu = P.friction;
    var xn = *x;
    var vn = *v;
    for (var a = 0u; a < d; a = a + 1u) {
        var out: real = 0.0;
        if (xn[a] < lo[a]) {
            xn[a] = lo[a];
            out = -1.0;
        } else if (xn[a] > hi[a]) {
            xn[a] = hi[a];
            out = 1.0;
        } else {
            continue;
        }
        let un = vn[a] * out;
        if (un > 0.0) {
            let dvn = (1.0 + e) * un;
            vn[a] = vn[a] * -e;
            if (mu > 0.0) {
                var vt2: real = 0.0;
                for (var b = 0u; b < d; b = b + 1u) {
                    if (b != a) {
                        vt2 = vt2 + vn[b] * vn[b];
                    }
                }
                if (vt2 > 0.0) {
                    let vt = sqrt(vt2);
                    let sc = max(vt - mu * dvn, 0.0) / vt;
                    for (var b = 0u; b < d; b = b + 1u) {
                        if (b != a) {
                            vn[b] = vn[b] * sc;
                        }
                    }
                }
            }
        }
    }
    *x = xn;
    *v = vn;
}
