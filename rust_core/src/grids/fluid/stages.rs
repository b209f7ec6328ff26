//! The stages of a step (`STAGES`): the sources' seeds, forces (buoyancy, vorticity confinement),
//! sources, advection of the scalars and the velocity, implicit viscosity, the pressure
//! projection, and the tracers.
use super::*;

impl StableFluid {
    /// A position for tracer `k` at step `step`: a hash of both picks a cell of the first
    /// source (or, without sources or if `anywhere`, of the fluid) and a point in it.
    pub(super) fn seed(&self, k: usize, step: u64, anywhere: bool) -> (Real, Real) {
        let (nx, dx) = (self.nx, self.dx);
        let mut h = hash((k as u64) ^ hash(step));
        let src = self.cfg.sources.first().filter(|s| !s.cells.is_empty() && !anywhere);
        let mut pick = (0.5 * dx, 0.5 * dx);
        for _ in 0..64 {
            let c = match src {
                Some(s) => s.cells[(h % s.cells.len() as u64) as usize].0,
                None => (h % (nx * self.ny) as u64) as usize,
            };
            let (h1, h2) = (hash(h ^ 1), hash(h ^ 2));
            pick = (((c % nx) as Real + unit(h1)) * dx, ((c / nx) as Real + unit(h2)) * dx);
            if self.fluid[c] > 0.0 {
                break;
            }
            h = hash(h);
        }
        pick
    }

    /// Advects density and temperature by the current velocity (one backtrace serves both).
    pub(super) fn advect_scalars(&mut self, dt: Real) {
        let (_, _, lay) = self.lays();
        let (nx, dx) = (self.nx, self.dx);
        let ambient = self.cfg.ambient_temperature;
        let before = self.smoke_amount();
        let vel = self.vel(&self.s.u, &self.s.v);
        let src = [&self.s.density[..], &self.s.temperature[..]];
        let fluid = &self.fluid;
        let pass = |hat: Option<[&[Real]; 2]>, d: &mut [Real], t: &mut [Real]| {
            each_row2(d, t, nx, |j, d, t| {
                lanes::run(lanes::SmokeRow { vel: &vel, dx, lay, fluid, ambient, src, hat, dt, j, out: [d, t] })
            })
        };
        if self.cfg.advection == Advection::MacCormack {
            pass(None, &mut self.fx, &mut self.fy);
            pass(Some([&self.fx, &self.fy]), &mut self.c2, &mut self.wz);
        } else {
            pass(None, &mut self.c2, &mut self.wz);
        }
        std::mem::swap(&mut self.s.density, &mut self.c2);
        std::mem::swap(&mut self.s.temperature, &mut self.wz);
        self.s.books.smoke_advection += self.smoke_amount() - before;
    }

    /// Sources blend density, temperature and face velocities towards their values.
    pub(super) fn apply_sources(&mut self) {
        let (nx, da) = (self.nx, self.dx * self.dx);
        let s = &mut self.s;
        for src in &self.cfg.sources {
            for &(c, w) in &src.cells {
                if self.fluid[c] == 0.0 {
                    continue;
                }
                let d = w * (src.density - s.density[c]);
                s.density[c] += d;
                s.books.injected += d * da;
                s.temperature[c] += w * (src.temperature - s.temperature[c]);
                let (i, j) = (c % nx, c / nx);
                for k in [i + (nx + 1) * (j + 1), i + 1 + (nx + 1) * (j + 1)] {
                    s.u[k] += self.u_open[k] * w * (src.velocity[0] - s.u[k]);
                }
                for k in [(i + 1) + (nx + 2) * j, (i + 1) + (nx + 2) * (j + 1)] {
                    s.v[k] += self.v_open[k] * w * (src.velocity[1] - s.v[k]);
                }
            }
        }
    }

    /// Buoyancy and vorticity confinement, over dt.
    pub(super) fn apply_forces(&mut self, dt: Real) {
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let (alpha, beta, amb, eps) =
            (self.cfg.buoyancy_alpha, self.cfg.buoyancy_beta, self.cfg.ambient_temperature, self.cfg.vorticity);
        let confine = eps > 0.0;
        if confine {
            let (u, v) = (&self.s.u, &self.s.v);
            let uc = |i: usize, j: usize| 0.5 * (u[i + (nx + 1) * (j + 1)] + u[i + 1 + (nx + 1) * (j + 1)]);
            let vc = |i: usize, j: usize| 0.5 * (v[(i + 1) + (nx + 2) * j] + v[(i + 1) + (nx + 2) * (j + 1)]);
            // Centred differences inside, one-sided at the walls (nx, ny ≥ 3: `validate`);
            // reciprocals, not divisions (the divider bounded these loops).
            let (centred, one_sided) = (0.5 / dx, 1.0 / dx);
            let inv = |d: usize| if d == 2 { centred } else { one_sided };
            let last = nx - 1;
            each_row(&mut self.wz, nx, |j, row| {
                let (j0, j1) = (j.saturating_sub(1), (j + 1).min(ny - 1));
                let hy = inv(j1 - j0);
                let cell = |i: usize, i0: usize, i1: usize, hx: Real| {
                    (vc(i1, j) - vc(i0, j)) * hx - (uc(i, j1) - uc(i, j0)) * hy
                };
                row[0] = cell(0, 0, 1, one_sided);
                for i in 1..last {
                    row[i] = cell(i, i - 1, i + 1, centred);
                }
                row[last] = cell(last, last - 1, last, one_sided);
            });
            let wz = &self.wz;
            let fy = &mut self.fy;
            each_row2(&mut self.fx, fy, nx, |j, fx, fy| {
                let (j0, j1) = (j.saturating_sub(1), (j + 1).min(ny - 1));
                let hy = inv(j1 - j0);
                let (w0, wc, w1) =
                    (&wz[nx * j0..nx * (j0 + 1)], &wz[nx * j..nx * (j + 1)], &wz[nx * j1..nx * (j1 + 1)]);
                let force = |i: usize, i0: usize, i1: usize, hx: Real| {
                    let ex = (wc[i1].abs() - wc[i0].abs()) * hx;
                    let ey = (w1[i].abs() - w0[i].abs()) * hy;
                    let k = eps * dx * wc[i] / ((ex * ex + ey * ey).sqrt() + 1e-300);
                    (k * ey, -k * ex)
                };
                (fx[0], fy[0]) = force(0, 0, 1, one_sided);
                for i in 1..last {
                    (fx[i], fy[i]) = force(i, i - 1, i + 1, centred);
                }
                (fx[last], fy[last]) = force(last, last - 1, last, one_sided);
            });
            let (fx, open) = (&self.fx, &self.u_open);
            rows_sum(&mut self.s.u[nx + 1..(nx + 1) * (ny + 1)], nx + 1, |j, row| {
                let f = &fx[nx * j..nx * (j + 1)];
                let m = &open[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                for i in 1..nx {
                    row[i] += m[i] * dt * 0.5 * (f[i - 1] + f[i]);
                }
                0.0
            });
        }
        if confine || alpha != 0.0 || beta != 0.0 {
            let (fy, open, rho, t) = (&self.fy, &self.v_open, &self.s.density, &self.s.temperature);
            rows_sum(&mut self.s.v[..(nx + 2) * (ny + 1)], nx + 2, |j, row| {
                if j == 0 || j == ny {
                    return 0.0;
                }
                let m = &open[(nx + 2) * j + 1..(nx + 2) * j + 1 + nx];
                let (r0, r1) = (&rho[nx * (j - 1)..nx * j], &rho[nx * j..nx * (j + 1)]);
                let (t0, t1) = (&t[nx * (j - 1)..nx * j], &t[nx * j..nx * (j + 1)]);
                let row = &mut row[1..1 + nx];
                for i in 0..nx {
                    let b = -alpha * 0.5 * (r0[i] + r1[i]) + beta * (0.5 * (t0[i] + t1[i]) - amb);
                    row[i] += m[i] * dt * b;
                }
                if confine {
                    let (f0, f1) = (&fy[nx * (j - 1)..nx * j], &fy[nx * j..nx * (j + 1)]);
                    for i in 0..nx {
                        row[i] += m[i] * dt * 0.5 * (f0[i] + f1[i]);
                    }
                }
                0.0
            });
        }
    }

    /// The share of the last step's pressure that acts at the departure point of this step's
    /// characteristics and is kept as the start of the new pressure (see [`Projection`]).
    pub(super) fn departure_share(&self) -> Real {
        match self.cfg.projection {
            Projection::Chorin => 0.0,
            Projection::Incremental => 0.5,
        }
    }

    /// Advects the velocity by itself. With the incremental projection, what is advected is
    /// u − ½dt·∇p (p the last step's pressure, on the open faces, with the projection's own
    /// differences), while the paths are traced through u itself (divergence-free).
    pub(super) fn advect_velocity(&mut self, dt: Real) {
        let (lu, lv, _) = self.lays();
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let bounds = Bounds::of(&self.cfg, &self.inflow_u);
        let mc = self.cfg.advection == Advection::MacCormack;
        let au = Active { lay: lu, kind: Node::U, a0: 0, a1: nx + 1, b0: 1, b1: ny + 1, mask: &self.u_open, fill: 0.0 };
        let av = Active { lay: lv, kind: Node::V, a0: 1, a1: nx + 1, b0: 0, b1: ny + 1, mask: &self.v_open, fill: 0.0 };
        let share = self.departure_share();
        let vel = self.vel(&self.s.u, &self.s.v);
        // The fields to advect: u and v, or u − ½dt·∇p in the projection's scratch (`rhs`, `q`:
        // (nx+2)(ny+2) values each, more than either face layout; the projection refills them).
        let (src_u, src_v): (&[Real], &[Real]) = if share > 0.0 {
            let (ku, kv) = (&mut self.rhs[..lu.w * lu.h], &mut self.q[..lv.w * lv.h]);
            kick_faces(&self.s, [&self.u_open, &self.v_open], [nx, ny], share * dt / dx, [&mut *ku, &mut *kv]);
            fill_u_ghosts(ku, nx, ny, bounds);
            fill_v_ghosts(kv, nx, ny, bounds);
            (ku, kv)
        } else {
            (&self.s.u, &self.s.v)
        };
        if mc {
            let hat = &mut self.hat[..lu.w * lu.h];
            advect_faces(&vel, dx, &au, src_u, None, dt, hat);
            fill_u_ghosts(hat, nx, ny, bounds);
            advect_faces(&vel, dx, &au, src_u, Some(hat), dt, &mut self.u2);
            let hat = &mut self.hat[..lv.w * lv.h];
            advect_faces(&vel, dx, &av, src_v, None, dt, hat);
            fill_v_ghosts(hat, nx, ny, bounds);
            advect_faces(&vel, dx, &av, src_v, Some(hat), dt, &mut self.v2);
        } else {
            advect_faces(&vel, dx, &au, src_u, None, dt, &mut self.u2);
            advect_faces(&vel, dx, &av, src_v, None, dt, &mut self.v2);
        }
        std::mem::swap(&mut self.s.u, &mut self.u2);
        std::mem::swap(&mut self.s.v, &mut self.v2);
        self.fill_ghosts_uv();
    }

    /// Backward-Euler viscosity, per component. `None` if stopped.
    pub(super) fn diffuse(&mut self, dt: Real, stop: &AtomicBool) -> Option<()> {
        let (nx, ny) = (self.nx, self.ny);
        let s = self.cfg.viscosity * dt / (self.dx * self.dx);
        let slip = self.slip_scale(dt, s);
        let Some(visc) = self.visc.as_mut() else { return Some(()) };
        if s != self.visc_scale {
            visc[0].stencil_mut().set_scale(s);
            visc[1].stencil_mut().set_scale(s);
            self.visc_scale = s;
        }
        let (tol, maxit) = (self.cfg.tolerance, self.cfg.max_iterations);
        let lid = self.cfg.lid.unwrap_or(0.0);
        let mut iters = 0;
        let (p, wp) = (&self.s.pressure, nx + 2);
        // u: unknown (i, j), i in 0..=nx, j in 0..ny, at padded (i+1) + (nx+3)(j+1).
        {
            let (x, b, u, open, u_walls) =
                (&mut self.vx[0], &mut self.vb[0], &mut self.s.u, &self.u_open, &self.u_walls);
            let (w, wu) = (nx + 3, nx + 1);
            let lid_term = if self.cfg.no_slip { 2.0 * s * lid } else { 0.0 };
            let inflow = !self.inflow_u.is_empty();
            crate::grids::rows2_sum(&mut x[w..w * (ny + 1)], &mut b[w..w * (ny + 1)], w, |j, x, b| {
                let src = &u[wu * (j + 1)..wu * (j + 2)];
                x[1..wu + 1].copy_from_slice(src);
                b[1..wu + 1].copy_from_slice(src);
                if inflow {
                    // The held inflow face is the next face's Dirichlet neighbour.
                    b[2] += open[wu * (j + 1) + 1] * s * src[0];
                }
                let m = &open[wu * (j + 1)..wu * (j + 2)];
                // The walls' value of u*: the slip the projection will take back
                // (`slip_scale`), from the pressure difference along the face's row, and the
                // lid's speed.
                let (nw, pr) = (&u_walls[wu * (j + 1)..wu * (j + 2)], &p[wp * (j + 1)..wp * (j + 2)]);
                for i in 0..wu {
                    b[i + 1] += nw[i] * slip * (pr[i + 1] - pr[i]);
                }
                if j == ny - 1 {
                    for i in 0..wu {
                        b[i + 1] += m[i] * lid_term;
                    }
                }
                0.0
            });
            iters += visc[0].solve(x, b, tol, maxit, stop)?.iterations;
            rows_sum(&mut u[wu..wu * (ny + 1)], wu, |j, row| {
                row.copy_from_slice(&x[w * (j + 1) + 1..w * (j + 1) + 1 + wu]);
                0.0
            });
        }
        // v: unknown (i, j), i in 0..nx, j in 0..=ny, at padded (i+1) + (nx+2)(j+1).
        {
            let (x, b, v, v_walls) = (&mut self.vx[1], &mut self.vb[1], &mut self.s.v, &self.v_walls);
            let w = nx + 2;
            crate::grids::rows2_sum(&mut x[w..w * (ny + 2)], &mut b[w..w * (ny + 2)], w, |j, x, b| {
                let src = &v[w * j + 1..w * j + 1 + nx];
                x[1..nx + 1].copy_from_slice(src);
                b[1..nx + 1].copy_from_slice(src);
                if j > 0 && j < ny {
                    // As for u (the rows of the closed faces j = 0 and ny have no walls).
                    let (nw, ps, pn) = (&v_walls[w * j + 1..w * j + 1 + nx], &p[wp * j + 1..], &p[wp * (j + 1) + 1..]);
                    for i in 0..nx {
                        b[i + 1] += nw[i] * slip * (pn[i] - ps[i]);
                    }
                }
                0.0
            });
            iters += visc[1].solve(x, b, tol, maxit, stop)?.iterations;
            rows_sum(&mut v[..w * (ny + 1)], w, |j, row| {
                row[1..nx + 1].copy_from_slice(&x[w * (j + 1) + 1..w * (j + 1) + 1 + nx]);
                0.0
            });
        }
        self.s.books.viscosity_iterations = iters;
        self.fill_ghosts_uv();
        Some(())
    }

    /// The viscous solve's wall term for the slip the projection makes, per no-slip wall along
    /// a face (`u_walls`, `v_walls`) and per unit pressure difference along it:
    /// 2s·(1 − share)·dt/dx. The projection subtracts dt·∇π from u*, π ≈ (1 − share)·p (exact
    /// for a steady pressure), so a wall value u*_w = 0 would leave −(1 − share)·dt·∂p/∂τ on
    /// the wall after it, an O(dt) slip that moves the steady state (a Poiseuille flow's
    /// pressure gradient 28 % low at Re 1, cfl 1). The wall value of u* is therefore
    /// (1 − share)·dt·∂p/∂τ, from the last step's pressure (Kim & Moin, J. Comput. Phys. 59
    /// (1985) 308; the ghost −u + 2u_w adds 2s·u_w to the right-hand side).
    fn slip_scale(&self, dt: Real, s: Real) -> Real {
        2.0 * s * (1.0 - self.departure_share()) * dt / self.dx
    }

    /// Makes the velocity divergence-free: solves ∇²p = ∇·u/dt (Neumann at walls and
    /// obstacles), u −= dt·∇p. The pressure is kept as the next solve's start. `None` if stopped.
    pub fn project(&mut self, dt: Real, stop: &AtomicBool) -> Option<Solve> {
        self.project_keeping(dt, 0.0, stop)
    }

    /// `project`, where a share `keep` of the last pressure p already acted at the departure
    /// points (`advect_velocity`): solves for π (started at (1 − keep)·p, which is exact for a
    /// steady pressure) and keeps keep·p + π as the pressure.
    pub(super) fn project_keeping(&mut self, dt: Real, keep: Real, stop: &AtomicBool) -> Option<Solve> {
        let (nx, ny, dx) = (self.nx, self.ny, self.dx);
        let w = nx + 2;
        // rhs = −(unnormalised divergence); q = p·dt/dx (the solve's unknown).
        {
            let (u, v, fl) = (&self.s.u, &self.s.v, &self.fluid);
            rows_sum(&mut self.rhs[w..w * (ny + 1)], w, |j, row| {
                let ur = &u[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                let (vs, vn) = (&v[w * j + 1..w * j + 1 + nx], &v[w * (j + 1) + 1..w * (j + 1) + 1 + nx]);
                let f = &fl[nx * j..nx * (j + 1)];
                let row = &mut row[1..1 + nx];
                for i in 0..nx {
                    row[i] = -f[i] * ((ur[i + 1] - ur[i]) + (vn[i] - vs[i]));
                }
                0.0
            });
        }
        let scale = dt / dx;
        let start = (1.0 - keep) * scale;
        for (q, p) in self.q.iter_mut().zip(&self.s.pressure) {
            *q = p * start;
        }
        let solve = self.pressure.solve(&mut self.q, &self.rhs, self.cfg.tolerance, self.cfg.max_iterations, stop)?;
        {
            let (q, open) = (&self.q, &self.u_open);
            rows_sum(&mut self.s.u[nx + 1..(nx + 1) * (ny + 1)], nx + 1, |j, row| {
                let qr = &q[w * (j + 1)..w * (j + 2)];
                let m = &open[(nx + 1) * (j + 1)..(nx + 1) * (j + 2)];
                for i in 0..=nx {
                    row[i] = m[i] * (row[i] - (qr[i + 1] - qr[i]));
                }
                0.0
            });
            let open = &self.v_open;
            rows_sum(&mut self.s.v[..w * (ny + 1)], w, |j, row| {
                if j == 0 || j == ny {
                    return 0.0;
                }
                let (qs, qn) = (&q[w * j..w * (j + 1)], &q[w * (j + 1)..w * (j + 2)]);
                let m = &open[w * j..w * (j + 1)];
                for i in 1..=nx {
                    row[i] = m[i] * (row[i] - (qn[i] - qs[i]));
                }
                0.0
            });
        }
        let inv = 1.0 / scale;
        for (p, q) in self.s.pressure.iter_mut().zip(&self.q) {
            *p = keep * *p + q * inv;
        }
        self.s.books.pressure = solve;
        self.fill_ghosts_uv();
        Some(solve)
    }

    /// Moves the tracers by RK2 through the velocity; re-seeds those that leave or hit a solid.
    pub(super) fn move_tracers(&mut self, dt: Real) {
        if self.s.tracers.is_empty() {
            return;
        }
        let mut tr = std::mem::take(&mut self.s.tracers);
        let (nx, ny, inv) = (self.nx, self.ny, 1.0 / self.dx);
        let step = self.s.steps;
        {
            let vel = self.vel(&self.s.u, &self.s.v);
            let me = &*self;
            par::chunks1(&mut tr, |start, chunk| {
                for (k, p) in chunk.chunks_exact_mut(2).enumerate() {
                    let (x, y) = (p[0], p[1]);
                    let (a, b) = vel.at(x, y);
                    let (xm, ym) = vel.clamp(x + 0.5 * dt * a, y + 0.5 * dt * b);
                    let (a, b) = vel.at(xm, ym);
                    let (xn, yn) = (x + dt * a, y + dt * b);
                    let inside = xn >= 0.0 && yn >= 0.0 && xn < vel.xmax && yn < vel.ymax;
                    let ok = inside && {
                        let (i, j) = (((xn * inv) as usize).min(nx - 1), ((yn * inv) as usize).min(ny - 1));
                        me.fluid[i + nx * j] > 0.0
                    };
                    let (xn, yn) = if ok { (xn, yn) } else { me.seed(start / 2 + k, step, false) };
                    p[0] = xn;
                    p[1] = yn;
                }
            });
        }
        self.s.tracers = tr;
    }
}

/// ku = u − h·Δp and kv = v − h·Δp on the open faces of `s` (h = share·dt/dx; Δp the
/// difference of the padded pressure across each face, as `project` takes it); ghosts are
/// left to the caller.
fn kick_faces(s: &State, [u_open, v_open]: [&[Real]; 2], [nx, ny]: [usize; 2], h: Real, [ku, kv]: [&mut [Real]; 2]) {
    let (u, v, p) = (&s.u, &s.v, &s.pressure);
    let (wu, w) = (nx + 1, nx + 2);
    each_row(ku, wu, |b, row| {
        let src = &u[wu * b..wu * (b + 1)];
        if b == 0 || b > ny {
            row.copy_from_slice(src);
            return;
        }
        let (m, pr) = (&u_open[wu * b..wu * (b + 1)], &p[w * b..w * (b + 1)]);
        for i in 0..wu {
            row[i] = src[i] - m[i] * h * (pr[i + 1] - pr[i]);
        }
    });
    each_row(kv, w, |j, row| {
        let src = &v[w * j..w * (j + 1)];
        if j == 0 || j == ny {
            row.copy_from_slice(src);
            return;
        }
        let (m, ps, pn) = (&v_open[w * j..w * (j + 1)], &p[w * j..w * (j + 1)], &p[w * (j + 1)..w * (j + 2)]);
        for i in 0..w {
            row[i] = src[i] - m[i] * h * (pn[i] - ps[i]);
        }
    });
}
