//! Point sources fixed in space: masses (Newtonian gravity on the particles' mass) or charges
//! (Coulomb's law on their `charge` attribute), with Plummer softening ε.
//!
//! Mass coupling, source masses M_s ≥ 0 (Plummer 1911; Aarseth, *Gravitational N-body
//! simulations*, 2003, eq. 2.4):
//!   F_i = −m_i G Σ_s M_s (x_i − x_s) / (r² + ε²)^{3/2},   U = −G Σ_i m_i Σ_s M_s / (r² + ε²)^{1/2}
//! Charge coupling, source charges Q_s of either sign (Griffiths, *Introduction to
//! Electrodynamics*, 4th ed., eqs. 2.1 and 2.26):
//!   F_i = q_i k Σ_s Q_s (x_i − x_s) / (r² + ε²)^{3/2},    U = k Σ_i q_i Σ_s Q_s / (r² + ε²)^{1/2}
//! (like charges repel). Both are c_i Σ_s K_s d / (r² + ε²)^{3/2} with c_i the particle's mass or
//! charge and K_s = −G M_s or k Q_s, and U = Σ_i c_i Σ_s K_s / (r² + ε²)^{1/2}: one kernel.
//!
//! A particle exactly on an unsoftened source (r = ε = 0) gets nothing from that source, force
//! or potential: the direction is undefined (the convention of `PairwiseGravity`). The sources
//! do not move and feel no reaction, so momentum is not conserved (angular momentum about a
//! single source is).
use super::{coupled_forces, coupled_potential, Coupling};
use crate::error::{invalid, Result};
use crate::par;
use crate::state::Model;
use crate::terms::registry::{Context, Params};
use crate::terms::{Term, Traits, Write};
use crate::vector::{Real, Vector};

pub struct PointSources<V: Vector> {
    pub name: String,
    /// Source positions, m.
    pub positions: Vec<V>,
    /// Source strengths: masses (kg) or charges (C).
    pub strengths: Vec<Real>,
    /// G (m³/(kg·s²)) or k (N·m²/C²).
    pub constant: Real,
    /// Plummer softening length ε, m.
    pub softening: Real,
    pub coupling: Coupling,
    /// K_s = −G M_s or k Q_s.
    k: Vec<Real>,
}

fn build<V: Vector>(name: String, mut p: Params, _: &Context) -> Result<Box<dyn Term<V>>> {
    let coupling = Coupling::from_params(&p)?;
    let (constant, softening) = (p.number("constant")?, p.number("softening")?);
    let positions = p.take_vectors::<V>("positions")?;
    let strengths = p.take_floats("strengths")?;
    Ok(Box::new(PointSources::new(name, positions, strengths, constant, softening, coupling)?))
}
crate::register_term!("point_sources", build);

impl<V: Vector> PointSources<V> {
    pub fn new(
        name: String,
        positions: Vec<V>,
        strengths: Vec<Real>,
        constant: Real,
        softening: Real,
        coupling: Coupling,
    ) -> Result<Self> {
        if !(constant.is_finite() && constant > 0.0) {
            return Err(invalid("constant", format!("{constant} must be finite and > 0")));
        }
        if !(softening.is_finite() && softening >= 0.0) {
            return Err(invalid("softening", format!("{softening} must be finite and >= 0")));
        }
        if let Some(s) = positions.iter().position(|x| !x.is_finite()) {
            return Err(invalid("positions", format!("source {s} is not finite")));
        }
        if strengths.len() != positions.len() {
            let n = positions.len();
            return Err(invalid("strengths", format!("has {} entries for {n} sources", strengths.len())));
        }
        let sign = match coupling {
            Coupling::Mass => -1.0,
            Coupling::Charge => 1.0,
        };
        let mut k = Vec::with_capacity(strengths.len());
        for (s, &q) in strengths.iter().enumerate() {
            if !q.is_finite() || (coupling == Coupling::Mass && q < 0.0) {
                let want = if coupling == Coupling::Mass { "finite and >= 0" } else { "finite" };
                return Err(invalid("strengths", format!("source {s} is {q} (must be {want})")));
            }
            let ks = sign * constant * q;
            if !ks.is_finite() {
                return Err(invalid("strengths", format!("source {s}: {q} times the constant {constant} overflows")));
            }
            k.push(ks);
        }
        Ok(Self { name, positions, strengths, constant, softening, coupling, k })
    }

    /// Σ_s K_s d / (r² + ε²)^{3/2} and Σ_s K_s / (r² + ε²)^{1/2} at `x`: the force and the
    /// potential per unit coupling. Sources in order: the same bits for any thread count.
    #[inline]
    fn field(&self, x: V) -> (V, Real) {
        let eps2 = self.softening * self.softening;
        let (mut f, mut u) = (V::ZERO, 0.0);
        for (&xs, &k) in self.positions.iter().zip(&self.k) {
            let d = x - xs;
            let r2 = d.length_squared() + eps2;
            if r2 > 0.0 {
                let inv_r = 1.0 / r2.sqrt();
                u += k * inv_r;
                f += d * (k * inv_r * inv_r * inv_r);
            }
        }
        (f, u)
    }
}

impl<V: Vector> Term<V> for PointSources<V> {
    fn name(&self) -> &str {
        &self.name
    }
    fn add_forces(&mut self, x: &[V], _v: &[V], model: &Model, f: &mut [V], write: Write) -> Real {
        let this = &*self;
        coupled_forces(self.coupling, x, model, f, write, |p| this.field(p).0);
        0.0
    }
    fn potential(&self, x: &[V], model: &Model) -> Option<Real> {
        Some(coupled_potential(self.coupling, x, model, |p| self.field(p).1))
    }
    fn traits(&self) -> Traits<V> {
        Traits { softened: true, ..Traits::conservative() }
    }
    fn time_scale(&self, x: &[V], model: &Model) -> Option<Real> {
        // The shortest free-fall (or Coulomb) time sqrt((r² + ε²)^{3/2} / |c_i K_s / m_i|) over
        // free particles and sources: a maximum, exact in any order.
        let c = self.coupling.of(model)?;
        let eps2 = self.softening * self.softening;
        let rate = par::reduce(x.len(), 0.0, Real::max, |r| {
            let mut m: Real = 0.0;
            for i in r {
                let a = c[i] * model.inv_mass[i];
                if a == 0.0 {
                    continue;
                }
                for (&xs, &k) in self.positions.iter().zip(&self.k) {
                    let r2 = (x[i] - xs).length_squared() + eps2;
                    if r2 > 0.0 {
                        m = m.max((a * k).abs() / (r2 * r2.sqrt()));
                    }
                }
            }
            m
        });
        (rate > 0.0).then(|| (1.0 / rate).sqrt()).filter(|t| t.is_finite() && *t > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec2, DVec3};

    fn model(n: usize) -> Model {
        Model { mass: vec![2.0; n], inv_mass: vec![0.5; n], ..Default::default() }
    }

    #[test]
    fn a_point_mass_attracts_with_newtons_law_and_its_potential_is_minus_gmm_over_r() {
        let src = vec![DVec3::new(1.0, 0.0, 0.0)];
        let mut t = PointSources::new("m".into(), src, vec![3.0], 0.5, 0.0, Coupling::Mass).unwrap();
        let x = [DVec3::new(1.0, 2.0, 0.0)];
        let m = model(1);
        let mut f = [DVec3::ONE];
        t.add_forces(&x, &x, &m, &mut f, Write::Overwrite);
        // |F| = G M m / r² = 0.5·3·2/4, towards the source (−y).
        assert!((f[0] - DVec3::new(0.0, -0.75, 0.0)).length() < 1e-15, "{:?}", f[0]);
        assert!((t.potential(&x, &m).unwrap() + 0.5 * 3.0 * 2.0 / 2.0).abs() < 1e-15);
        // The free-fall time at r = 2: sqrt(r³ / (G M)).
        assert!((t.time_scale(&x, &m).unwrap() - (8.0f64 / 1.5).sqrt()).abs() < 1e-14);
    }

    #[test]
    fn like_charges_repel_unlike_attract_and_uncharged_scenes_feel_nothing() {
        let src = vec![DVec2::ZERO];
        let mut t = PointSources::new("q".into(), src, vec![2.0], 3.0, 0.0, Coupling::Charge).unwrap();
        let x = [DVec2::new(2.0, 0.0), DVec2::new(0.0, -1.0), DVec2::new(5.0, 5.0)];
        let mut m = model(3);
        let mut f = [DVec2::ONE; 3];
        t.add_forces(&x, &x, &m, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::ZERO; 3]);
        assert_eq!(t.potential(&x, &m), Some(0.0));
        assert_eq!(t.time_scale(&x, &m), None);
        m.attributes.insert("charge", vec![1.0, -1.0, 0.0]);
        t.add_forces(&x, &x, &m, &mut f, Write::Overwrite);
        // k Q q / r²: 3·2·1/4 outward (+x) for the like charge; 3·2/1 inward (+y) for the other.
        assert!((f[0] - DVec2::new(1.5, 0.0)).length() < 1e-15);
        assert!((f[1] - DVec2::new(0.0, 6.0)).length() < 1e-15);
        assert_eq!(f[2], DVec2::ZERO);
        assert!((t.potential(&x, &m).unwrap() - (3.0 * 2.0 / 2.0 - 3.0 * 2.0)).abs() < 1e-15);
    }

    #[test]
    fn the_force_is_minus_the_gradient_of_the_potential_with_softening() {
        let src = vec![DVec3::new(0.1, -0.2, 0.3), DVec3::new(-1.0, 0.5, 0.0)];
        let t = PointSources::new("m".into(), src, vec![1.0, 2.5], 1.3, 0.2, Coupling::Mass).unwrap();
        let x = DVec3::new(0.4, 0.7, -0.6);
        let (f, _) = t.field(x);
        let h = 1e-6;
        for a in 0..3 {
            let mut e = [0.0; 3];
            e[a] = h;
            let d = DVec3::from_slice(&e);
            let g = (t.field(x + d).1 - t.field(x - d).1) / (2.0 * h);
            assert!((f.comp(a) + g).abs() < 1e-8, "axis {a}: {} vs {}", f.comp(a), -g);
        }
    }

    #[test]
    fn on_an_unsoftened_source_nothing_is_added_and_pinned_particles_are_skipped() {
        let mut t = PointSources::new("m".into(), vec![DVec2::ZERO], vec![1.0], 1.0, 0.0, Coupling::Mass).unwrap();
        let x = [DVec2::ZERO, DVec2::new(1.0, 0.0)];
        let mut m = model(2);
        m.inv_mass[1] = 0.0;
        let mut f = [DVec2::ONE; 2];
        t.add_forces(&x, &x, &m, &mut f, Write::Overwrite);
        assert_eq!(f, [DVec2::ZERO; 2]);
        assert_eq!(t.potential(&x, &m), Some(0.0));
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = |r: Result<PointSources<DVec2>>| r.err().unwrap().to_string();
        let p = || vec![DVec2::ZERO];
        assert!(e(PointSources::new("m".into(), p(), vec![1.0], 0.0, 0.0, Coupling::Mass)).starts_with("constant"));
        assert!(e(PointSources::new("m".into(), p(), vec![1.0], 1.0, -1.0, Coupling::Mass)).starts_with("softening"));
        assert!(e(PointSources::new("m".into(), p(), vec![-1.0], 1.0, 0.0, Coupling::Mass)).starts_with("strengths"));
        assert!(
            e(PointSources::new("m".into(), p(), vec![1.0, 2.0], 1.0, 0.0, Coupling::Mass)).starts_with("strengths")
        );
        assert!(
            e(PointSources::new("m".into(), p(), vec![1e308], 1e10, 0.0, Coupling::Charge)).starts_with("strengths")
        );
        let nan = vec![DVec2::new(f64::NAN, 0.0)];
        assert!(e(PointSources::new("m".into(), nan, vec![1.0], 1.0, 0.0, Coupling::Mass)).starts_with("positions"));
        // A negative source charge is fine.
        assert!(PointSources::new("m".into(), p(), vec![-1.0], 1.0, 0.0, Coupling::Charge).is_ok());
    }
}
