//! Adaptive Dormand–Prince RK5(4) ("dopri5"; Dormand & Prince 1980, J. Comput. Appl. Math. 6, 19,
//! Table 2; Hairer, Nørsett & Wanner, Solving ODEs I, §II.4–5, the DOPRI5 code).
//!
//! One `step(dt)` integrates exactly `dt` in as many internal steps `h` as the error control
//! needs, landing on the end of `dt`. The 5th-order solution is propagated (local
//! extrapolation); the embedded 4th-order one gives the error estimate
//!   err = max_i |h Σ_j e_j k_j|_i / (atol + rtol · max(|y0|_i, |y1|_i)),   accept if err ≤ 1,
//! over every component i of every position and velocity. The max norm (not DOPRI5's RMS) is
//! used because in a particle system the error lives in a few particles (a close encounter) and
//! an RMS over millions would hide it; a max is also independent of the reduction order.
//!
//! Step-size control: the PI controller of Gustafsson (Hairer & Wanner, Solving ODEs II, §IV.2,
//! eq. 2.43c), h' = h · clamp(0.9 · err^−0.17 · err_prev^0.04, 0.2, 10), with no growth right
//! after a rejection. The first h comes from Hairer's starting-step heuristic (ODEs I, §II.4).
//! Seven stages, "first same as last": 6 force evaluations per accepted step.
//!
//! One output step may take thousands of internal steps, so `step_interruptible` reads its stop
//! flag before every attempt (accepted or not): a relaxed atomic load, which changes no result.
use super::{
    accel, bad, ensure_len, store, try_copy, Adaptive, Cache, Carry, Integrator, IntegratorInfo, Particles, Stopped,
};
use crate::ode;
use crate::par;
use crate::vector::{Real, Vector};
use std::collections::TryReserveError;
use std::sync::atomic::{AtomicBool, Ordering};

// The tableau (a, e = b − b̂) is the ODE layer's; stage 7's row of `a` is b (FSAL).
const A: [[Real; ode::MAX_STAGES]; ode::MAX_STAGES] = ode::DOPRI5.a;
const E: [Real; ode::MAX_STAGES] = match ode::DOPRI5.e {
    Some(e) => e,
    None => panic!("Dormand–Prince has an embedded estimate"),
};
const SAFETY: Real = 0.9;
const FAC_MIN: Real = 0.2;
const FAC_MAX: Real = 10.0;
const ALPHA: Real = 0.17; // 1/5 − 0.75 β
const BETA: Real = 0.04;
/// Consecutive rejections after which the step is given up (the error cannot be controlled,
/// e.g. non-finite forces): h has then shrunk by at least 0.2^40 ≈ 1e-28.
const MAX_REJECTS: u32 = 40;

pub struct Dopri5<V: Vector> {
    pub rtol: Real,
    pub atol: Real,
    /// Stage derivatives: kx[j] = velocity, kv[j] = acceleration at stage j.
    kx: [Vec<V>; 7],
    kv: [Vec<V>; 7],
    /// Stage positions.
    xs: Vec<V>,
    f: Vec<V>,
    /// Term powers at each stage (dissipation books).
    pw: [Vec<Real>; 7],
    /// kx[0], kv[0], pw[0] hold the derivative at the current state (FSAL).
    fsal: bool,
    /// Next internal step (s); 0 until the first step picks one.
    h: Real,
    err_prev: Real,
    pub accepted: u64,
    pub rejected: u64,
    /// Particle with the largest error when the step size could not be controlled.
    failed: Option<usize>,
}

impl<V: Vector> Default for Dopri5<V> {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-9,
            kx: Default::default(),
            kv: Default::default(),
            xs: Vec::new(),
            f: Vec::new(),
            pw: Default::default(),
            fsal: false,
            h: 0.0,
            err_prev: 1e-4,
            accepted: 0,
            rejected: 0,
            failed: None,
        }
    }
}

/// Per-component error scale atol + rtol·max(|a|, |b|).
#[inline(always)]
fn scaled_max<V: Vector>(e: V, a: V, b: V, rtol: Real, atol: Real) -> Real {
    let mut m: Real = 0.0;
    for k in 0..V::DIM {
        let sc = atol + rtol * a.comp(k).abs().max(b.comp(k).abs());
        // A zero error is within any tolerance, even a zero one (atol = 0 on a pinned particle).
        let ek = e.comp(k).abs();
        let r = if ek == 0.0 { 0.0 } else { ek / sc };
        // NaN-propagating max: a non-finite error must reject the step.
        m = if r.is_nan() || r > m { r } else { m };
    }
    m
}

fn max_combine(a: Real, b: Real) -> Real {
    if a.is_nan() || b.is_nan() {
        Real::NAN
    } else {
        a.max(b)
    }
}

impl<V: Vector> Dopri5<V> {
    /// Derivative at the current state into stage 0.
    fn first_stage(&mut self, sys: &mut Particles<V>) {
        sys.forces.eval(&sys.state.x, &sys.state.v, &sys.model, &mut self.f);
        self.pw[0].clear();
        self.pw[0].extend_from_slice(sys.forces.last_power());
        let (f, im, g, v0) = (&self.f, &sys.model.inv_mass, sys.forces.g, &sys.state.v);
        let (kx, kv) = (&mut self.kx[0], &mut self.kv[0]);
        par::chunks2(kx, kv, |s, kx, kv| {
            for k in 0..kx.len() {
                let i = s + k;
                kx[k] = v0[i];
                kv[k] = accel(f[i], im[i], g);
            }
        });
        self.fsal = true;
    }

    /// Stage `S` (1..=6) at x0 + h Σ_j A[S][j] k_j; converts the forces of stage S−1 (in `f`)
    /// to accelerations in the same pass (stage 0's are converted by `first_stage`). `S` is a
    /// constant so the sum over j unrolls with the tableau folded in.
    fn stage<const S: usize>(&mut self, sys: &mut Particles<V>, h: Real) {
        let s = S;
        let (im, g) = (&sys.model.inv_mass, sys.forces.g);
        let (x0, v0) = (&sys.state.x, &sys.state.v);
        let f = &self.f;
        let convert = s >= 2;
        let (kx_lo, kx_hi) = self.kx.split_at_mut(s);
        let (kv_lo, kv_hi) = self.kv.split_at_mut(s - 1);
        let a = A[s];
        par::chunks3(&mut self.xs, &mut kx_hi[0], &mut kv_hi[0], |st, xs, vs, kv_prev| {
            for k in 0..xs.len() {
                let i = st + k;
                if convert {
                    kv_prev[k] = accel(f[i], im[i], g);
                }
                let (mut dx, mut dv) = (kx_lo[0][i] * a[0], V::ZERO);
                for j in 1..S {
                    if a[j] != 0.0 {
                        dx += kx_lo[j][i] * a[j];
                    }
                }
                for j in 0..S - 1 {
                    if a[j] != 0.0 {
                        dv += kv_lo[j][i] * a[j];
                    }
                }
                dv += kv_prev[k] * a[S - 1];
                xs[k] = x0[i] + dx * h;
                vs[k] = v0[i] + dv * h;
            }
        });
        sys.forces.eval(&self.xs, &self.kx[s], &sys.model, &mut self.f);
        self.pw[s].clear();
        self.pw[s].extend_from_slice(sys.forces.last_power());
    }

    /// Converts stage 7's forces and returns the scaled error norm (NaN if not finite).
    fn error(&mut self, sys: &Particles<V>, h: Real) -> Real {
        let (im, g) = (&sys.model.inv_mass, sys.forces.g);
        let (x0, v0) = (&sys.state.x, &sys.state.v);
        let (f, xs) = (&self.f, &self.xs);
        let (rtol, atol) = (self.rtol, self.atol);
        let (kx_lo, kx_hi) = self.kx.split_at_mut(6);
        let (kv_lo, kv_hi) = self.kv.split_at_mut(6);
        let v1 = &kx_hi[0];
        par::chunks1_fold(&mut kv_hi[0], 0.0, max_combine, |st, kv7| {
            let mut m: Real = 0.0;
            for k in 0..kv7.len() {
                let i = st + k;
                kv7[k] = accel(f[i], im[i], g);
                let (mut ex, mut ev) = (v1[i] * E[6], kv7[k] * E[6]);
                for j in [0, 2, 3, 4, 5] {
                    ex += kx_lo[j][i] * E[j];
                    ev += kv_lo[j][i] * E[j];
                }
                if bad(xs[i], v1[i]) {
                    return Real::NAN;
                }
                m = max_combine(m, scaled_max(ex * h, x0[i], xs[i], rtol, atol));
                m = max_combine(m, scaled_max(ev * h, v0[i], v1[i], rtol, atol));
            }
            m
        })
    }

    /// Particle of the last attempt with a non-finite or else the largest scaled error (for the
    /// divergence report).
    fn worst_particle(&self, sys: &Particles<V>, h: Real) -> usize {
        let (x0, v0) = (&sys.state.x, &sys.state.v);
        let mut best = (0, Real::NEG_INFINITY);
        for i in 0..x0.len() {
            let (x1, v1) = (self.xs[i], self.kx[6][i]);
            let (mut ex, mut ev) = (V::ZERO, V::ZERO);
            for j in 0..7 {
                ex += self.kx[j][i] * E[j];
                ev += self.kv[j][i] * E[j];
            }
            let e = scaled_max(ex * h, x0[i], x1, self.rtol, self.atol).max(scaled_max(
                ev * h,
                v0[i],
                v1,
                self.rtol,
                self.atol,
            ));
            if bad(x1, v1) || e.is_nan() {
                return i;
            }
            if e > best.1 {
                best = (i, e);
            }
        }
        best.0
    }

    /// Hairer's starting step (Solving ODEs I, §II.4): h with h⁵·|y''| ≈ 0.01 in the error norm.
    /// Costs one force evaluation (not booked: it does not advance the state).
    fn initial_step(&mut self, sys: &mut Particles<V>, span: Real) -> Real {
        let (x0, v0) = (&sys.state.x, &sys.state.v);
        let (rtol, atol) = (self.rtol, self.atol);
        let norm = |a: &[V], b: &[V], sa: &[V], sb: &[V]| -> Real {
            par::reduce(a.len(), 0.0, max_combine, |r| {
                let mut m: Real = 0.0;
                for i in r {
                    m = m
                        .max(scaled_max(a[i], sa[i], sa[i], rtol, atol))
                        .max(scaled_max(b[i], sb[i], sb[i], rtol, atol));
                }
                m
            })
        };
        let d0 = norm(x0, v0, x0, v0);
        let d1 = norm(&self.kx[0], &self.kv[0], x0, v0);
        let mut h0 = if d0 < 1e-5 || d1 < 1e-5 { 1e-6 * span } else { 0.01 * d0 / d1 };
        // A zero atol on a component that starts at 0 makes d1 infinite and h0 zero.
        h0 = if h0 > 1e-10 * span { h0.min(span) } else { 1e-10 * span };
        {
            let (kx_lo, kx_hi) = self.kx.split_at_mut(1);
            let (kx0, kv0) = (&kx_lo[0], &self.kv[0]);
            par::chunks2(&mut self.xs, &mut kx_hi[0], |s, xs, vs| {
                for k in 0..xs.len() {
                    let i = s + k;
                    xs[k] = x0[i] + kx0[i] * h0;
                    vs[k] = v0[i] + kv0[i] * h0;
                }
            });
        }
        // Not booked: this evaluation does not advance the state.
        sys.forces.eval(&self.xs, &self.kx[1], &sys.model, &mut self.f);
        let (im, g, f) = (&sys.model.inv_mass, sys.forces.g, &self.f);
        let (kx0, kx1, kv1) = (&self.kx[0], &self.kx[1], &self.kv[0]);
        let d2 = par::reduce(x0.len(), 0.0, max_combine, |r| {
            let mut m: Real = 0.0;
            for i in r {
                let da = accel(f[i], im[i], g) - kv1[i];
                let dv = kx1[i] - kx0[i];
                m = m.max(scaled_max(dv, x0[i], x0[i], rtol, atol)).max(scaled_max(da, v0[i], v0[i], rtol, atol));
            }
            m
        }) / h0;
        let h1 = if d1.max(d2) <= 1e-15 { (1e-6 * span).max(h0 * 1e-3) } else { (0.01 / d1.max(d2)).powf(0.2) };
        let h = (100.0 * h0).min(h1);
        // Never 0: a first step that is too long is rejected and shrunk by the controller.
        if h.is_finite() && h > 0.0 {
            h.max(1e-10 * span)
        } else {
            h0
        }
    }
}

impl<V: Vector> Integrator<V> for Dopri5<V> {
    fn info(&self) -> IntegratorInfo {
        IntegratorInfo { name: "dopri5", order: 5, symplectic: false, force_evals_per_step: 6 }
    }

    fn step(&mut self, sys: &mut Particles<V>, dt: Real) -> bool {
        let never = AtomicBool::new(false);
        self.step_interruptible(sys, dt, &never).unwrap_or(true)
    }

    fn step_interruptible(&mut self, sys: &mut Particles<V>, dt: Real, stop: &AtomicBool) -> Result<bool, Stopped> {
        let n = sys.state.x.len();
        if self.xs.len() != n {
            self.fsal = false;
        }
        ensure_len(&mut self.xs, n);
        ensure_len(&mut self.f, n);
        for j in 0..7 {
            ensure_len(&mut self.kx[j], n);
            ensure_len(&mut self.kv[j], n);
        }
        self.failed = None;
        if !self.fsal {
            self.first_stage(sys);
        }
        if !(self.h > 0.0) {
            self.h = self.initial_step(sys, dt);
        }
        let mut done: Real = 0.0;
        let mut rejects = 0u32;
        let mut just_rejected = false;
        while done < dt {
            if stop.load(Ordering::Relaxed) {
                return Err(Stopped);
            }
            let left = dt - done;
            // Land exactly on the end of dt; stretch by ≤ 1 % rather than leave a sliver.
            if !(self.h > 0.0) || done + self.h == done {
                // No progress possible (the controller's step underflowed).
                self.failed = Some(0);
                return Ok(true);
            }
            let last = self.h >= left * 0.99;
            let h = if last { left } else { self.h };
            self.stage::<1>(sys, h);
            self.stage::<2>(sys, h);
            self.stage::<3>(sys, h);
            self.stage::<4>(sys, h);
            self.stage::<5>(sys, h);
            self.stage::<6>(sys, h);
            let err = self.error(sys, h);
            if err <= 1.0 {
                // Accept: the new state is stage 7's, whose derivative starts the next step.
                for (j, b) in ode::DOPRI5.b[..6].iter().enumerate() {
                    sys.forces.set_last_power(&self.pw[j]);
                    sys.forces.book_power(h * b);
                }
                std::mem::swap(&mut sys.state.x, &mut self.xs);
                sys.state.v.copy_from_slice(&self.kx[6]);
                if sys.single {
                    // Round only the accepted state: the error estimate must see the smooth
                    // stage 7, not float32 rounding noise (which, times ω² of a stiff spring,
                    // made the controller chase it). The derivative at the rounded state is
                    // then evaluated afresh: 7 evaluations per step instead of 6.
                    let single = true;
                    par::chunks2(&mut sys.state.x, &mut sys.state.v, |_, x, v| {
                        x.iter_mut().chain(v.iter_mut()).for_each(|p| *p = store(*p, single));
                    });
                    self.fsal = false;
                    self.first_stage(sys);
                } else {
                    self.kx.swap(0, 6);
                    self.kv.swap(0, 6);
                    self.pw.swap(0, 6);
                }
                self.accepted += 1;
                done = if last { dt } else { done + h };
                let err_c = err.max(1e-10);
                let mut fac = SAFETY * err_c.powf(-ALPHA) * self.err_prev.powf(BETA);
                fac = fac.clamp(FAC_MIN, if just_rejected { 1.0 } else { FAC_MAX });
                // A shortened landing step says nothing about the next step's size.
                if !last || h >= self.h {
                    self.h = h * fac;
                } else {
                    self.h = self.h.max(h * fac);
                }
                self.err_prev = err_c;
                rejects = 0;
                just_rejected = false;
            } else {
                self.rejected += 1;
                rejects += 1;
                just_rejected = true;
                let fac = if err.is_finite() { (SAFETY * err.powf(-0.2)).max(FAC_MIN) } else { FAC_MIN };
                self.h = h * fac;
                if rejects >= MAX_REJECTS || done + self.h == done {
                    self.failed = Some(self.worst_particle(sys, h));
                    // The FSAL stage is still valid (state unchanged).
                    return Ok(true);
                }
            }
        }
        // The state was checked finite in `error`.
        Ok(false)
    }

    fn last_forces(&self) -> &[V] {
        &self.f
    }

    fn scratch(&mut self, _velocity_dependent: bool) -> Vec<&mut Vec<V>> {
        let mut s: Vec<&mut Vec<V>> = vec![&mut self.xs, &mut self.f];
        s.extend(self.kx.iter_mut().chain(self.kv.iter_mut()));
        s
    }

    fn reset(&mut self) {
        // Keep h: it is still a good guess after a collision or an edit of the state.
        self.fsal = false;
    }

    fn configure(&mut self, o: &super::IntegratorOptions) {
        self.rtol = o.rtol;
        self.atol = o.atol;
    }

    fn as_carry(&self) -> Option<&dyn Carry<V>> {
        Some(self)
    }
    fn as_carry_mut(&mut self) -> Option<&mut dyn Carry<V>> {
        Some(self)
    }
    fn as_adaptive(&self) -> Option<&dyn Adaptive> {
        Some(self)
    }
    fn as_adaptive_mut(&mut self) -> Option<&mut dyn Adaptive> {
        Some(self)
    }
}

impl<V: Vector> Carry<V> for Dopri5<V> {
    /// The derivative at the current state (accelerations) and, after the stage-0 powers, the
    /// controller's memory (next h, last error), so a saved run continues bit for bit. Without
    /// a derivative there are no forces and no powers, only the controller's memory.
    fn get(&self) -> Option<(Vec<V>, Vec<Real>)> {
        let mut p = if self.fsal { self.pw[0].clone() } else { Vec::new() };
        p.extend([self.h, self.err_prev]);
        Some((if self.fsal { self.kv[0].clone() } else { Vec::new() }, p))
    }

    fn try_get(&self) -> Result<Option<Cache<V>>, TryReserveError> {
        let f = if self.fsal { try_copy(&self.kv[0])? } else { Vec::new() };
        let mut p = if self.fsal { self.pw[0].clone() } else { Vec::new() };
        p.extend([self.h, self.err_prev]);
        Ok(Some((f, p)))
    }

    fn set(&mut self, f: Vec<V>, mut p: Vec<Real>, v: &[V], n_terms: usize) -> bool {
        // Without a derivative (`f` empty) the powers are absent (or zeros, in files saved by
        // earlier versions); the controller is restored either way (a rolled-back first call
        // needs it).
        let fits = p.len() == n_terms + 2 || (f.is_empty() && p.len() == 2);
        if !fits || !(f.is_empty() || f.len() == v.len()) {
            return false;
        }
        let k = p.len() - 2;
        self.err_prev = p[k + 1];
        self.h = p[k];
        p.truncate(k);
        self.fsal = !f.is_empty();
        if self.fsal {
            self.kx[0] = v.to_vec();
            self.kv[0] = f;
            self.pw[0] = p;
            self.xs.resize(v.len(), V::ZERO);
        }
        true
    }
}

impl<V: Vector> Adaptive for Dopri5<V> {
    fn stats(&self) -> (u64, u64, Real) {
        (self.accepted, self.rejected, self.h)
    }

    fn set_counts(&mut self, accepted: u64, rejected: u64) {
        self.accepted = accepted;
        self.rejected = rejected;
    }

    fn failure(&self) -> Option<(usize, crate::error::Failure)> {
        self.failed.map(|i| (i, crate::error::Failure::Error))
    }
}
