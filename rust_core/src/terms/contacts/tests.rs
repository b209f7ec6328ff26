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
            let plane = HalfSpace::new(V::ZERO, V::from_slice(&normal)).unwrap();
            let wall = Wall { shape: plane.into(), zeta: damping_ratio(law, 0.7), friction: 0.4 };
            let (x0, v0, model) = pile::<V>(300, uniform, 7);
            let mut reference = None;
            let paths =
                std::iter::once(PairPath::Loop).chain(simd::Level::available().into_iter().map(PairPath::Lanes));
            for path in paths {
                let mut c = Contacts::new("c".into(), material, vec![wall.clone()]);
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
    let plane = HalfSpace::new(glam::DVec2::ZERO, glam::DVec2::Y).unwrap();
    let floor = Wall { shape: plane.into(), zeta: damping_ratio(Law::Linear, 0.5), friction: 0.5 };
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
    let fresh = c.history().unwrap();
    assert_eq!(fresh, vec![0.0, 0.0, 0.0]);
    c.set_history(&fresh, 5).unwrap();
    assert_eq!(c.history().unwrap(), fresh);
    assert!(c.set_history(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 5).is_err());
    c.fit(3);
    assert_eq!(c.non_finite(), None);
    c.omega[1] = Real::NAN;
    c.dissipated[0] = Real::INFINITY;
    assert_eq!(c.non_finite(), Some(1));
    assert!(!c.books_finite());
    let diverged = c.history().unwrap();
    assert!(c.set_history(&diverged, 3).is_err());
    c.fit(0);
    c.restore_history(&diverged, 3);
    assert!(c.omega[1].is_nan() && c.dissipated[0] == Real::INFINITY && c.omega.len() == 3);
}

fn linear(e: Real, mu: Real) -> Material {
    let ratio: Real = 1.0 / 3.0;
    Material {
        law: Law::Linear,
        stiffness: 1e4,
        tangential_ratio: ratio,
        restitution: e,
        zeta: damping_ratio(Law::Linear, e),
        friction: mu,
        inertia_factor: 0.5,
        tangential_damping: ratio.sqrt(),
        rolling_friction: 0.0,
        rolling_damping: 0.0,
    }
}

/// A disc of radius r dropped onto each shape (and into a bowl) comes to rest touching it at
/// the linear law's overlap, straight above where it fell: the shape's top, plus r − δ. The
/// overlap at rest is m g/k (1 + hγ) exactly: the dashpot reads the mid-step speed
/// v − h f (h = ½dt/m, `Material::normal`), which at rest is −h f, not 0; at a 50th of a
/// contact hγ = ζπ/50, 3 % here (ζ = 0.49 for e = 0.3).
#[test]
fn a_grain_rests_on_every_wall_shape_at_the_linear_overlap() {
    use glam::DVec2;
    let (m, r, k, g) = (0.01, 0.01, 1e4, 9.81);
    let top = 0.1;
    let cases: Vec<(&str, AnyShape<DVec2>)> = vec![
        ("plane", HalfSpace::new(DVec2::new(0.0, top), DVec2::Y).unwrap().into()),
        ("ball", Ball::new(DVec2::new(0.0, top - 0.05), 0.05, false).unwrap().into()),
        ("bowl", Ball::new(DVec2::new(0.0, top + 0.05), 0.05, true).unwrap().into()),
        ("capsule", Capsule::new(DVec2::new(-0.05, top - 0.02), DVec2::new(0.05, top - 0.02), 0.02).unwrap().into()),
        ("oriented box", OrientedBox::new(DVec2::new(0.0, top - 0.03), DVec2::new(0.05, 0.03), 0.0).unwrap().into()),
    ];
    for (what, shape) in cases {
        let wall = Wall { shape, zeta: damping_ratio(Law::Linear, 0.3), friction: 0.5 };
        let mut c = Contacts::new("c".into(), linear(0.3, 0.5), vec![wall]);
        let mut x = vec![DVec2::new(0.0, top + r + 0.005)];
        let mut v = vec![DVec2::ZERO];
        let mut attributes = std::collections::BTreeMap::new();
        attributes.insert("radius", vec![r]);
        let model = Model { mass: vec![m], inv_mass: vec![1.0 / m], attributes };
        let dt = std::f64::consts::PI * (m / k).sqrt() / STEPS_PER_CONTACT;
        let out = run(&mut c, &mut x, &mut v, &model, dt, (0.5 / dt) as usize);
        assert!(out.iter().all(|a| a.is_finite()), "{what}");
        let hg = 0.5 * dt / m * 2.0 * damping_ratio(Law::Linear, 0.3) * (k * m).sqrt();
        let overlap = top + r - x[0].y;
        let want = m * g / k * (1.0 + hg);
        assert!((overlap - want).abs() < 1e-6 * want, "{what}: overlap {overlap} m, want {want} m");
        assert!((overlap / (m * g / k) - 1.0).abs() < 0.04, "{what}: overlap {overlap} m against m g/k");
        assert!(x[0].x.abs() < 1e-12 && v[0].length() < 1e-6, "{what}: {:?} {:?}", x[0], v[0]);
        assert_eq!(c.count(), 1, "{what}");
    }
}

/// The walls from the term's parameters: each shape's numbers in order, refused naming "walls"
/// and the wall (wrong count, unknown shape, non-finite, out of range).
#[test]
fn walls_from_parameters_are_checked_and_named() {
    use crate::terms::registry::Value;
    use glam::{DVec2, DVec3};
    let params = |kinds: &str, p: Vec<Real>, w: usize| {
        Params::new()
            .with("wall_kinds", Value::Text(kinds.into()))
            .with("wall_params", Value::Floats(p))
            .with("wall_restitution", Value::Floats(vec![0.5; w]))
            .with("wall_friction", Value::Floats(vec![0.2; w]))
    };
    let p = vec![0.0, 0.0, 0.0, 2.0, 1.0, 1.0, 0.5, 1.0, 0.0, 0.0, 1.0, 0.0, 0.1, 0.0, 0.0, 1.0, 0.5, 0.3];
    let w = walls::<DVec2>(&mut params("plane,sphere,capsule,oriented_box", p, 4), Law::Linear).unwrap();
    assert_eq!(w[0].shape, AnyShape::from(HalfSpace::new(DVec2::ZERO, DVec2::Y).unwrap()));
    assert_eq!(w[1].shape, AnyShape::from(Ball::new(DVec2::new(1.0, 1.0), 0.5, true).unwrap()));
    assert_eq!(w[2].shape, AnyShape::from(Capsule::new(DVec2::ZERO, DVec2::new(1.0, 0.0), 0.1).unwrap()));
    let ob = OrientedBox::new(DVec2::ZERO, DVec2::new(1.0, 0.5), 0.3).unwrap();
    assert_eq!(w[3].shape, AnyShape::from(ob));
    let p3 = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.1, 0.2, 0.3];
    let w3 = walls::<DVec3>(&mut params("oriented_box", p3, 1), Law::Linear).unwrap();
    assert_eq!(
        w3[0].shape,
        AnyShape::from(OrientedBox::new(DVec3::ZERO, DVec3::ONE, DVec3::new(0.1, 0.2, 0.3)).unwrap())
    );
    assert!(walls::<DVec2>(&mut params("", vec![], 0), Law::Linear).unwrap().is_empty());
    let refused = |kinds: &str, p: Vec<Real>, w: usize| match walls::<DVec2>(&mut params(kinds, p, w), Law::Linear) {
        Err(crate::Error::InvalidInput { arg, msg }) => {
            assert_eq!(arg, "walls", "{msg}");
            msg
        }
        other => panic!("{kinds}: expected InvalidInput, got {other:?}"),
    };
    assert!(refused("cone", vec![0.0; 4], 1).contains("unknown shape"));
    assert!(refused("sphere", vec![0.0, 0.0, 1.0], 1).contains("too few"));
    assert!(refused("sphere", vec![0.0, 0.0, 1.0, 0.0, 9.0], 1).contains("that take 4"));
    assert!(refused("sphere", vec![f64::NAN, 0.0, 1.0, 0.0], 1).contains("wall 0 (sphere)"));
    assert!(refused("sphere", vec![0.0, 0.0, -1.0, 0.0], 1).contains("radius"));
    assert!(refused("sphere", vec![0.0, 0.0, 1.0, 0.5], 1).contains("inside"));
    assert!(refused("plane,plane", vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], 2).contains("wall 1 (plane): normal"));
    assert!(refused("capsule", vec![0.0; 4], 1).contains("too few"));
    assert!(refused("oriented_box", vec![0.0, 0.0, 1.0, -1.0, 0.0], 1).contains("half_extents"));
    assert!(refused("plane", vec![0.0, 0.0, 0.0, 1.0], 2).contains("one entry per wall"));
}

/// The passes' loop for any shape gives a plane wall the bits of the loop for planes alone:
/// a pile on a floor, with and without a ball far away (which then sends every wall through
/// the loop for any shape), the same positions, forces, torques and books, bit for bit.
#[test]
fn a_plane_wall_has_the_same_bits_beside_any_shape() {
    fn check<V: Vector>() {
        let mut normal = [0.0; 3];
        normal[V::DIM - 1] = 1.0;
        let floor = Wall {
            shape: HalfSpace::new(V::ZERO, V::from_slice(&normal[..V::DIM])).unwrap().into(),
            zeta: damping_ratio(Law::Linear, 0.7),
            friction: 0.4,
        };
        let far = Wall {
            shape: Ball::new(V::from_slice(&[1e3; 3][..V::DIM]), 1.0, false).unwrap().into(),
            zeta: damping_ratio(Law::Linear, 0.5),
            friction: 0.2,
        };
        let (x0, v0, model) = pile::<V>(300, false, 11);
        let mut material = linear(0.5, 0.3);
        material.rolling_friction = 0.2;
        material.rolling_damping = 0.3;
        let mut runs = Vec::new();
        for walls in [vec![floor.clone()], vec![floor.clone(), far.clone()]] {
            let mut c = Contacts::new("c".into(), material, walls);
            let (mut x, mut v) = (x0.clone(), v0.clone());
            let out = run(&mut c, &mut x, &mut v, &model, 2e-5, 80);
            assert!(c.last.walls > 0, "{}D: no grain on the floor", V::DIM);
            let bits: Vec<u64> = x.iter().flat_map(|p| (0..V::DIM).map(|k| p.comp(k).to_bits())).collect();
            runs.push((bits, out.iter().map(|a| a.to_bits()).collect::<Vec<_>>()));
        }
        assert!(runs[0] == runs[1], "{}D: the loop for any shape changed a plane's bits", V::DIM);
    }
    check::<glam::DVec2>();
    check::<glam::DVec3>();
}
