use super::*;

#[test]
fn the_restitution_map_inverts_for_both_laws() {
    for law in [Law::Linear, Law::Hertz] {
        for &e in &[0.05, 0.1, 0.3, 0.5, 0.8, 0.95, 1.0] {
            let z = damping_ratio(law, e);
            let back = match law {
                Law::Linear => restitution_linear(z),
                Law::Hertz => restitution_hertz(z),
            };
            assert!((back - e).abs() < 1e-9, "{law:?} e={e}: zeta={z} gives {back}");
        }
    }
    // Undamped: exactly elastic; the unclamped textbook map ζ = −ln e/√(π² + ln² e) is not
    // this model's (the clamp lets go early), so the two must differ at strong damping.
    assert_eq!(restitution_linear(0.0), 1.0);
    let e: Real = 0.3;
    let textbook = -e.ln() / (std::f64::consts::PI.powi(2) + e.ln().powi(2)).sqrt();
    assert!((damping_ratio(Law::Linear, e) - textbook).abs() > 1e-3);
}

/// A pile of `n` grains with random radii, some pinned, some overlapping, moving at random;
/// unequal masses unless `uniform`.
fn pile<V: Vector>(n: usize, uniform: bool, seed: u64) -> (Vec<V>, Vec<V>, Model) {
    let mut state = seed;
    let mut rnd = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as Real / (1u64 << 53) as Real
    };
    let side = (n as Real).powf(1.0 / V::DIM as Real) * 2.0e-3;
    let (mut x, mut v, mut mass, mut inv, mut r) = (vec![], vec![], vec![], vec![], vec![]);
    for _ in 0..n {
        let c: Vec<Real> = (0..V::DIM).map(|_| rnd() * side).collect();
        let u: Vec<Real> = (0..V::DIM).map(|_| rnd() - 0.5).collect();
        x.push(V::from_slice(&c));
        v.push(V::from_slice(&u) * 0.3);
        let ri = if uniform { 1e-3 } else { 1e-3 * (0.8 + 0.4 * rnd()) };
        let m = if uniform { 1e-3 } else { 1e-3 * (ri / 1e-3).powi(V::DIM as i32) };
        r.push(ri);
        mass.push(m);
        inv.push(if rnd() < 0.05 { 0.0 } else { 1.0 / m });
    }
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert("radius", r);
    (x, v, Model { mass, inv_mass: inv, attributes })
}

/// Semi-implicit Euler steps of `c` alone under gravity; the forces and torques of every step.
fn run<V: Vector>(c: &mut Contacts<V>, x: &mut [V], v: &mut [V], model: &Model, dt: Real, steps: usize) -> Vec<Real> {
    let mut out = Vec::new();
    let mut f = vec![V::ZERO; x.len()];
    let mut g = [0.0; 3];
    g[V::DIM - 1] = -9.81;
    let g = V::from_slice(&g);
    for _ in 0..steps {
        c.begin_step(dt);
        c.add_forces(x, v, model, &mut f, Write::Overwrite);
        for i in 0..x.len() {
            if model.inv_mass[i] != 0.0 {
                v[i] += (f[i] * model.inv_mass[i] + g) * dt;
                x[i] += v[i] * dt;
            }
            out.extend((0..V::DIM).map(|k| f[i].comp(k)));
        }
        c.end_step(x, v, model, dt);
        let mut t = Vec::new();
        c.torque.iter().for_each(|&w| push_axial::<V>(&mut t, w));
        out.extend(t);
    }
    c.settle(x, v, model);
    out.extend(c.dissipated);
    out
}

fn lanes_match_the_loop<V: Vector>() {
    for law in [Law::Linear, Law::Hertz] {
        for uniform in [true, false] {
            let e = 0.5;
            let ratio: Real = 2.0 / 7.0;
            let material = Material {
                law,
                stiffness: if law == Law::Linear { 1e3 } else { 1e6 },
                tangential_ratio: ratio,
                restitution: e,
                zeta: damping_ratio(law, e),
                friction: 0.3,
                inertia_factor: 0.5,
                tangential_damping: if law == Law::Linear { ratio.sqrt() } else { (1.5 * ratio).sqrt() },
                rolling_friction: 0.0,
                rolling_damping: 0.0,
            };
            let mut normal = [0.0; 3];
            normal[V::DIM - 1] = 1.0;
            let wall =
                Wall { point: V::ZERO, normal: V::from_slice(&normal), zeta: damping_ratio(law, 0.7), friction: 0.4 };
            let (x0, v0, model) = pile::<V>(300, uniform, 7);
            let mut reference = None;
            let paths =
                std::iter::once(PairPath::Loop).chain(simd::Level::available().into_iter().map(PairPath::Lanes));
            for path in paths {
                let mut c = Contacts::new("c".into(), material, vec![wall]);
                c.path = path;
                let (mut x, mut v) = (x0.clone(), v0.clone());
                let out = run(&mut c, &mut x, &mut v, &model, 2e-5, 60);
                assert!(c.count() > 0 && out.iter().all(|a| a.is_finite()));
                let bits: Vec<u64> = x.iter().flat_map(|p| (0..V::DIM).map(|k| p.comp(k).to_bits())).collect();
                // Positions, and every step's forces and torques (not the books: `dissipated`).
                let got = (bits, out[..out.len() - 2].iter().map(|a| a.to_bits()).collect::<Vec<_>>());
                match &reference {
                    None => reference = Some(got),
                    Some(r) => {
                        let what = format!("{}D {law:?} uniform={uniform}, {path:?}", V::DIM);
                        assert!(r.0 == got.0, "{what}: positions differ from the scalar loop's");
                        assert!(r.1 == got.1, "{what}: forces or torques differ from the scalar loop's");
                    }
                }
            }
        }
    }
}

#[test]
fn lanes_match_the_scalar_pair_pass() {
    // Same bits (positions, every step's forces and torques) as the branchy loop, at every
    // level this CPU has; the books only to round-off (the lanes sum in another order).
    lanes_match_the_loop::<glam::DVec2>();
    lanes_match_the_loop::<glam::DVec3>();
}

/// A disc rolling without slipping on a floor at v0 with rolling resistance μ_r (Ai et al.
/// model C) spends its kinetic energy ½(1 + β) m v² at the rate μ_r r m g · v/r: it stops
/// after (1 + β) v0²/(2 μ_r g), to the lever's δ/r (1e-3 here) and the spring's give; the
/// friction book takes its kinetic energy.
#[test]
fn a_disc_rolling_on_a_floor_stops_where_its_rolling_friction_says() {
    let (m, r, k, mu_r, v0, g) = (0.01, 0.01, 1e4, 0.1, 0.5, 9.81);
    let ratio: Real = 1.0 / 3.0;
    let material = Material {
        law: Law::Linear,
        stiffness: k,
        tangential_ratio: ratio,
        restitution: 0.5,
        zeta: damping_ratio(Law::Linear, 0.5),
        friction: 0.5,
        inertia_factor: 0.5,
        tangential_damping: ratio.sqrt(),
        rolling_friction: mu_r,
        rolling_damping: 0.3,
    };
    let floor =
        Wall { point: glam::DVec2::ZERO, normal: glam::DVec2::Y, zeta: damping_ratio(Law::Linear, 0.5), friction: 0.5 };
    let d0 = m * g / k;
    let mut x = vec![glam::DVec2::new(0.0, r - d0)];
    let mut v = vec![glam::DVec2::new(v0, 0.0)];
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert("radius", vec![r]);
    let model = Model { mass: vec![m], inv_mass: vec![1.0 / m], attributes };
    let mut c = Contacts::new("c".into(), material, vec![floor]);
    c.fit(1);
    c.omega[0] = -v0 / (r - 0.5 * d0);
    let ke0 = 0.5 * m * v0 * v0 + 0.5 * 0.5 * m * r * r * c.omega[0] * c.omega[0];
    let dt = std::f64::consts::PI * (m / k).sqrt() / STEPS_PER_CONTACT;
    let out = run(&mut c, &mut x, &mut v, &model, dt, (1.2 / dt) as usize);
    assert!(out.iter().all(|a| a.is_finite()));
    let want = 1.5 * v0 * v0 / (2.0 * mu_r * g);
    assert!((x[0].x - want).abs() < 2e-3 * want, "stopped at {} m, want {want} m", x[0].x);
    assert!(v[0].length() < 1e-3 * v0 && c.omega[0].abs() * r < 1e-3 * v0);
    // What it lost is booked as friction (less what the springs at rest still store).
    assert!((c.dissipated[1] - ke0).abs() < 1e-6 * ke0, "friction book {} J, kinetic {ke0} J", c.dissipated[1]);
}

#[test]
fn axial_components_round_trip() {
    let mut b = Vec::new();
    push_axial::<glam::DVec2>(&mut b, 2.5);
    assert_eq!(b, vec![2.5]);
    b.clear();
    push_axial::<glam::DVec3>(&mut b, glam::DVec3::new(1.0, -2.0, 3.0));
    assert_eq!(b, vec![1.0, -2.0, 3.0]);
}

/// Issue 44 items 1–2: a term that never stepped holds no per-particle state, and its
/// history (for 0 particles) loads into a scene of any size; a snapshot holding a diverged
/// spin is refused from outside but restores as it was, and `non_finite` names the grain.
#[test]
fn an_unstepped_history_loads_and_a_diverged_snapshot_restores() {
    let e = 0.5;
    let material = Material {
        law: Law::Linear,
        stiffness: 1e3,
        tangential_ratio: 2.0 / 7.0,
        restitution: e,
        zeta: damping_ratio(Law::Linear, e),
        friction: 0.3,
        inertia_factor: 0.5,
        tangential_damping: Real::sqrt(2.0 / 7.0),
        rolling_friction: 0.0,
        rolling_damping: 0.0,
    };
    let mut c = Contacts::<glam::DVec2>::new("grains".into(), material, Vec::new());
    let fresh = c.history();
    assert_eq!(fresh, vec![0.0, 0.0, 0.0]);
    c.set_history(&fresh, 5).unwrap();
    assert_eq!(c.history(), fresh);
    assert!(c.set_history(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 5).is_err());
    c.fit(3);
    assert_eq!(c.non_finite(), None);
    c.omega[1] = Real::NAN;
    c.dissipated[0] = Real::INFINITY;
    assert_eq!(c.non_finite(), Some(1));
    assert!(!c.books_finite());
    let diverged = c.history();
    assert!(c.set_history(&diverged, 3).is_err());
    c.fit(0);
    c.restore_history(&diverged, 3);
    assert!(c.omega[1].is_nan() && c.dissipated[0] == Real::INFINITY && c.omega.len() == 3);
}
