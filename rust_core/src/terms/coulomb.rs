//! The Coulomb force between every pair of charged particles, with Plummer softening, by direct
//! summation on the pairwise-gravity kernel (`super::pairwise_gravity`) with the charges as the
//! source weights and the opposite sign (Griffiths, *Introduction to Electrodynamics*, 4th ed.,
//! eqs. 2.1 and 2.42, softened as Plummer 1911):
//!
//! F_i = k q_i Σ_j q_j (x_i − x_j) / (|x_i − x_j|² + ε²)^{3/2}
//! U   = k Σ_{i<j} q_i q_j / (|x_i − x_j|² + ε²)^{1/2}
//!
//! q is the `charge` attribute (C); a scene without it feels no force and holds no potential, and
//! a particle with charge 0 neither pushes nor is pushed. Pinned particles are sources and feel
//! no force. Both sums are the gravity kernels' (same SIMD levels, the symmetric sum from 1024
//! particles, float32 with a single-precision state, the same bits for any thread count).
use super::pairwise_gravity::Pairwise;
use super::registry::{Context, Params};
use super::Term;
use crate::error::{invalid, Result};
use crate::vector::Vector;

fn build<V: Vector>(name: String, p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let (k, softening) = (p.number("k")?, p.number("softening")?);
    if k <= 0.0 {
        return Err(invalid("k", format!("{k} must be finite and > 0")));
    }
    if softening < 0.0 {
        return Err(invalid("softening", format!("{softening} must be finite and >= 0")));
    }
    Ok(Box::new(Pairwise::coulomb(name, k, softening)))
}
crate::register_term!("coulomb", build);

#[cfg(test)]
mod tests {
    use super::super::Write;
    use super::*;
    use crate::state::Model;
    use glam::{DVec2, DVec3};

    fn model(q: &[f64], pinned: &[bool]) -> Model {
        let n = q.len();
        let mut m = Model {
            mass: vec![2.0; n],
            inv_mass: pinned.iter().map(|&p| if p { 0.0 } else { 0.5 }).collect(),
            ..Default::default()
        };
        m.attributes.insert("charge", q.to_vec());
        m
    }

    #[test]
    fn two_charges_feel_the_analytic_force_and_potential() {
        let (k, eps) = (3.0, 0.25);
        let x = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 2.0, 2.0)]; // r = 3
        for (q1, q2) in [(2.0, 5.0), (2.0, -5.0), (-1.5, -0.5)] {
            let mdl = model(&[q1, q2], &[false, false]);
            let mut t = Pairwise::coulomb("c".into(), k, eps);
            let mut f = [DVec3::ONE; 2];
            Term::<DVec3>::add_forces(&mut t, &x, &x, &mdl, &mut f, Write::Overwrite);
            let d = x[0] - x[1];
            let r2 = d.length_squared() + eps * eps;
            let want = d * (k * q1 * q2 / (r2 * r2.sqrt()));
            assert!((f[0] - want).length() <= 1e-14 * want.length(), "{:?} vs {want}", f[0]);
            assert!((f[1] + want).length() <= 1e-14 * want.length());
            // Like charges push particle 0 away from 1 (along x0 − x1), unlike pull it closer.
            assert_eq!(f[0].dot(d) > 0.0, q1 * q2 > 0.0);
            let u = Term::<DVec3>::potential(&t, &x, &mdl).unwrap();
            let want_u = k * q1 * q2 / r2.sqrt();
            assert!((u - want_u).abs() <= 1e-14 * want_u.abs(), "{u} vs {want_u}");
        }
    }

    #[test]
    fn uncharged_scenes_feel_nothing_and_pinned_charges_only_push() {
        let x = [DVec2::new(0.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(0.0, 1.0)];
        let mut t = Pairwise::coulomb("c".into(), 1.0, 0.0);
        let mut plain = Model { mass: vec![1.0; 3], inv_mass: vec![1.0; 3], ..Default::default() };
        let mut f = [DVec2::ONE; 3];
        Term::<DVec2>::add_forces(&mut t, &x, &x, &plain, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::ZERO; 3]);
        f = [DVec2::ONE; 3];
        Term::<DVec2>::add_forces(&mut t, &x, &x, &plain, &mut f, Write::Add);
        assert_eq!(f, [DVec2::ONE; 3]);
        assert_eq!(Term::<DVec2>::potential(&t, &x, &plain), Some(0.0));
        assert_eq!(Term::<DVec2>::time_scale(&t, &x, &plain), None);
        plain.attributes.insert("charge", vec![1.0, 1.0, 0.0]);
        plain.inv_mass[0] = 0.0; // pinned source
        Term::<DVec2>::add_forces(&mut t, &x, &x, &plain, &mut f, Write::Overwrite);
        assert_eq!(f[0], DVec2::ZERO);
        // Pushed by the pinned charge: k q q / r² = 1 along +x.
        assert!((f[1] - DVec2::new(1.0, 0.0)).length() < 1e-15, "{}", f[1]);
        // Charge 0: no force.
        assert_eq!(f[2], DVec2::ZERO);
        // The time scale of the free charge's motion: sqrt(r³ m / (k q q)) = 1.
        let ts = Term::<DVec2>::time_scale(&t, &x, &plain).unwrap();
        assert!((ts - 1.0).abs() < 1e-15, "{ts}");
    }

    /// Newton's third law holds to round-off for both sums (direct below 1024 particles,
    /// symmetric above), and the direct and symmetric sums agree.
    #[test]
    fn net_force_vanishes_for_a_neutral_cloud() {
        for n in [203usize, 1500] {
            let mut seed = 7u64;
            let mut rnd = || {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            };
            let x: Vec<DVec3> = (0..n).map(|_| DVec3::new(rnd(), rnd(), rnd())).collect();
            let q: Vec<f64> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 } * (1.0 + rnd())).collect();
            let mdl = model(&q, &vec![false; n]);
            let mut t = Pairwise::coulomb("c".into(), 1.0, 0.01);
            let mut f = vec![DVec3::ZERO; n];
            Term::<DVec3>::add_forces(&mut t, &x, &x, &mdl, &mut f, Write::Overwrite);
            let net: DVec3 = f.iter().copied().sum();
            let scale: f64 = f.iter().map(|v| v.length()).sum();
            assert!(net.length() <= 1e-13 * scale, "n = {n}: net {net} of {scale}");
            // Against the naive sum.
            for i in (0..n).step_by(97) {
                let mut want = DVec3::ZERO;
                for j in (0..n).filter(|&j| j != i) {
                    let d = x[i] - x[j];
                    want += d * (q[i] * q[j] / (d.length_squared() + 1e-4).powf(1.5));
                }
                assert!((f[i] - want).length() <= 1e-12 * want.length().max(1.0), "{i}: {} vs {want}", f[i]);
            }
        }
    }
}
