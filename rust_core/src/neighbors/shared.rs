//! Neighbour searches shared between the terms of one particle system.
//!
//! A term that needs "all particles within r" looks here, when it is added to a system
//! (`Term::share`), for a search that terms of its kind already keep under the same key (for
//! SPH: the same support, kernel and pass precision). If it finds one, it joins it: one cell
//! list over the particles of all of them, built once per force evaluation, whose neighbour
//! loops see every member's particles, so the members interact (two fluids push on each
//! other). If it finds none, it registers its own for the next term to join.
//!
//! The registry is type-erased: each entry is whatever its kind of term shares, and only that
//! kind reads it back (by downcast to its own type), so the system needs no knowledge of SPH.
use std::any::Any;
use std::sync::Arc;

/// The shared searches of one particle system, by key.
#[derive(Default)]
pub struct Shared {
    entries: Vec<(String, Arc<dyn Any + Send + Sync>)>,
}

impl Shared {
    /// Whether no search is registered.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The search registered under `key`, if there is one of type `T`.
    pub fn find<T: Any + Send + Sync>(&self, key: &str) -> Option<Arc<T>> {
        let (_, e) = self.entries.iter().find(|(k, _)| k == key)?;
        e.clone().downcast::<T>().ok()
    }

    /// Registers `search` under `key`, in place of any search registered there before (which
    /// keeps working for its members; later terms join the new one).
    pub fn register<T: Any + Send + Sync>(&mut self, key: String, search: Arc<T>) {
        self.entries.retain(|(k, _)| *k != key);
        self.entries.push((key, search));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn finds_by_key_and_type_and_the_last_registered_wins() {
        let mut s = Shared::default();
        assert!(s.find::<Mutex<u32>>("a").is_none());
        let a = Arc::new(Mutex::new(1u32));
        s.register("a".into(), a.clone());
        assert!(Arc::ptr_eq(&s.find::<Mutex<u32>>("a").unwrap(), &a));
        assert!(s.find::<Mutex<i64>>("a").is_none(), "another type under the key is not it");
        assert!(s.find::<Mutex<u32>>("b").is_none());
        let b = Arc::new(Mutex::new(2u32));
        s.register("a".into(), b.clone());
        assert!(Arc::ptr_eq(&s.find::<Mutex<u32>>("a").unwrap(), &b));
        assert_eq!(*a.lock().unwrap(), 1, "the replaced search is untouched");
    }
}
