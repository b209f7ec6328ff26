//! The registry of collider types, as `terms::registry` is for force terms: each collider
//! registers a key and a builder from `Params` in its own file (`register_collider!`), and the
//! binding has one `add_collider(kind, params)` for all of them, so a new collider touches its
//! own file (plus its `mod` line), its Python record and its tests.
use super::Constraint;
use crate::error::{invalid, Result};
use crate::terms::registry::Params;
use crate::vector::Vector;
use glam::{DVec2, DVec3};
use std::any::Any;

pub type Build<V> = fn(&Params) -> Result<Box<dyn Constraint<V>>>;

/// A registered collider type: its key and its builders for 2D and 3D.
#[derive(Debug)]
pub struct ColliderType {
    pub kind: &'static str,
    build2: Build<DVec2>,
    build3: Build<DVec3>,
}

impl ColliderType {
    pub const fn new(kind: &'static str, build2: Build<DVec2>, build3: Build<DVec3>) -> Self {
        Self { kind, build2, build3 }
    }

    /// The collider from `params` (checked: `InvalidInput` naming the parameter).
    pub fn build<V: Vector>(&self, params: &Params) -> Result<Box<dyn Constraint<V>>> {
        let builders: [&dyn Any; 2] = [&self.build2, &self.build3];
        for b in builders {
            if let Some(f) = b.downcast_ref::<Build<V>>() {
                return f(params);
            }
        }
        unreachable!("a vector type other than DVec2 or DVec3")
    }
}

inventory::collect!(ColliderType);

/// The registered collider type `kind`.
pub fn lookup(kind: &str) -> Result<&'static ColliderType> {
    inventory::iter::<ColliderType>
        .into_iter()
        .find(|t| t.kind == kind)
        .ok_or_else(|| invalid("kind", format!("unknown collider type {kind:?}; known: {}", kinds().join(", "))))
}

/// Every registered key, sorted.
pub fn kinds() -> Vec<&'static str> {
    let mut k: Vec<_> = inventory::iter::<ColliderType>.into_iter().map(|t| t.kind).collect();
    k.sort_unstable();
    k
}

/// Registers a collider type: `register_collider!("sphere", build)` with
/// `fn build<V: Vector>(p: &Params) -> Result<Box<dyn Constraint<V>>>`.
#[macro_export]
macro_rules! register_collider {
    ($kind:literal, $build:ident) => {
        inventory::submit! {
            $crate::constraints::registry::ColliderType::new($kind, $build::<glam::DVec2>, $build::<glam::DVec3>)
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terms::registry::Value;

    #[test]
    fn every_collider_is_registered_once_and_bad_parameters_are_named() {
        let k = kinds();
        assert_eq!(k, ["box", "capsule", "oriented_box", "plane", "sphere"]);
        assert!(lookup("cone").unwrap_err().to_string().contains("known: box, capsule"));
        let p = Params::new()
            .with("center", Value::Floats(vec![0.0, 0.0]))
            .with("radius", Value::Number(-1.0))
            .with("inside", Value::Number(0.0))
            .with("restitution", Value::Number(0.5))
            .with("friction", Value::Number(0.0));
        assert!(lookup("sphere").unwrap().build::<DVec2>(&p).err().unwrap().to_string().contains("radius"));
        assert!(lookup("sphere").unwrap().build::<DVec3>(&p).err().unwrap().to_string().contains("center"));
    }
}
