//! The roles a term may play besides giving forces, each asked for by the one stage that runs
//! it (`Term::as_magnetic`, `as_constraints`, `as_projection`, `as_jacobian`): a term that
//! does not play a role returns `None`, and nothing else in it mentions the role. The model is
//! salva's split of a fluid's forces (`NonPressureForce`) from its pressure solver
//! (`PressureSolver`): a force is a force; a constraint is projected; a pressure solver is a
//! projection the particle system runs; a magnetic field is what the Boris push asks for.
use super::Projection;
use crate::error::Result;
use crate::state::Model;
use crate::vector::{Real, Vector};

/// The pairwise sum of gravity or Coulomb (`pairwise_gravity`), as the stages that take its law
/// apart read it: the batch's fused kernel (`crate::batch`), which steps the small sum with the
/// same bits, and the Wisdom–Holman integrator (`integrators::wisdom_holman`), which splits
/// Kepler orbits off Newtonian gravity.
pub trait FusedForce {
    /// `Some((c, ε², weights))` where the term is the small pairwise sum F_i = c w_i S_i at this
    /// scene's `n` particles, float64.
    fn small_pairwise<'a>(&self, model: &'a Model, n: usize) -> Option<(Real, Real, &'a [Real])>;
    /// `Some((G, ε))` where the term is Newtonian gravity summed directly over every pair (G in
    /// m³/(kg·s²), the Plummer softening ε in m), at any size and precision.
    fn newtonian(&self) -> Option<(Real, Real)>;
}

/// A magnetic field (F = q v × B), which the Boris push turns the velocities through exactly
/// (`integrators/boris.rs`); the other integrators take its force from `Term::add_forces`.
pub trait Magnetic<V: Vector> {
    /// Adds the field B (T) at each position of `x` into `b` (in 2D its z component).
    fn add_field(&self, x: &[V], model: &Model, b: &mut [V::Axial]);
}

/// Position-based constraints with compliance (XPBD; Macklin, Müller & Chentanez 2016),
/// projected by the "xpbd" integrator (`integrators/xpbd.rs`); such a term adds no force, and
/// the other integrators leave it inert.
pub trait Constraints<V: Vector> {
    /// Starts a substep: the accumulated Lagrange multipliers λ return to 0.
    fn begin(&mut self);
    /// One Gauss–Seidel iteration over the constraints in a substep of `h` seconds, moving the
    /// positions `x` (m) of free particles (compliance scaled as α/h²).
    fn project(&mut self, x: &mut [V], model: &Model, h: Real);
}

/// A velocity projection or pressure solver (DFSPH, `sph/dfsph/`), run by
/// "semi_implicit_euler" inside its step; a term playing it lists that integrator alone
/// (`registry::integrator_rule`).
pub trait VelocityProjection<V: Vector> {
    /// Projects the velocities `v` (m/s) of the particles the term covers at positions `x`, in
    /// a step of `dt` (s): `Projection::Divergence` at the step's start, before the forces are
    /// evaluated, and `Projection::Density` after the kick, before the drift (positions are the
    /// step's start in both). Returns the kinetic energy the projection removed (J; negative if
    /// it added some), which the integrator books as the term's dissipation. `g` is the step's
    /// uniform acceleration (world gravity, m/s²), which walls need for their hydrostatic
    /// pressure (DFSPH).
    fn project(&mut self, stage: Projection, x: &[V], v: &mut [V], model: &Model, dt: Real, g: V) -> Real;
}

/// A fluid that rigid bodies meet through boundary particles sampled on their surfaces
/// (Akinci et al., "Versatile rigid-fluid coupling for incompressible SPH", ACM TOG 31 (2012)
/// 62): the bodies' coupling (`systems::bodies::BodyContacts`) samples each moving body's
/// surface at the fluid's particle spacing, weighs each sample by Ψ_b = ρ0 / Σ_k W_bk over its
/// body's samples (paper eq. 4–5), and before every step hands the fluid the samples and their
/// bodies' motion; the fluid counts them in its density and divergence like its walls (but
/// moving), and its pressure solve pushes the bodies as it pushes its particles, iteration by
/// iteration (the solve sees the body's response, so a light body whose added mass exceeds its
/// own is solved with the fluid, as in the strong coupling of Gissler et al., "Interlinked SPH
/// pressure solvers for strong fluid-rigid coupling", ACM TOG 38 (2019) 5). After the step the coupling applies to each body the
/// impulse the fluid gave it (paper eq. 10–11: equal and opposite to the fluid's).
pub trait MovingBoundary<V: Vector> {
    /// The smoothing length h (m), rest density ρ0 (kg/m^dim), kernel, and particle spacing
    /// (m: (m̄/ρ0)^(1/dim) over the fluid's particles), to sample and weigh the boundary.
    fn boundary_sampling(&self, model: &Model) -> (Real, Real, crate::sph::KernelKind, Real);
    /// The boundary of the next step: positions `x` (m), Ψ_b (`psi`, kg), each sample's body
    /// (index into `bodies`) and its offset from that body's centre of mass (m), and the
    /// bodies' motion at the step's start.
    fn set_boundary(&mut self, x: &[V], psi: &[Real], body: &[u32], offset: &[V], bodies: &[BodyMotion<V>]);
    /// The linear (N s) and angular (N m s, about the centre of mass) impulse the fluid gave
    /// each body over the last step of `dt` seconds (zeros before a step).
    fn boundary_impulses(&self, dt: Real, out: &mut Vec<(V, [Real; 3])>);
    /// Whether the energy the fluid gives the bodies is booked by the coupling as exchanged
    /// (DFSPH: its projections book the fluid's share as they remove it), or is paid by the
    /// fluid's own potential energy, which counts the boundary (WCSPH's internal energy).
    fn books_exchange(&self) -> bool;
}

/// A rigid body as a fluid's pressure solve sees it: velocity (m/s), angular velocity (rad/s,
/// (0, 0, ω) in 2D), inverse mass (1/kg) and world inverse inertia (symmetric: m11, m12, m13,
/// m22, m23, m33; 2D: only m33), 0 for a body that is not pushed (kinematic), and the
/// acceleration its own step gives it (gravity, m/s²), which the density solve adds as the fluid
/// adds its particles' (the body's step then adds it for real); and the gravity of the scene
/// (m/s², for every body, pushed or not), which sets the hydrostatic rise of the fluid's
/// pressure from a particle to a sample of the body (Adami et al. 2012: g − a_b, per body; the
/// body's own acceleration a_b is not known before the solve and is left out).
#[derive(Clone, Copy, Debug)]
pub struct BodyMotion<V: Vector> {
    pub v: V,
    pub w: [Real; 3],
    pub inv_mass: Real,
    pub inv_inertia: [Real; 6],
    pub accel: V,
    pub gravity: V,
}

/// The force's Jacobians, for implicit integrators ("implicit_euler"): a term that has them is
/// taken implicitly (linearised at the step's start); a term without them explicitly at the
/// step's start. Uniform fields (gravity) are constant and need none.
pub trait Jacobian<V: Vector> {
    /// Called once per step, before the products at `(x, v)`: a term may keep the
    /// state-dependent part of its Jacobian (springs: each axis and transverse factor, so that
    /// a CG iteration needs no square root or division) for the products that follow, which
    /// are then made at these same `x` and `v` until the next call.
    /// Returns whether it kept anything (a term that cannot, or need not, computes its products
    /// directly).
    fn prepare(&mut self, _x: &[V], _v: &[V], _model: &Model) -> bool {
        false
    }
    /// Adds `(cx ∂f/∂x + cv ∂f/∂v)·w` at `(x, v)` into `out`, one vector per particle,
    /// matrix-free (`c = (cx, cv)`; ∂f/∂x in N/m, ∂f/∂v in N·s/m), gathered per particle so that
    /// results are bit-identical for any thread count. Rows of pinned particles may be non-zero
    /// (the solver filters them).
    fn product(&self, x: &[V], v: &[V], model: &Model, c: (Real, Real), w: &[V], out: &mut [V]);
    /// Adds the diagonal of `cx ∂f/∂x + cv ∂f/∂v` at `(x, v)` into `out` (component k of
    /// `out[i]` gets the entry of row and column (i, k)): the Jacobi preconditioner.
    fn diagonal(&self, x: &[V], v: &[V], model: &Model, c: (Real, Real), out: &mut [V]);
}

/// A state of the term's own, besides the particles', that it steps, books and restores itself
/// (contacts: spins and tangential springs; DFSPH: the pressure solve's warm starts): the
/// particle system calls these around each step, for the energy and momentum books, and for
/// rollback and save/load.
pub trait OwnState<V: Vector> {
    /// Called before each integrator step (or "xpbd" substep) with its dt (s).
    fn begin_step(&mut self, _dt: Real) {}
    /// Called after each integrator step, before the constraint stage, with the state the step
    /// made: the term advances its own state here.
    fn end_step(&mut self, _x: &[V], _v: &[V], _model: &Model, _dt: Real) {}
    /// Completes what `end_step` deferred to the next evaluation (the contacts' springs), when a
    /// call of steps ends or before something else changes the state (the constraint stage's
    /// projections among them); idempotent.
    fn settle(&mut self, _x: &[V], _v: &[V], _model: &Model) {}
    /// "xpbd" only: the state a substep of `h` predicted, before its projections move it (the
    /// term may close its books here).
    fn after_predict(&mut self, _x: &[V], _v: &[V], _model: &Model, _h: Real) {}
    /// Kinetic energy the own state carries (contacts: rotation, ½Iω²), J.
    fn kinetic(&self, _model: &Model) -> Real {
        0.0
    }
    /// Angular momentum the own state carries (contacts: spins, Σ Iω), kg·m²/s.
    fn angular_momentum(&self, _model: &Model) -> [Real; 3] {
        [0.0; 3]
    }
    /// Energy books the term keeps itself (dissipated energies by cause, J), where it does not
    /// book through the integrator (`Term::dissipative` false).
    fn books(&self) -> Vec<(String, Real)> {
        Vec::new()
    }
    /// Whether `books` are finite; checked after every step, without `books`' allocations.
    fn books_finite(&self) -> bool {
        true
    }
    /// The first particle whose own state (not its books) is not finite, if any: checked after
    /// every step, so that a divergence is caught where it starts.
    fn non_finite(&self) -> Option<usize> {
        None
    }
    /// The memory the term's last evaluation could not have for lists its state sizes (the
    /// contacts of crowded grains), checked after every step: the world then rolls the call
    /// back and reports this `Error::OutOfMemory` (`Failure::Memory`).
    fn refused(&self) -> Option<crate::error::Error> {
        None
    }
    /// The own state as reals (rollback, save/load); `Error::OutOfMemory` where its buffer
    /// cannot be had (a save under a memory cap aborted the process before).
    fn history(&self) -> Result<Vec<Real>>;
    /// Restores what `history` returned, for a scene of `n_particles`; checked, nothing changes
    /// on error.
    fn set_history(&mut self, h: &[Real], n_particles: usize) -> Result<()>;
    /// Restores what `history` returned on this very term (a rollback to a snapshot its system
    /// took): the values are taken as they are, non-finite ones included, so it cannot fail.
    fn restore_history(&mut self, h: &[Real], n_particles: usize);
    /// The spins the term gives its particles (contacts: grains), for a coupling that pushes
    /// a particle at its surface and so turns it (the rigid bodies' `BodyContacts`); `None`
    /// (the default) where the term gives none.
    fn spins(&mut self) -> Option<Spins<'_, V>> {
        None
    }
}

/// The spins a term gives its particles (`OwnState::spins`): a particle turns if it has a
/// radius r > 0 (the model's `"radius"` attribute) and is not pinned (inverse mass ≠ 0), with
/// moment of inertia I = β m r² about its centre.
pub struct Spins<'a, V: Vector> {
    /// Angular velocity of each particle, rad/s (2D: about z); as many as the system has
    /// particles once the term has stepped (fewer before: then none turns).
    pub omega: &'a mut [V::Axial],
    /// β in I = β m r² (dimensionless).
    pub inertia_factor: Real,
}

#[cfg(test)]
mod tests {
    use crate::integrators::{by_name, IntegratorOptions};
    use crate::systems::particles::ParticleSystem;
    use crate::terms::{Drag, ForceSet, Term, UniformGravity, UniformMagneticField};
    use glam::DVec2;

    #[test]
    fn the_force_set_knows_each_terms_roles_and_a_replacement_updates_them() {
        let mut f = ForceSet::<DVec2>::default();
        f.push(Box::new(UniformGravity { name: "g".into(), g: DVec2::new(0.0, -9.81) })).unwrap();
        f.push(Box::new(Drag { name: "air".into(), b: 0.1 })).unwrap();
        f.push(Box::new(UniformMagneticField::<DVec2> { name: "B".into(), b: 0.5 })).unwrap();
        assert!(f.has_jacobian() && f.magnetic() && !f.projects_velocities());
        assert!(f.constraint_terms().is_empty());
        let roles = |t: &mut Box<dyn Term<DVec2>>| {
            (
                t.as_magnetic().is_some(),
                t.as_jacobian().is_some(),
                t.as_own_state().is_some(),
                t.as_constraints().is_some(),
            )
        };
        let got: Vec<_> = f.terms.iter_mut().map(roles).collect();
        assert_eq!(got, [(false, false, false, false), (false, true, false, false), (true, false, false, false)]);
        // Replacing the drag by a second gravity: no Jacobian left, g summed in term order.
        f.replace(1, Box::new(UniformGravity { name: "air".into(), g: DVec2::new(1.0, 0.0) })).unwrap();
        assert!(!f.has_jacobian());
        assert_eq!(f.g, DVec2::ZERO + DVec2::new(0.0, -9.81) + DVec2::new(1.0, 0.0));
    }

    #[test]
    fn integrator_options_are_validated_and_kept_across_a_switch() {
        let mut p = ParticleSystem::<DVec2>::new("dopri5").unwrap();
        assert_eq!(p.options(), IntegratorOptions::default());
        let o = IntegratorOptions { rtol: 1e-9, xpbd_substeps: 4, ..IntegratorOptions::default() };
        p.set_options(o).unwrap();
        for bad in [
            IntegratorOptions { rtol: 1.0, ..o },
            IntegratorOptions { atol: -1.0, ..o },
            IntegratorOptions { cg_tol: 0.0, ..o },
            IntegratorOptions { cg_max_iter: 0, ..o },
            IntegratorOptions { xpbd_substeps: 0, ..o },
            IntegratorOptions { xpbd_iterations: 20_000, ..o },
        ] {
            assert!(p.set_options(bad).is_err(), "{bad:?}");
            assert_eq!(p.options(), o, "nothing changes on error");
        }
        p.set_integrator("xpbd").unwrap();
        assert_eq!((p.options(), p.substeps()), (o, (4, 1)));
        assert_eq!(p.integrator_info().force_evals_per_step, 4, "xpbd took its substeps from the options");
        assert!(by_name::<DVec2>("no_such").is_err());
    }
}
