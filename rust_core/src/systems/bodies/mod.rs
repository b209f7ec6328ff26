//! Rigid bodies in 2D and 3D (balls, boxes, capsules, convex polygons and hulls, triangle meshes
//! for fixed bodies; revolute, fixed, prismatic, spherical and rope joints), solved by rapier
//! (Crozet, dimforge: `rapier2d-f64`, `rapier3d-f64`). Contact and joint solving is a field of
//! its own with a well-kept library: physcore adds what it does not have, the coupling with
//! particles (`BodyContacts`), the energy books, rollback and bit-identical restarts, and the
//! rendering. The system is written once (`common.rs`) and built per dimension (`dim2`,
//! `dim3`).
//!
//! Why rapier: deterministic (its `enhanced-determinism` feature: libm's functions, the same
//! bits on every platform), double precision, serialisable state (serde), and no threads of its
//! own here (no `parallel` feature), so results never depend on the thread count.
//!
//! Bodies are numbered in the order they were added, across groups (the Python `Bodies` parts):
//! the fields (`x`, `y`, `angle`, `vx`, ... in 2D; `x`, `y`, `z`, `qx`, ..., `wz` in 3D) hold one
//! value per body in that order. A group is one shape kind; joints join two bodies (or a body
//! and a fixed point).
//!
//! The books: kinetic energy (translation and rotation) and the potential of uniform gravity
//! of the dynamic bodies; what rapier's contacts, friction, restitution and joints (and its
//! integrator's error) change is booked as one residual, "bodies: contacts and joints", since
//! rapier does not report them apart; what the particle coupling exchanges, as "bodies ⇄
//! particles". So the total balances by construction and the residual is what to read.
pub mod dim2;
pub mod dim3;

pub use dim2::{Bodies as Bodies2, BodyContacts as BodyContacts2, Group as Group2};
pub use dim3::{Bodies as Bodies3, BodyContacts as BodyContacts3, Group as Group3};

use crate::alloc::Need;
use crate::error::{invalid, Error, Result};
use crate::terms::registry::Params;
use crate::vector::{Real, Vector as PVector};
use std::sync::atomic::{AtomicBool, Ordering};

fn finite_all(key: &str, v: &[Real]) -> Result<()> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(invalid(key, format!("entry {i} is not finite: {}", v[i]))),
        None => Ok(()),
    }
}

fn take_len(p: &mut Params, key: &str, len: usize) -> Result<Vec<Real>> {
    let v = p.take_floats(key)?;
    if v.len() != len {
        return Err(invalid(key, format!("has {} values, expected {len}", v.len())));
    }
    finite_all(key, &v)?;
    Ok(v)
}

/// Refuses `vertices` (`dim` reals a vertex) whose extent float64 cannot resolve: under 1e-150 m
/// (squared lengths underflow) or under 1e-12 of their distance from the origin (the vertices
/// coincide once rounded). parry's hull builders panicked on such input (a polygon of vertices
/// 1e-200 apart, found by the hostile fuzz) instead of refusing it.
fn resolvable(vertices: &[Real], dim: usize) -> Result<()> {
    let (mut extent, mut far): (Real, Real) = (0.0, 0.0);
    for k in 0..dim {
        let axis = vertices.iter().skip(k).step_by(dim);
        let (lo, hi) = axis.fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        extent = extent.max(hi - lo);
        far = far.max(lo.abs()).max(hi.abs());
    }
    if extent > 1e-150 && extent > 1e-12 * far {
        Ok(())
    } else {
        Err(invalid(
            "vertices",
            format!("span {extent:.3e} m at {far:.3e} m from the origin: too small a shape for float64 to resolve"),
        ))
    }
}

/// A shape built by parry (`Err`: why it refuses the input), a panic inside it (input it does
/// not refuse) turned into a refusal too, naming `key`.
fn built<T>(key: &str, build: impl FnOnce() -> std::result::Result<T, String>) -> Result<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(build)) {
        Ok(Ok(shape)) => Ok(shape),
        Ok(Err(why)) => Err(invalid(key, why)),
        Err(_) => Err(invalid(key, "the shape builder failed on them")),
    }
}

/// `job()` on a thread of its own while this one watches `stop` (every 10 ms): once it is set,
/// `Error::Interrupted` is returned at once and the job is left to finish unseen (it owns what
/// it reads; its result is dropped). parry's hull of 200,000 vertices takes seconds and has no
/// way to be stopped inside. Where no thread can start (a limit on threads, or no memory for its
/// stack) the job runs here, to its end.
fn off_thread<T: Send + 'static>(stop: &AtomicBool, job: impl FnOnce() -> T + Send + 'static) -> Result<T> {
    match watched("physcore-shape", stop, job) {
        Some(Ok(value)) => Ok(value),
        Some(Err(_)) => Err(invalid("vertices", "the shape builder failed on them")),
        None => Err(Error::Interrupted { rolled_back_to: 0 }),
    }
}

/// How a job run in a process of its own (`apart`) ended.
#[derive(Debug, PartialEq)]
#[cfg_attr(not(unix), allow(dead_code))]
enum Apart {
    /// It returned.
    Ended,
    /// It panicked (the panic was caught there).
    Panicked,
    /// Its process died: why, in words (an abort, most often an allocation no memory could
    /// hold; a crash; no end within its time).
    Died(String),
    /// Ctrl-C came while it ran (`crate::stop::signalled`): it was killed.
    Interrupted,
    /// No process could be made (no `fork` here, or the system refused one), or its end could
    /// not be read (SIGCHLD ignored by the program): the caller runs the job itself.
    Unavailable,
}

/// `job()` in a child process (`fork`), so that what no Rust code can recover from (an
/// allocation that fails, which aborts; a stack overflow; a crash in unsafe code) ends that
/// process, not this one. The child's address space is held to its size at the fork plus
/// `extra` bytes (RLIMIT_AS, Linux), so a runaway allocation fails there instead of taking the
/// machine's memory; its stdout and stderr go to /dev/null. The parent polls its end (from 20 µs
/// up to every 10 ms) and Ctrl-C, and kills it after `wall` (a state can also loop for ever).
/// The child runs on one thread, this one's copy: the job must not wait on other threads
/// (rapier here has none; rayon's pool is not in the child).
#[cfg(unix)]
fn apart(extra: u128, wall: std::time::Duration, job: impl FnOnce()) -> Apart {
    // SAFETY: fork, then in the child only this thread's code, allocation (glibc's malloc is
    // reset for the child) and libc calls, ended by `_exit` (no atexit handlers, no Python).
    let pid = unsafe { libc::fork() };
    if pid < 0 {
        return Apart::Unavailable;
    }
    if pid == 0 {
        unsafe {
            let null = libc::open(c"/dev/null".as_ptr(), libc::O_WRONLY);
            if null >= 0 {
                libc::dup2(null, 1);
                libc::dup2(null, 2);
            }
            for s in [libc::SIGSEGV, libc::SIGBUS, libc::SIGABRT, libc::SIGILL, libc::SIGFPE] {
                libc::signal(s, libc::SIG_DFL);
            }
            hold_address_space(extra);
        }
        let ok = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).is_ok();
        unsafe { libc::_exit(if ok { 0 } else { 101 }) }
    }
    let (start, mut nap) = (std::time::Instant::now(), std::time::Duration::from_micros(20));
    loop {
        let mut status = 0;
        // SAFETY: waits on our own child.
        let r = unsafe { libc::waitpid(pid, &mut status, libc::WNOHANG) };
        if r == pid {
            return if libc::WIFEXITED(status) {
                match libc::WEXITSTATUS(status) {
                    0 => Apart::Ended,
                    101 => Apart::Panicked,
                    c => Apart::Died(format!("its process exited with status {c}")),
                }
            } else if libc::WIFSIGNALED(status) {
                Apart::Died(match libc::WTERMSIG(status) {
                    libc::SIGABRT => "it aborted: an allocation failed (no memory could hold it)".into(),
                    libc::SIGSEGV | libc::SIGBUS => "it crashed (a stack overflow or a bad address)".into(),
                    libc::SIGKILL => "its process was killed (out of memory?)".into(),
                    s => format!("its process died of signal {s}"),
                })
            } else {
                Apart::Died("its process ended oddly".into())
            };
        }
        if r < 0 {
            if std::io::Error::last_os_error().raw_os_error() == Some(libc::EINTR) {
                continue;
            }
            return Apart::Unavailable;
        }
        let late = start.elapsed() > wall;
        if late || crate::stop::signalled() {
            // SAFETY: our own child, not yet reaped.
            unsafe {
                libc::kill(pid, libc::SIGKILL);
                libc::waitpid(pid, &mut status, 0);
            }
            return if late {
                Apart::Died(format!("it did not end within {:.0} s", wall.as_secs_f64()))
            } else {
                Apart::Interrupted
            };
        }
        std::thread::sleep(nap);
        nap = (nap * 2).min(std::time::Duration::from_millis(10));
    }
}

#[cfg(not(unix))]
fn apart(_extra: u128, _wall: std::time::Duration, _job: impl FnOnce()) -> Apart {
    Apart::Unavailable
}

/// Lowers this process's RLIMIT_AS (soft) to its present size plus `extra` bytes (never raising
/// it). Linux only: elsewhere the limit is left as it is.
#[cfg(unix)]
unsafe fn hold_address_space(extra: u128) {
    #[cfg(target_os = "linux")]
    {
        // /proc/self/statm: the size in pages first.
        let Ok(statm) = std::fs::read_to_string("/proc/self/statm") else {
            return;
        };
        let Some(pages) = statm.split_whitespace().next().and_then(|p| p.parse::<u128>().ok()) else {
            return;
        };
        let page = libc::sysconf(libc::_SC_PAGESIZE).max(4096) as u128;
        let want = (pages * page).saturating_add(extra).min(libc::rlim_t::MAX as u128) as libc::rlim_t;
        let mut lim = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        if libc::getrlimit(libc::RLIMIT_AS, &mut lim) == 0 && want < lim.rlim_cur {
            lim.rlim_cur = want;
            libc::setrlimit(libc::RLIMIT_AS, &lim);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = extra;
}

/// `job()` on a thread named `name` while this one polls `stop` every 10 ms: `None` once `stop`
/// is seen set (the job is left to finish unseen and its result dropped), else the job's result,
/// or the payload of its panic (for the caller to resume or refuse). Where no thread can start,
/// the job runs here, to its end (a panic then unwinds from here, as without the thread).
fn watched<T: Send + 'static>(
    name: &str,
    stop: &AtomicBool,
    job: impl FnOnce() -> T + Send + 'static,
) -> Option<std::thread::Result<T>> {
    use std::sync::mpsc::{channel, RecvTimeoutError};
    use std::sync::{Arc, Mutex};
    let slot = Arc::new(Mutex::new(Some(job)));
    let (theirs, (tx, rx)) = (slot.clone(), channel());
    // The thread's id, so that an abandoned job can be sent to the back of the queue.
    let tid = Arc::new(std::sync::atomic::AtomicI64::new(0));
    let their_tid = tid.clone();
    let started = std::thread::Builder::new().name(name.into()).stack_size(8 << 20).spawn(move || {
        #[cfg(target_os = "linux")]
        // SAFETY: gettid has no preconditions.
        their_tid.store(unsafe { libc::gettid() } as i64, Ordering::Relaxed);
        let _ = &their_tid;
        if let Some(job) = theirs.lock().unwrap_or_else(|p| p.into_inner()).take() {
            let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)));
        }
    });
    if started.is_err() {
        let job = slot.lock().unwrap_or_else(|p| p.into_inner()).take().expect("the thread never started");
        return Some(Ok(job()));
    }
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(10)) {
            Ok(result) => return Some(result),
            Err(RecvTimeoutError::Timeout) if stop.load(Ordering::Relaxed) => {
                // The abandoned job runs on to its end, unseen: at the lowest priority, so that
                // it does not slow the caller's rollback on a busy machine (Linux: a thread's
                // own nice value).
                #[cfg(target_os = "linux")]
                {
                    let t = tid.load(Ordering::Relaxed);
                    if t > 0 {
                        // SAFETY: setpriority on a thread id of this process; a failure is harmless.
                        unsafe { libc::setpriority(libc::PRIO_PROCESS, t as libc::id_t, 19) };
                    }
                }
                let _ = &tid;
                return None;
            }
            Err(RecvTimeoutError::Timeout) => {}
            // The job is sent as it ends, panic or not: only a thread killed unwinding gets here.
            Err(RecvTimeoutError::Disconnected) => return Some(Err(Box::new("the thread ended without a result"))),
        }
    }
}

/// Bytes packed 6 to a real (each an integer below 2⁴⁸, exact and finite), so that rapier's
/// serialised state travels in the scene file's arrays of reals.
/// Allocated fallibly (`need`).
fn pack(bytes: &[u8], need: &Need) -> Result<Vec<Real>> {
    need.collect(bytes.chunks(6).map(|c| {
        let mut w = [0u8; 8];
        w[..c.len()].copy_from_slice(c);
        u64::from_le_bytes(w) as Real
    }))
}

/// What a saved bodies state starts with: this tag, then the FNV-1a digest (64 bit, little
/// endian) of the bincode bytes that follow. A flipped bit anywhere changes the digest (each
/// byte's step is a bijection of the hash state), so a damaged file is refused before rapier's
/// state is read: one flipped bit in a state aborted the process on the next step (a 103 GB
/// allocation) or made every call panic. (A state saved before the digest has no tag and is
/// read as it is.) It guards against damage, not against a file crafted to pass it.
const SEAL: &[u8; 8] = b"pcbody01";

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3))
}

/// The length of the tag and the digest before the bytes of a sealed state.
const SEALED: usize = 16;

/// Seals the bytes after the first `SEALED` of `bytes` (written in place, so that a large state
/// is never copied): the tag, then their digest, go in front.
fn seal(bytes: &mut [u8]) {
    let digest = fnv1a(&bytes[SEALED..]);
    bytes[..8].copy_from_slice(SEAL);
    bytes[8..SEALED].copy_from_slice(&digest.to_le_bytes());
}

/// The bytes a sealed state carries, once their digest is checked. Bytes whose first eight
/// are more than 8 bits from the tag are a state from before the seal, read as they are (one
/// starts with rapier's counts, nowhere near ASCII); a tag with a bit or a few flipped is damage.
fn unsealed(bytes: &[u8]) -> Result<&[u8]> {
    let near = bytes.len() >= 8 && bytes[..8].iter().zip(SEAL).map(|(a, b)| (a ^ b).count_ones()).sum::<u32>() <= 8;
    if !near {
        return Ok(bytes);
    }
    let rest = bytes
        .strip_prefix(SEAL.as_slice())
        .ok_or_else(|| invalid("state", "is damaged: its tag is not the bodies state's"))?;
    let (digest, body) = rest.split_at_checked(8).ok_or_else(|| invalid("state", "is cut short"))?;
    if u64::from_le_bytes(digest.try_into().expect("8 bytes")) != fnv1a(body) {
        return Err(invalid("state", "is damaged: its bytes do not match the digest saved with them"));
    }
    Ok(body)
}

/// The bytes `pack` packed (`None`: not such reals), allocated fallibly (`need`).
fn unpack(packed: &[Real], len: Real, need: &Need) -> Result<Option<Vec<u8>>> {
    if !(len >= 0.0 && len.fract() == 0.0 && len as usize <= packed.len() * 6 && len as usize + 6 > packed.len() * 6) {
        return Ok(None);
    }
    let mut out = Vec::new();
    need.reserve(&mut out, packed.len() * 6)?;
    for &w in packed {
        if !(0.0..281_474_976_710_656.0).contains(&w) || w.fract() != 0.0 {
            return Ok(None);
        }
        out.extend_from_slice(&(w as u64).to_le_bytes()[..6]);
    }
    out.truncate(len as usize);
    Ok(Some(out))
}

fn particle_kinetic<V: PVector>(v: &[V], mass: &[Real], inv_mass: &[Real]) -> Real {
    let mut k = 0.0;
    for i in 0..v.len() {
        if inv_mass[i] != 0.0 {
            k += 0.5 * mass[i] * v[i].length_squared();
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::systems::System;
    use crate::terms::registry::Value;

    /// What kills a process kills the child `apart` runs the job in, and says how.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_job_apart_ends_panics_aborts_overflows_runs_out_of_memory_or_out_of_time_alone() {
        use std::time::Duration;
        let wall = Duration::from_secs(20);
        assert_eq!(apart(1 << 26, wall, || {}), Apart::Ended);
        assert_eq!(apart(1 << 26, wall, || panic!("a panic")), Apart::Panicked);
        let aborted = apart(1 << 26, wall, || std::process::abort());
        assert!(matches!(&aborted, Apart::Died(why) if why.contains("aborted")), "{aborted:?}");
        // 1 GiB asked, 64 MiB allowed above the size at the fork: the allocation fails there.
        let big = apart(1 << 26, wall, || {
            let v = vec![1u8; 1 << 30];
            std::hint::black_box(&v);
        });
        assert!(matches!(&big, Apart::Died(why) if why.contains("aborted")), "{big:?}");
        #[allow(unconditional_recursion)]
        fn deep(n: u64) -> u64 {
            std::hint::black_box(deep(std::hint::black_box(n + 1))) + 1
        }
        let overflow = apart(1 << 26, wall, || {
            std::hint::black_box(deep(0));
        });
        assert!(
            matches!(&overflow, Apart::Died(why) if why.contains("crashed") || why.contains("aborted")),
            "{overflow:?}"
        );
        let t = std::time::Instant::now();
        let endless = apart(1 << 26, Duration::from_millis(300), || loop {
            std::hint::spin_loop();
        });
        assert!(matches!(&endless, Apart::Died(why) if why.contains("did not end")), "{endless:?}");
        assert!(t.elapsed() < Duration::from_secs(5));
    }

    #[test]
    fn a_sealed_state_refuses_every_flipped_bit_and_an_unsealed_one_reads_as_it_is() {
        let body: Vec<u8> = (0..200u32).map(|i| (i * 7 + 3) as u8).collect();
        let mut s = vec![0u8; SEALED];
        s.extend_from_slice(&body);
        seal(&mut s);
        assert_eq!(unsealed(&s).unwrap(), &body[..]);
        for bit in 0..s.len() * 8 {
            let mut f = s.clone();
            f[bit / 8] ^= 1 << (bit % 8);
            assert!(unsealed(&f).is_err(), "bit {bit} flipped was not seen");
        }
        assert!(unsealed(&s[..12]).is_err());
        assert_eq!(unsealed(&body).unwrap(), &body[..]);
    }

    /// A group of dynamic bodies of `shape` at the `dim`-D positions `x`.
    pub(super) fn group(dim: usize, shape: &str, x: &[Real], size: &[Real]) -> Params {
        let n = x.len() / dim;
        let (rot, ang) = if dim == 2 { (vec![0.0; n], n) } else { ([0.0, 0.0, 0.0, 1.0].repeat(n), 3 * n) };
        Params::new()
            .with("shape", Value::Text(shape.into()))
            .with("kind", Value::Text("dynamic".into()))
            .with("n", Value::Number(n as Real))
            .with("positions", Value::Floats(x.to_vec()))
            .with(if dim == 2 { "angles" } else { "orientations" }, Value::Floats(rot))
            .with("velocities", Value::Floats(vec![0.0; dim * n]))
            .with("angular_velocities", Value::Floats(vec![0.0; ang]))
            .with("size", Value::Floats(size.to_vec()))
            .with("density", Value::Number(1000.0))
            .with("friction", Value::Number(0.5))
            .with("restitution", Value::Number(0.1))
    }

    #[test]
    fn a_stop_is_answered_within_its_poll_while_the_job_runs_on() {
        let stop = AtomicBool::new(true);
        let t = std::time::Instant::now();
        let r = off_thread(&stop, || std::thread::sleep(std::time::Duration::from_secs(2)));
        assert!(matches!(r, Err(Error::Interrupted { .. })), "{r:?}");
        assert!(t.elapsed().as_secs_f64() < 0.5, "{:?}", t.elapsed());
        assert_eq!(off_thread(&AtomicBool::new(false), || 7).unwrap(), 7);
    }

    #[test]
    fn bytes_pack_into_reals_and_back() {
        let bytes: Vec<u8> = (0..=255u8).chain(0..7).collect();
        let need = Need::new("save", 0, "");
        let packed = pack(&bytes, &need).unwrap();
        assert!(packed.iter().all(|w| w.is_finite() && w.fract() == 0.0));
        assert_eq!(unpack(&packed, bytes.len() as Real, &need).unwrap().unwrap(), bytes);
        assert!(unpack(&packed, (bytes.len() + 100) as Real, &need).unwrap().is_none());
        assert!(unpack(&[0.5], 1.0, &need).unwrap().is_none());
    }

    #[test]
    fn a_ball_falls_freely_and_a_restore_returns_bit_for_bit() {
        let mut b = Bodies2::new("bodies");
        b.add_group(group(2, "ball", &[0.0, 10.0], &[0.1])).unwrap();
        b.set(&crate::systems::WorldSetting::Gravity([0.0, -9.81, 0.0]));
        let stop = AtomicBool::new(false);
        let snap = b.snapshot().unwrap();
        let dt = 1e-3;
        for _ in 0..1000 {
            b.step(dt, &stop).unwrap();
        }
        let y = b.fields(&["y"]).unwrap()[0][0];
        // Free fall, y0 − g t²/2 at t = 1 s, to the first order in dt of rapier's integrator.
        assert!((y - (10.0 - 9.81 / 2.0)).abs() < 9.81 * dt, "{y}");
        // The books balance: kinetic + potential + residual as at the start.
        let e = b.energy();
        assert!((e.total() - 1000.0 * std::f64::consts::PI * 0.01 * 9.81 * 10.0).abs() < 1e-6, "{e:?}");
        b.restore(snap);
        assert_eq!(b.fields(&["y"]).unwrap()[0][0], 10.0);
    }

    #[test]
    fn a_ball_falls_freely_in_3d_and_its_books_balance() {
        let mut b = Bodies3::new("bodies");
        b.add_group(group(3, "ball", &[0.0, 0.0, 10.0], &[0.1])).unwrap();
        b.set(&crate::systems::WorldSetting::Gravity([0.0, 0.0, -9.81]));
        let stop = AtomicBool::new(false);
        let snap = b.snapshot().unwrap();
        let dt = 1e-3;
        for _ in 0..1000 {
            b.step(dt, &stop).unwrap();
        }
        let z = b.fields(&["z"]).unwrap()[0][0];
        assert!((z - (10.0 - 9.81 / 2.0)).abs() < 9.81 * dt, "{z}");
        let mass = 1000.0 * 4.0 / 3.0 * std::f64::consts::PI * 0.001;
        let e = b.energy();
        assert!((e.total() - mass * 9.81 * 10.0).abs() < 1e-6, "{e:?}");
        b.restore(snap);
        assert_eq!(b.fields(&["z"]).unwrap()[0][0], 10.0);
    }

    /// A 2D capsule's moment of inertia is the stadium's, each half-disc's centroid 4r/(3π)
    /// from its flat side (parry2d's is a hemisphere's 3r/8: 1.9 % low here); a 3D capsule's
    /// moments come in the body's axes, the axial one (x) first, each hemisphere's centroid
    /// 3r/8 from its flat side (parallel axes).
    #[test]
    fn capsules_have_their_exact_inertia_in_their_own_axes() {
        let (l, r, rho, pi) = (0.2, 0.1, 1000.0, std::f64::consts::PI);
        let mut b = Bodies2::new("bodies");
        b.add_group(group(2, "capsule", &[0.0, 0.0], &[l, r])).unwrap();
        let (m_rect, m_disc) = (rho * 4.0 * l * r, rho * pi * r * r);
        let d = 4.0 * r / (3.0 * pi);
        let stadium = m_rect * (4.0 * l * l + 4.0 * r * r) / 12.0 + m_disc * (0.5 * r * r + l * l + 2.0 * l * d);
        let i = b.fields(&["inertia"]).unwrap()[0][0];
        assert!((i / stadium - 1.0).abs() < 1e-12, "{i} against {stadium}");
        let mut b = Bodies3::new("bodies");
        b.add_group(group(3, "capsule", &[0.0; 3], &[l, r])).unwrap();
        let (m_cyl, m_ball) = (rho * pi * r * r * 2.0 * l, rho * 4.0 / 3.0 * pi * r * r * r);
        let axial = 0.5 * m_cyl * r * r + 0.4 * m_ball * r * r;
        let across = m_cyl * (3.0 * r * r + 4.0 * l * l) / 12.0 + m_ball * (0.4 * r * r + l * l + 0.75 * l * r);
        let i = b.fields(&["ix", "iy", "iz"]).unwrap();
        for (got, want) in i.iter().zip([axial, across, across]) {
            assert!((got[0] / want - 1.0).abs() < 1e-12, "{i:?} against {:?}", [axial, across, across]);
        }
    }

    /// A free brick tumbling about no principal axis keeps its angular momentum in the world,
    /// R I Rᵀ ω, to rounding (each substep's turn is the Cayley rotation of the implicit
    /// midpoint rule's step of L; turning about the end-of-step ω let it turn at first order).
    #[test]
    fn a_tumbling_brick_keeps_its_angular_momentum_in_the_world() {
        let mut b = Bodies3::new("bodies");
        let mut p = group(3, "box", &[0.0; 3], &[0.2, 0.1, 0.05]);
        p.insert("angular_velocities", Value::Floats(vec![1.0, 3.0, 2.0]));
        b.add_group(p).unwrap();
        let momentum = |b: &Bodies3| {
            let f = b.fields(&["qx", "qy", "qz", "qw", "wx", "wy", "wz", "ix", "iy", "iz"]).unwrap();
            let q = glam::DQuat::from_xyzw(f[0][0], f[1][0], f[2][0], f[3][0]);
            let (w, i) = (glam::DVec3::new(f[4][0], f[5][0], f[6][0]), glam::DVec3::new(f[7][0], f[8][0], f[9][0]));
            q * (i * (q.inverse() * w))
        };
        let (stop, l0) = (AtomicBool::new(false), momentum(&b));
        for _ in 0..2000 {
            b.step(1e-3, &stop).unwrap();
        }
        let drift = (momentum(&b) - l0).length() / l0.length();
        assert!(drift < 1e-12, "{drift:e}");
    }

    #[test]
    fn bad_groups_are_refused_by_name() {
        let mut b = Bodies2::new("bodies");
        let e = b.add_group(group(2, "blob", &[0.0, 0.0], &[0.1])).unwrap_err();
        assert!(e.to_string().contains("shape"), "{e}");
        let e = b.add_group(group(2, "ball", &[0.0, 0.0], &[-1.0])).unwrap_err();
        assert!(e.to_string().contains("size"), "{e}");
        for bad in [-0.1, Real::NAN, Real::INFINITY] {
            let p = group(2, "ball", &[0.0, 0.0], &[0.1]).with("rolling_friction", Value::Number(bad));
            let e = b.add_group(p).unwrap_err();
            assert!(e.to_string().contains("rolling_friction"), "{e}");
        }
        assert!(b.is_empty());
        let mut b = Bodies3::new("bodies");
        let e = b.add_group(group(3, "box", &[0.0, 0.0, 0.0], &[0.1, 0.1])).unwrap_err();
        assert!(e.to_string().contains("size"), "{e}");
        let mut p = group(3, "box", &[0.0, 0.0, 0.0], &[0.1, 0.1, 0.1]);
        p.insert("orientations", Value::Floats(vec![0.0; 4]));
        let e = b.add_group(p).unwrap_err();
        assert!(e.to_string().contains("orientations"), "{e}");
        assert!(b.is_empty());
    }
}
