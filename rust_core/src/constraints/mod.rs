//! The constraint (projection) stage: run after each integration step, it moves particles back
//! into the allowed set and corrects their velocities. The colliders (`Plane`, `Aabb`, `Sphere`,
//! `Capsule`, `OrientedBox`) are one generic [`Collider`] (`collider`: the loop, the bounce and
//! the books, written once) over a shape of `crate::geometry`, each registered by key in its own
//! small file (`registry`, as force terms are); position-based constraints (XPBD) are the
//! "xpbd" integrator's. The energy a projection removes goes into one book, "collisions".
//!
//! A new collider is a shape (`geometry/`, `impl Shape`) plus a file here with its type alias,
//! `impl Collide<V> for MyShape<V> {}`, a constructor and `register_collider!`.
pub mod aabb;
pub mod capsule;
pub mod collider;
pub mod oriented_box;
pub mod plane;
pub mod registry;
pub mod sphere;
pub use aabb::Aabb;
pub use capsule::Capsule;
pub use collider::{Collide, Collider, Resolved};
pub use oriented_box::OrientedBox;
pub use plane::Plane;
pub use sphere::Sphere;

use crate::error::{invalid, Result};
use crate::par;
use crate::state::{Model, State};
use crate::vector::{Real, Vector};

/// One constraint of the projection stage.
pub trait Constraint<V: Vector>: Send + Sync {
    /// Projects `x` back into the allowed set and corrects `v` (restitution, friction); returns
    /// (energy removed, J; whether any particle was moved). `f_last`: forces (N) of the last
    /// evaluation, `g`: the uniform acceleration (m/s², not in `f_last`), for the work the
    /// projection does against them. `kick` (s): the integrator's share of a velocity change
    /// in its own energy error (`IntegratorInfo::projection_kick`): each moved particle also books
    /// `kick`·m g·(v_new − v_old). (The uniform field's alone: the terms that book their own
    /// dissipation, the contacts, already balance theirs exactly; with the whole force an
    /// elastic gas in a box drifted 1.1e-3.)
    fn project(&self, x: &mut [V], v: &mut [V], model: &Model, f_last: &[V], g: V, kick: Real) -> (Real, bool);
}

/// The constraints of a particle system, applied in the order they were added, and the energy
/// they have removed so far.
pub struct Constraints<V: Vector> {
    items: Vec<Box<dyn Constraint<V>>>,
    /// Energy removed by the constraints so far, J (the "collisions" book).
    pub dissipated: Real,
}

impl<V: Vector> Default for Constraints<V> {
    fn default() -> Self {
        Self { items: Vec::new(), dissipated: 0.0 }
    }
}

impl<V: Vector> Constraints<V> {
    pub fn push(&mut self, c: Box<dyn Constraint<V>>) {
        self.items.push(c);
    }
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Runs every constraint on `state` and books what they remove (`kick`: see
    /// `Constraint::project`); returns whether any particle was moved (a cached force or stage derivative is then stale). With a single-precision
    /// state the moved state is rounded back to float32.
    pub fn apply(&mut self, state: &mut State<V>, model: &Model, f_last: &[V], g: V, kick: Real, single: bool) -> bool {
        let mut touched = false;
        for c in &self.items {
            let (d, t) = c.project(&mut state.x, &mut state.v, model, f_last, g, kick);
            self.dissipated += d;
            touched |= t;
        }
        if touched && single {
            par::chunks2(&mut state.x, &mut state.v, |_, x, v| {
                x.iter_mut().chain(v.iter_mut()).for_each(|p| *p = p.round_f32());
            });
        }
        touched
    }
}

/// The contact coefficients of a wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Coefficient of restitution e in [0, 1].
    pub restitution: Real,
    /// Coulomb friction coefficient μ ≥ 0.
    pub friction: Real,
}

impl Contact {
    /// `InvalidInput` naming the argument if e is outside [0, 1] or μ is not finite and ≥ 0.
    pub fn new(restitution: Real, friction: Real) -> Result<Self> {
        if !(0.0..=1.0).contains(&restitution) {
            return Err(invalid("restitution", format!("{restitution} is outside [0, 1]")));
        }
        if !(friction.is_finite() && friction >= 0.0) {
            return Err(invalid("friction", format!("{friction} must be finite and >= 0")));
        }
        Ok(Self { restitution, friction })
    }

    /// The velocity after a collision with a wall of unit normal `n` (into the allowed side):
    /// if `v` moves into the wall, its normal part becomes −e v_n and its tangential speed drops
    /// by μ(1 + e)|v_n| (Coulomb friction on the impulse), never past zero; else `v` unchanged.
    #[inline(always)]
    pub fn bounce<V: Vector>(&self, v: V, n: V) -> V {
        let (e, mu) = (self.restitution, self.friction);
        let vn = v.dot(n);
        if !(vn < 0.0) {
            return v; // moving away or along (or NaN: left for the divergence check)
        }
        let vt = v - n * vn;
        let vt2 = vt.length_squared();
        let dvn = (1.0 + e) * (-vn);
        let vt_new = if mu > 0.0 && vt2 > 0.0 {
            let vtl = vt2.sqrt();
            vt * ((vtl - mu * dvn).max(0.0) / vtl)
        } else {
            vt
        };
        vt_new + n * (-e * vn)
    }
}
