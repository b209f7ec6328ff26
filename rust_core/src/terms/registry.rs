//! Term types by key. Each term file registers how to build itself from named parameters
//! (`register_term!("gravity", build)` beside its `impl Term`), so a front end adds any term
//! through one call, [`lookup`] then [`TermType::build`], and adding a term type touches only its
//! own file (plus its `mod` line). The registry is collected at link time by `inventory`
//! (dtolnay's crate: no global constructor to call, works on every platform Rust targets).
use super::Term;
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::vector::{Real, Vector};
use glam::{DVec2, DVec3};
use std::any::Any;
use std::collections::BTreeMap;

/// One parameter value as a front end hands it over.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Number(Real),
    /// A flat run of numbers (a vector, one number per particle or per spring, or rows of
    /// vectors flattened).
    Floats(Vec<Real>),
    /// Particle indices.
    Indices(Vec<u32>),
    Text(String),
}

impl Value {
    fn kind(&self) -> &'static str {
        match self {
            Value::Number(_) => "a number",
            Value::Floats(_) => "an array of numbers",
            Value::Indices(_) => "an array of particle indices",
            Value::Text(_) => "a string",
        }
    }
}

/// The named parameters of one term. Accessors name the parameter in their errors.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Params {
    values: BTreeMap<String, Value>,
}

impl Params {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn with(mut self, key: &str, value: Value) -> Self {
        self.insert(key, value);
        self
    }
    pub fn insert(&mut self, key: &str, value: Value) {
        self.values.insert(key.to_string(), value);
    }
    /// A copy whose arrays are allocated fallibly (`clone` aborts the process when the
    /// allocator refuses): a refusal is `Error::OutOfMemory` of call `what` naming the parameter
    /// and its length, as `params_of`'s copies of a front end's arrays are. What a part's record
    /// keeps of the parameters it was built from.
    pub fn try_clone(&self, what: &'static str) -> Result<Self> {
        self.try_clone_except(what, &[])
    }
    /// `try_clone` without the parameters named in `skip`.
    pub fn try_clone_except(&self, what: &'static str, skip: &[&str]) -> Result<Self> {
        let mut values = BTreeMap::new();
        for (key, v) in self.values.iter().filter(|(k, _)| !skip.contains(&k.as_str())) {
            let copy_of = |n: usize, bytes: u128| {
                Need::new(what, bytes, format!("a copy of its {key} ({} entries)", count(n as u128)))
            };
            let v = match v {
                Value::Floats(a) => Value::Floats(copy_of(a.len(), Need::bytes_of::<Real>(a.len())).copy(a)?),
                Value::Indices(a) => Value::Indices(copy_of(a.len(), Need::bytes_of::<u32>(a.len())).copy(a)?),
                Value::Number(x) => Value::Number(*x),
                Value::Text(t) => Value::Text(t.clone()),
            };
            values.insert(key.clone(), v);
        }
        Ok(Self { values })
    }
    /// The number of entries of array `key` (0 where it is missing or a single value).
    pub fn len_of(&self, key: &str) -> usize {
        match self.values.get(key) {
            Some(Value::Floats(a)) => a.len(),
            Some(Value::Indices(a)) => a.len(),
            _ => 0,
        }
    }
    /// Whether `key` was given (for optional parameters with defaults).
    pub fn has(&self, key: &str) -> bool {
        self.values.contains_key(key)
    }
    fn get(&self, key: &str) -> Result<&Value> {
        self.values.get(key).ok_or_else(|| invalid(key, "missing"))
    }
    fn wrong(key: &str, want: &str, got: &Value) -> crate::error::Error {
        invalid(key, format!("expected {want}, got {}", got.kind()))
    }
    /// A finite number.
    pub fn number(&self, key: &str) -> Result<Real> {
        match self.get(key)? {
            Value::Number(x) if x.is_finite() => Ok(*x),
            Value::Number(x) => Err(invalid(key, format!("must be finite, got {x}"))),
            v => Err(Self::wrong(key, "a number", v)),
        }
    }
    /// A whole number in `0..=max` (given as a number, as front ends without integers do).
    pub fn count(&self, key: &str, max: usize) -> Result<usize> {
        let x = self.number(key)?;
        if x < 0.0 || x.fract() != 0.0 || x > max as Real {
            return Err(invalid(key, format!("expected a whole number in 0..={max}, got {x}")));
        }
        Ok(x as usize)
    }
    /// A yes/no (given as 1 or 0).
    pub fn flag(&self, key: &str) -> Result<bool> {
        let x = self.number(key)?;
        if x == 1.0 || x == 0.0 {
            Ok(x == 1.0)
        } else {
            Err(invalid(key, format!("expected true or false (1 or 0), got {x}")))
        }
    }
    /// A finite vector of the scene's dimension.
    pub fn vector<V: Vector>(&self, key: &str) -> Result<V> {
        match self.get(key)? {
            Value::Floats(v) if v.len() == V::DIM && v.iter().all(|c| c.is_finite()) => Ok(V::from_slice(v)),
            Value::Floats(v) if v.len() == V::DIM => Err(invalid(key, "must be finite")),
            Value::Floats(v) => Err(invalid(key, format!("expected {} components, got {}", V::DIM, v.len()))),
            v => Err(Self::wrong(key, "a vector", v)),
        }
    }
    /// A finite pseudo-vector of the scene's dimension (`Vector::Axial`): 3 components in 3D,
    /// 1 in 2D (the z component, out of the plane).
    pub fn axial<V: Vector>(&self, key: &str) -> Result<V::Axial> {
        let n = V::AXIAL_DIM;
        let what = if n == 1 {
            "1 component in 2D (the z component, out of the plane)".to_string()
        } else {
            format!("{n} components")
        };
        match self.get(key)? {
            Value::Floats(v) if v.len() == n && v.iter().all(|c| c.is_finite()) => Ok(V::axial_from_slice(v)),
            Value::Floats(v) if v.len() == n => Err(invalid(key, "must be finite")),
            Value::Floats(v) => Err(invalid(key, format!("expected {what}, got {}", v.len()))),
            v => Err(Self::wrong(key, "a vector", v)),
        }
    }
    /// Moves out a flat array of numbers (not checked: the term checks what it needs).
    pub fn take_floats(&mut self, key: &str) -> Result<Vec<Real>> {
        match self.values.remove(key) {
            Some(Value::Floats(v)) => Ok(v),
            Some(v) => Err(Self::wrong(key, "an array of numbers", &v)),
            None => Err(invalid(key, "missing")),
        }
    }
    /// Moves out rows of vectors given flattened (length a multiple of the dimension).
    pub fn take_vectors<V: Vector>(&mut self, key: &str) -> Result<Vec<V>> {
        let flat = self.take_floats(key)?;
        if flat.len() % V::DIM != 0 {
            return Err(invalid(key, format!("expected rows of {} numbers, got {} numbers", V::DIM, flat.len())));
        }
        let n = flat.len() / V::DIM;
        let need = Need::new("add_term", Need::bytes_of::<V>(n), format!("{} rows of {key}", count(n as u128)));
        need.collect(flat.chunks_exact(V::DIM).map(V::from_slice))
    }
    /// Moves out particle indices.
    pub fn take_indices(&mut self, key: &str) -> Result<Vec<u32>> {
        match self.values.remove(key) {
            Some(Value::Indices(v)) => Ok(v),
            Some(v) => Err(Self::wrong(key, "an array of particle indices", &v)),
            None => Err(invalid(key, "missing")),
        }
    }
    pub fn text(&self, key: &str) -> Result<&str> {
        match self.get(key)? {
            Value::Text(s) => Ok(s),
            v => Err(Self::wrong(key, "a string", v)),
        }
    }
}

/// What a term may need to know of the scene it joins.
#[derive(Debug, Clone, Copy)]
pub struct Context {
    pub n_particles: usize,
}

/// Builds one term of the scene's dimension from its name and parameters.
pub type Build<V> = fn(String, Params, &Context) -> Result<Box<dyn Term<V>>>;

/// The integrators a part can be stepped by, with the argument a refusal names and what the
/// part is called in it (`check_integrator`).
pub type Rule = (&'static [&'static str], &'static str, &'static str);

/// A registered term type: its key, its builders for 2D and 3D, and its part–integrator rule
/// (`None`: any integrator), registered beside the term (`register_term!`).
#[derive(Debug)]
pub struct TermType {
    pub kind: &'static str,
    build2: Build<DVec2>,
    build3: Build<DVec3>,
    rule: Option<Rule>,
}

impl TermType {
    pub const fn new(kind: &'static str, build2: Build<DVec2>, build3: Build<DVec3>, rule: Option<Rule>) -> Self {
        Self { kind, build2, build3, rule }
    }

    /// The term for a scene of vectors `V` (`DVec2` or `DVec3`).
    pub fn build<V: Vector>(&self, name: String, params: Params, ctx: &Context) -> Result<Box<dyn Term<V>>> {
        // Exactly one of the two casts succeeds: V is DVec2 or DVec3 (the only `Vector`s).
        let builders: [&dyn Any; 2] = [&self.build2, &self.build3];
        for b in builders {
            if let Some(f) = b.downcast_ref::<Build<V>>() {
                return f(name, params, ctx);
            }
        }
        unreachable!("Vector is implemented for DVec2 and DVec3 only")
    }
}

inventory::collect!(TermType);

/// The integrators a part of `kind` can be stepped by (`None`: any, or no such kind), with the
/// argument a refusal names and what the part is called in it: the rule its term registered
/// (`register_term!(kind, build, rule)`). The terms' `Traits::integrators` read it, and so does
/// the facade (`check_integrator`) before it adds anything of the part.
pub fn integrator_rule(kind: &str) -> Option<Rule> {
    lookup(kind).ok().and_then(|t| t.rule)
}

/// `InvalidInput` if a part of `kind` cannot be stepped by `integrator`.
pub fn check_integrator(kind: &str, integrator: &str) -> Result<()> {
    match integrator_rule(kind) {
        Some((ok, arg, who)) if !ok.contains(&integrator) => {
            let names = ok.iter().map(|o| format!("integrator='{o}'")).collect::<Vec<_>>().join(" or ");
            let only = if ok.len() == 1 { " only" } else { "" };
            Err(invalid(
                arg,
                format!(
                    "{who} {names}{only} (the scene uses '{integrator}'); build the scene with \
                     pc.Scene(..., integrator='{}') or set scene.integrator first",
                    ok[0]
                ),
            ))
        }
        _ => Ok(()),
    }
}

/// The registered type `kind`.
pub fn lookup(kind: &str) -> Result<&'static TermType> {
    inventory::iter::<TermType>
        .into_iter()
        .find(|t| t.kind == kind)
        .ok_or_else(|| invalid("kind", format!("unknown term type {kind:?}; known: {}", kinds().join(", "))))
}

/// Every registered key, sorted.
pub fn kinds() -> Vec<&'static str> {
    let mut k: Vec<_> = inventory::iter::<TermType>.into_iter().map(|t| t.kind).collect();
    k.sort_unstable();
    k
}

/// Registers a term type: `register_term!("gravity", build)` with
/// `fn build<V: Vector>(name: String, p: Params, ctx: &Context) -> Result<Box<dyn Term<V>>>`;
/// a term that only some integrators can step adds its rule (`Rule`):
/// `register_term!("dfsph", build, (&["semi_implicit_euler"], "method", "DFSPH steps with"))`.
#[macro_export]
macro_rules! register_term {
    ($kind:literal, $build:ident) => {
        inventory::submit! {
            $crate::terms::registry::TermType::new($kind, $build::<glam::DVec2>, $build::<glam::DVec3>, None)
        }
    };
    ($kind:literal, $build:ident, $rule:expr) => {
        inventory::submit! {
            $crate::terms::registry::TermType::new($kind, $build::<glam::DVec2>, $build::<glam::DVec3>, Some($rule))
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The copy a part's record keeps (`try_clone`, fallible) is the parameters, every kind of value.
    #[test]
    fn a_fallible_copy_of_the_parameters_is_a_clone() {
        let p = Params::new()
            .with("i", Value::Indices(vec![0, 1, 2]))
            .with("stiffness", Value::Floats(vec![1.0, 2.5]))
            .with("damping", Value::Number(0.5))
            .with("name", Value::Text("cloth".into()));
        assert_eq!(p.try_clone("springs").unwrap(), p);
        assert_eq!(Params::new().try_clone("springs").unwrap(), Params::new());
    }

    /// The rules are registered beside their terms and read back by key; a kind without one
    /// (or unknown) takes any integrator.
    #[test]
    fn part_integrator_rules_come_from_the_registration() {
        let (ok, arg, _) = integrator_rule("dfsph").expect("DFSPH registers its rule");
        assert_eq!((ok, arg), (&["semi_implicit_euler"][..], "method"));
        assert!(integrator_rule("contacts").unwrap().0.contains(&"xpbd"));
        assert!(integrator_rule("springs").is_none() && integrator_rule("no_such_term").is_none());
        assert!(check_integrator("dfsph", "verlet").unwrap_err().to_string().contains("method"));
        assert!(check_integrator("springs", "verlet").is_ok());
    }

    #[test]
    fn every_term_type_is_registered_once() {
        let k = kinds();
        for want in ["drag", "gravity", "pairwise_gravity", "sph", "springs", "tree_gravity"] {
            assert!(k.contains(&want), "{want} missing from {k:?}");
        }
        let mut unique = k.clone();
        unique.dedup();
        assert_eq!(unique, k, "a key is registered twice");
        assert!(lookup("no_such_term").unwrap_err().to_string().contains("known: "));
    }

    #[test]
    fn a_term_builds_for_both_dimensions_and_names_bad_parameters() {
        let ctx = Context { n_particles: 0 };
        let g = lookup("gravity").unwrap();
        let p2 = Params::new().with("g", Value::Floats(vec![0.0, -9.81]));
        assert_eq!(g.build::<DVec2>("g".into(), p2.clone(), &ctx).unwrap().name(), "g");
        let e = g.build::<DVec3>("g".into(), p2, &ctx).err().unwrap().to_string();
        assert!(e.starts_with("g: expected 3 components"), "{e}");
        let e = g.build::<DVec2>("g".into(), Params::new(), &ctx).err().unwrap().to_string();
        assert_eq!(e, "g: missing");
        let text = Params::new().with("g", Value::Text("down".into()));
        let e = g.build::<DVec2>("g".into(), text, &ctx).err().unwrap().to_string();
        assert_eq!(e, "g: expected a vector, got a string");
    }
}
