//! Fallible allocation for buffers sized by the user's input. Rust's `Vec` growth aborts the
//! process when the allocator refuses (out of memory, or an address-space limit such as
//! RLIMIT_AS); these helpers return `Error::OutOfMemory` instead, naming the call, how many
//! bytes it needed and for what, so Python raises `MemoryError` and the process lives on.
use crate::error::{Error, Result};
use std::fmt::Display;

/// A call's memory need: reported if one of its allocations fails.
#[derive(Clone, Debug)]
pub struct Need {
    what: &'static str,
    bytes: u64,
    of: String,
}

impl Need {
    /// `what` needs `bytes` (saturating) `of` something, e.g. ("add_particles", 9.6e8,
    /// "20,000,000 particles").
    pub fn new(what: &'static str, bytes: u128, of: impl Display) -> Self {
        Self { what, bytes: u64::try_from(bytes).unwrap_or(u64::MAX), of: of.to_string() }
    }

    /// A read of the fields `names` of `n` values each (float64) of `elements` ("grid cells"):
    /// call "field", as the facade's `Grid.field` and flows' properties are.
    pub fn fields(names: &[&str], n: usize, elements: &str) -> Self {
        let bytes = Self::bytes_of::<f64>(n) * names.len() as u128;
        Self::new("field", bytes, format!("{} of {} {elements}", names.join(", "), count(n as u128)))
    }

    /// The bytes needed (saturated at u64::MAX).
    pub fn bytes(&self) -> u128 {
        self.bytes as u128
    }

    /// `n` items of type `T`, in bytes (saturating).
    pub fn bytes_of<T>(n: usize) -> u128 {
        n as u128 * std::mem::size_of::<T>() as u128
    }

    pub fn error(&self) -> Error {
        Error::OutOfMemory { what: self.what.to_string(), bytes: self.bytes, of: self.of.clone() }
    }

    /// Refuses at once if the need cannot be addressed at all (more than `isize::MAX` bytes).
    pub fn check(&self) -> Result<()> {
        if self.bytes > isize::MAX as u64 {
            return Err(self.error());
        }
        Ok(())
    }

    /// Capacity for `len` items in total (nothing if there is already room).
    pub fn reserve<T>(&self, v: &mut Vec<T>, len: usize) -> Result<()> {
        if len > v.capacity() {
            v.try_reserve_exact(len - v.len()).map_err(|_| self.error())?;
        }
        Ok(())
    }

    /// Checks that `bytes` more can be had now (reserved and freed at once, never touched), for
    /// transient buffers allocated where a refusal cannot be reported (inside parallel parts).
    /// The reservation is handed to `black_box`: the optimiser may remove an allocation that is
    /// never used (and assume it succeeded), which would make the check pass at any limit. A
    /// room check is only as good as its byte count: a buffer grown by doubling (a `collect` of
    /// a filter) can pass its estimate; such buffers are better allocated fallibly themselves.
    pub fn room(&self, bytes: u128) -> Result<()> {
        let b = usize::try_from(bytes).map_err(|_| self.error())?;
        let mut v = Vec::<u8>::new();
        v.try_reserve_exact(b).map_err(|_| self.error())?;
        std::hint::black_box(&mut v);
        Ok(())
    }

    /// `vec![value; n]`.
    pub fn filled<T: Clone>(&self, n: usize, value: T) -> Result<Vec<T>> {
        let mut v = Vec::new();
        self.resize(&mut v, n, value)?;
        Ok(v)
    }

    /// `v.resize(n, value)`.
    pub fn resize<T: Clone>(&self, v: &mut Vec<T>, n: usize, value: T) -> Result<()> {
        self.reserve(v, n)?;
        v.resize(n, value);
        Ok(())
    }

    /// `s.to_vec()`.
    pub fn copy<T: Clone>(&self, s: &[T]) -> Result<Vec<T>> {
        let mut v = Vec::new();
        self.reserve(&mut v, s.len())?;
        v.extend_from_slice(s);
        Ok(v)
    }

    /// `it.collect()` for an iterator of known length.
    pub fn collect<T>(&self, it: impl ExactSizeIterator<Item = T>) -> Result<Vec<T>> {
        let mut v = Vec::new();
        self.reserve(&mut v, it.len())?;
        v.extend(it);
        Ok(v)
    }
}

/// `n` with thousands separators: 20,000,000.
pub fn count(n: u128) -> String {
    let s = n.to_string();
    let mut out = String::with_capacity(s.len() + s.len() / 3);
    for (k, c) in s.chars().enumerate() {
        if k > 0 && (s.len() - k).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// Bytes in decimal units (lives with the error that prints it, so that `error` needs nothing of
/// this module).
pub use crate::error::human;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_counts_read_well() {
        assert_eq!(count(0), "0");
        assert_eq!(count(999), "999");
        assert_eq!(count(1000), "1,000");
        assert_eq!(count(20_000_000), "20,000,000");
        assert_eq!(human(512), "512 bytes");
        assert_eq!(human(800_000_000), "800 MB");
        assert_eq!(human(1_920_000_000), "1.92 GB");
        assert_eq!(human(12_345), "12.3 kB");
        assert_eq!(human(999_999), "1.00 MB");
    }

    #[test]
    fn a_refused_allocation_is_an_error_naming_the_need() {
        assert!(Need::new("neighbors", 1u128 << 70, "").check().is_err());
        let need = Need::new("neighbors", 1u128 << 40, format!("{} pairs", count(1 << 36)));
        assert!(need.check().is_ok());
        // More than the address space: refused by the allocator, not by an abort.
        let mut v: Vec<u64> = Vec::new();
        let e = need.reserve(&mut v, usize::MAX / 8).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("neighbors: needs 1.10 TB for 68,719,476,736 pairs"), "{msg}");
        assert!(v.capacity() == 0);
    }

    #[test]
    fn room_refuses_what_the_allocator_refuses() {
        // 2^46 bytes (64 TiB): addressable, but more than any machine this runs on commits.
        let need = Need::new("blur", 1u128 << 46, "a test");
        assert!(need.room(1u128 << 46).is_err());
        assert!(need.room(1 << 20).is_ok());
    }
}
