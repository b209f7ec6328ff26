//! DFSPH's solves (the module's steps 2–4): the velocities gathered into cell order, the
//! divergence and density errors, the warm starts, the Jacobi iterations and the surface
//! forces, and the densities the term reports.
use super::*;

impl<V: Vector> Solver<V> {
    /// Sorted velocities from the scene's `v`, and their kinetic energy (J).
    pub(super) fn gather_v(&mut self, v: &[V]) -> Real {
        let (order, m, free) = (&self.grid.order, &self.m, &self.free);
        let (first, ts) = (self.first, &self.to_scene);
        self.vs.resize(self.n, V::ZERO);
        par::chunks1_sum(&mut self.vs, |s, vs| {
            let mut e = 0.0;
            for (k, vk) in vs.iter_mut().enumerate() {
                *vk = v[Self::at(first, ts, order[s + k] as usize)];
                // Pinned particles carry no kinetic energy in the books (`ParticleSystem::energy`).
                if free[s + k] {
                    e += 0.5 * m[s + k] * vk.length_squared();
                }
            }
            e
        })
    }

    /// Writes the sorted velocities back into the scene's `v`; returns their kinetic energy.
    pub(super) fn scatter_v(&self, v: &mut [V]) -> Real {
        let out = SyncPtr(v.as_mut_ptr());
        let (order, vs, m, free) = (&self.grid.order, &self.vs, &self.m, &self.free);
        let (first, ts) = (self.first, &self.to_scene);
        par::sum(self.n, 0.0, |ks| {
            let mut e = 0.0;
            for k in ks {
                // SAFETY: `order` is a permutation: each particle is written by one sorted slot.
                unsafe { *out.get().add(Self::at(first, ts, order[k] as usize)) = vs[k] };
                if free[k] {
                    e += 0.5 * m[k] * vs[k].length_squared();
                }
            }
            e
        })
    }

    /// One error pass: per sorted particle the error e_i of `stage` at the sorted velocities
    /// (density: (ρ*_i − ρ0)₊, kg/m^dim; divergence: (Dρ_i/Dt)₊, kg/(m^dim s)), turned into
    /// κ_i/ρ_i = e_i / (dt^p D_i) in `k`; returns Σ e_i.
    pub(super) fn errors(&mut self, stage: Projection, dt: Real) -> Real {
        self.boundary_divergence();
        let (pairs, sites, rho, vs, rho0) = (&self.pairs, &self.sites, &self.rho, &self.vs, self.p.rho0);
        let scale = match stage {
            Projection::Density => 1.0 / (dt * dt),
            Projection::Divergence => 1.0 / dt,
        };
        par::chunks1_sum(&mut self.k, |s, k| {
            let p = &pairs[s / CHUNK];
            let mut total = 0.0;
            for (kk, kout) in k.iter_mut().enumerate() {
                let i = s + kk;
                let (site, vi) = (&sites[i], vs[i]);
                // Σ_j (v_i − v_j)·g_ij = v_i·Σ_j g_ij − Σ_j v_j·g_ij: per pair only the
                // neighbour's part, in two independent sums (SPH-2D 41k, 2 threads: 0.62 →
                // 0.48 ms a pass beside the pairwise form in one process; between separate
                // binaries within noise; the whole run's solver share 11.7 → 8.0 ms a step).
                let acc = pair_sum(p, kk, |j, g| g * vs[j]);
                let div = vi.dot(site.gw + site.gs) - components_sum(acc) - site.wv;
                let e = match stage {
                    Projection::Density => (rho[i] + dt * div - rho0).max(0.0),
                    Projection::Divergence if site.inner => div.max(0.0),
                    Projection::Divergence => 0.0,
                };
                *kout = e * site.dinv * scale;
                total += e;
            }
            total
        })
    }

    /// One velocity update with κ/ρ in `k` (module doc), adding `k` into `ksum`.
    pub(super) fn apply(&mut self, dt: Real) {
        let (pairs, sites, k, free) = (&self.pairs, &self.sites, &self.k, &self.free);
        par::chunks2(&mut self.vs, &mut self.ksum, |s, vs, ksum| {
            let p = &pairs[s / CHUNK];
            for kk in 0..vs.len() {
                let i = s + kk;
                let ki = k[i];
                // Walls mirror the particle's pressure (p_b = p_i: (κ_i + κ_i)/ρ_i), so a wall
                // layer balances the fluid's push; with κ_i alone (Akinci 2012, eq. 10, as in
                // WCSPH) the hydrostatic push drove the corner particles of a 2 m column through
                // the walls (144 particles across, T* = 0.15), their own pressure pushing
                // nothing where the fluid's and the walls' gradients cancel.
                // Σ_j (κ_i + κ_j) g_ij = κ_i Σ_j g_ij + Σ_j κ_j g_ij (as in `errors`).
                let a = (sites[i].gw * 2.0 + sites[i].gs) * ki + pair_sum(p, kk, |j, g| g * k[j]);
                if free[i] {
                    vs[kk] -= a * dt;
                }
                ksum[kk] += ki;
            }
        });
        self.push_boundary(dt);
    }

    /// Turns the κ/ρ of an error pass in `k` into `pick(κ/ρ, w)` with w = `WARM_START` times
    /// the particle's last summed κ/ρ of `stage`, where it compresses (κ/ρ > 0), else 0.
    pub(super) fn warm_start(&mut self, stage: Projection, pick: impl Fn(Real, Real) -> Real + Sync) {
        let (order, k) = (&self.grid.order, &mut self.k);
        let hist = match stage {
            Projection::Density => &self.kappa,
            Projection::Divergence => &self.kappa_v,
        };
        let ws = match stage {
            Projection::Density => WARM_START_DENSITY,
            Projection::Divergence => WARM_START,
        };
        par::chunks1(k, |s, k| {
            for (kk, ko) in k.iter_mut().enumerate() {
                *ko = if *ko > 0.0 { pick(*ko, hist[order[s + kk] as usize] * ws) } else { 0.0 };
            }
        });
    }

    /// One solve (module doc, steps 2 and 4) on the scene's velocities `v`; returns the energy
    /// it removed (J; `books`): 0 from the divergence solve, whose share the density solve
    /// books with its own at the step's end.
    pub(super) fn solve(&mut self, stage: Projection, v: &mut [V], dt: Real) -> Real {
        let t0 = Instant::now();
        let n = self.n;
        self.gather_v(v);
        match stage {
            Projection::Divergence => {
                self.v_start.clone_from(&self.vs);
                self.open = true;
            }
            Projection::Density => {
                if !self.open {
                    // A density solve alone (no divergence stage this step): its start is the step's.
                    self.v_start.clone_from(&self.vs);
                    self.dv_div.clear();
                    self.dv_div.resize(n, V::ZERO);
                }
                self.v_kick.clone_from(&self.vs);
            }
        }
        // Warm start: half the last step's sum (module doc; κ/ρ does not scale with dt), only
        // where the state compresses now (a push where it no longer does would expand it,
        // which the one-sided solve never takes back: energy put in). The density solve
        // applies it before its iterations (paper, Algorithm 2); the divergence solve folds it
        // into its first iteration (`WarmStart`).
        let warm = match stage {
            Projection::Density => WarmStart::Before,
            Projection::Divergence => WarmStart::FirstIteration,
        };
        if stage == Projection::Density {
            self.kick_boundary(dt);
            self.hydrostatic_boundary(dt);
            self.hydrostatic_walls(dt);
        }
        self.k.resize(n, 0.0);
        self.ksum.clear();
        self.ksum.resize(n, 0.0);
        if warm == WarmStart::Before {
            self.errors(stage, dt);
            self.warm_start(stage, |_, w| w);
            self.apply(dt);
        }
        let rho0 = self.p.rho0;
        let tol = match stage {
            Projection::Density => self.p.density_tol,
            Projection::Divergence => self.p.divergence_tol,
        };
        let norm = match stage {
            Projection::Density => 1.0 / (n.max(1) as Real * rho0),
            Projection::Divergence => dt / (n.max(1) as Real * rho0),
        };
        // At least 2 density iterations and 1 divergence iteration a step (paper, Algorithms 2
        // and 3): a mean below the tolerance can hide a deep layer's growing compression (a 2 m
        // column, 144 particles across, blew up at step 13 when the solve first had to act).
        let least = match stage {
            Projection::Density => 2,
            Projection::Divergence => 1,
        };
        let mut iterations = 0u32;
        let err = loop {
            let err = self.errors(stage, dt) * norm;
            let done = err <= tol && iterations >= least.min(self.p.max_iterations);
            if done || iterations >= self.p.max_iterations || self.stop.is_set() {
                break err;
            }
            if iterations == 0 && warm == WarmStart::FirstIteration {
                self.warm_start(stage, Real::max);
            }
            self.apply(dt);
            iterations += 1;
        };
        // Keep the sum for the next step's warm start (particle order). κ/ρ = p/ρ² does not
        // scale with dt: a steady flow needs the same pressure whatever the step.
        if stage == Projection::Density {
            // Both solves push with the same form: the step's pressure is their sum.
            // With surface tension, plus the surface forces' virial (`surface_acceleration`):
            // the mechanical pressure.
            let (order, ksum) = (&self.grid.order, &self.ksum);
            let (sp, rho, kappa_v) = (&self.surface_p, &self.rho, &self.kappa_v);
            unsort(order, &mut self.pressure, |k| {
                let i = order[k] as usize;
                (ksum[k] + kappa_v[i]) * rho[k] * rho[k] + sp.get(k).copied().unwrap_or(0.0)
            });
        }
        {
            let (order, ksum) = (&self.grid.order, &self.ksum);
            let out = match stage {
                Projection::Density => &mut self.kappa,
                Projection::Divergence => &mut self.kappa_v,
            };
            unsort(order, out, |k| ksum[k]);
        }
        let removed = match stage {
            Projection::Divergence => {
                let (vs, v0) = (&self.vs, &self.v_start);
                self.dv_div.resize(n, V::ZERO);
                par::chunks1(&mut self.dv_div, |s, d| {
                    for (kk, dk) in d.iter_mut().enumerate() {
                        *dk = vs[s + kk] - v0[s + kk];
                    }
                });
                [0.0; 3]
            }
            Projection::Density => {
                self.open = false;
                let e = self.books_step();
                self.a_forces.clear();
                e
            }
        };
        self.scatter_v(v);
        let b = &mut self.books;
        b.unconverged += (err > tol) as u64;
        match stage {
            Projection::Density => {
                b.steps += 1;
                b.density_iterations += iterations as u64;
                b.density_error = err;
                b.density_error_max = b.density_error_max.max(err);
                b.dissipated_divergence += removed[0];
                b.dissipated_density += removed[1];
            }
            Projection::Divergence => {
                b.divergence_iterations += iterations as u64;
                b.divergence_error = err;
                b.divergence_error_max = b.divergence_error_max.max(err);
            }
        }
        self.clock[1] += t0.elapsed().as_secs_f64();
        removed[0] + removed[1] + removed[2]
    }

    /// The energy the step's two solves removed (J: divergence, density), each its velocity
    /// changes' work −Σ_i m_i Δv_i·v̄_i over the step's mean velocity v̄ = (v_start + v_end)/2
    /// (the midpoint rule, as the drift moves each particle by dt times a velocity of the step).
    /// Not their change of ½ m|v|²: a fluid at rest on a floor gains ½ m (g dt)² a particle
    /// from the kick, which the density solve takes out, so that measure booked M g² dt/2 a
    /// second of dissipation that never happened (the books of a resting 0.5 × 0.5 m pool rose
    /// 41 % in 3 s); over the step's mean velocity, zero at rest, the books see the work the
    /// pressure does on a moving fluid.
    fn books_step(&self) -> [Real; 3] {
        let (vs, v0, vk, d1, m, free) = (&self.vs, &self.v_start, &self.v_kick, &self.dv_div, &self.m, &self.free);
        let (af, dt) = (&self.a_forces, self.kick_dt);
        let forces = af.len() == self.n;
        par::reduce(
            self.n,
            [0.0; 3],
            |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]],
            |ks| {
                let mut e = [0.0; 3];
                for k in ks {
                    if free[k] {
                        let mean = (v0[k] + vs[k]) * 0.5;
                        e[0] -= m[k] * d1[k].dot(mean);
                        e[1] -= m[k] * (vs[k] - vk[k]).dot(mean);
                        if forces {
                            e[2] -= m[k] * dt * af[k].dot(mean);
                        }
                    }
                }
                e
            },
        )
    }

    /// The step's pairs of a fluid particle and a boundary sample (`MovingWalls::pair_up`).
    pub(super) fn pair_up<K: Kernel>(&mut self) {
        let (xs, h) = (&self.xs, self.p.h);
        if let Some(mw) = self.moving.as_mut() {
            mw.pair_up::<K>(&self.grid, |k| xs[k], h);
        }
    }

    /// The bodies' share of Dρ_k/Dt at their motion now, Σ_b Ψ_b v_b·∇W_kb (`Site::wv`).
    pub(super) fn boundary_divergence(&mut self) {
        let Some(mw) = &self.moving else {
            return;
        };
        for &(k, a, e) in &mw.runs {
            let wv = mw.pairs[a as usize..e as usize].iter().map(|&(_, b, g, _)| mw.velocity(b as usize).dot(g)).sum();
            self.sites[k as usize].wv = wv;
        }
    }

    /// The bodies' response to one velocity update with κ/ρ in `k`: a free particle k pushed by
    /// −dt 2 (κ_k/ρ_k) Ψ_b ∇W_kb through sample b (walls mirror the pressure, `apply`) pushes
    /// b's body by 2 m_k dt (κ_k/ρ_k) Ψ_b ∇W_kb at b (Akinci et al. 2012, eq. 10–11), which
    /// changes its velocity and spin (and the solve sees them in its next error pass), and is
    /// added to the step's impulse. In pair order: the same bits for any thread count.
    pub(super) fn push_boundary(&mut self, dt: Real) {
        let Some(mw) = self.moving.as_mut() else {
            return;
        };
        let (k, m, free) = (&self.k, &self.m, &self.free);
        let mut dp = std::mem::take(&mut mw.push);
        dp.clear();
        dp.resize(mw.bodies.len(), (V::ZERO, [0.0; 3]));
        for &(kk, a, e) in &mw.runs {
            let kk = kk as usize;
            if !free[kk] || k[kk] == 0.0 {
                continue;
            }
            let s = 2.0 * m[kk] * dt * k[kk];
            for &(_, b, g, _) in &mw.pairs[a as usize..e as usize] {
                let (j, body) = (g * s, mw.body[b as usize] as usize);
                let l = cross3(mw.offset[b as usize], j);
                dp[body].0 += j;
                for c in 0..3 {
                    dp[body].1[c] += l[c];
                }
            }
        }
        mw.give(dp);
    }

    /// Before the density solve: each pushed body's own acceleration over the step (gravity),
    /// as the kick gave the fluid its forces.
    pub(super) fn kick_boundary(&mut self, dt: Real) {
        if let Some(mw) = self.moving.as_mut() {
            for b in mw.bodies.iter_mut().filter(|b| b.inv_mass > 0.0) {
                b.v += b.accel * dt;
            }
        }
    }

    /// Before the density solve: the hydrostatic part of each sample's mirrored pressure. A
    /// sample mirrors its particle's pressure (`apply`), but it lies up to 2h from it, up or
    /// down in the fluid's column: its pressure is p_b = p_k + ρ_k g·(x_b − x_k) (Adami, Hu &
    /// Adams 2012, eq. 27, for a body at rest: its own acceleration is left out). The
    /// difference is known at the step's start, so it is given once, as a force: particle k by
    /// dt Σ_b Ψ_b (g·(x_k − x_b)/ρ_k) ∇W_kb, its body the opposite at b. Without it a floating
    /// box rode 0.1–0.2 spacings higher (2D, a 0.3 × 0.15 m box of 250 kg/m², 80 across: −6.1 %
    /// of Archimedes' draft, −0.2 % with it, both read with the test's old surface estimate,
    /// which read 0.15 cm deep at 80 across: tests/bodies/test_floating.py, `_draft`); left out on the box's vertical sides only, most
    /// of that came back: with p_b = p_k the particle below a side's sample presses it harder
    /// than the one above, an upward push on a wall that hydrostatics pushes only sideways. In
    /// pair order: the same bits for any thread count.
    pub(super) fn hydrostatic_boundary(&mut self, dt: Real) {
        let Some(mw) = self.moving.as_mut() else {
            return;
        };
        let (m, free, rho, xs) = (&self.m, &self.free, &self.rho, &self.xs);
        let mut dp = std::mem::take(&mut mw.push);
        dp.clear();
        dp.resize(mw.bodies.len(), (V::ZERO, [0.0; 3]));
        let mut xb = [0.0; 3];
        for &(kk, a, e) in &mw.runs {
            let kk = kk as usize;
            if !free[kk] || rho[kk] <= 0.0 {
                continue;
            }
            let mut dv = V::ZERO;
            for &(_, b, g, _) in &mw.pairs[a as usize..e as usize] {
                let b = b as usize;
                for (d, x) in xb.iter_mut().enumerate().take(V::DIM) {
                    *x = mw.w.pos[d][b];
                }
                let r = xs[kk] - V::from_slice(&xb[..V::DIM]);
                let body = mw.body[b] as usize;
                let step = g * (dt * mw.bodies[body].gravity.dot(r) / rho[kk]);
                dv += step;
                let j = step * -m[kk];
                let l = cross3(mw.offset[b], j);
                dp[body].0 += j;
                for c in 0..3 {
                    dp[body].1[c] += l[c];
                }
            }
            self.vs[kk] += dv;
        }
        mw.give(dp);
    }

    /// Before the density solve: the hydrostatic part of the static walls' mirrored pressure,
    /// as `hydrostatic_boundary` gives the bodies' (Adami, Hu & Adams 2012, eq. 27, a wall at
    /// rest): particle i by dt Σ_b Ψ_b (g·(x_i − x_b)/ρ_i) ∇W_ib (`Site::hw`). Without it a
    /// wall sample mirrors p_i at every height, so along a vertical wall the walls and the
    /// fluid's pressure gradient do not balance gravity there: a force that no pressure can
    /// take out (it is not a gradient) drove a steady circulation down the walls and up the
    /// middle of a resting pool (0.5 × 0.5 m, 24 × 24: rms 0.23 m/s at t = 4 s, α = 0.05).
    pub(super) fn hydrostatic_walls(&mut self, dt: Real) {
        let (sites, rho, free) = (&self.sites, &self.rho, &self.free);
        par::chunks1(&mut self.vs, |s, vs| {
            for (kk, v) in vs.iter_mut().enumerate() {
                let i = s + kk;
                if free[i] && rho[i] > 0.0 {
                    *v += sites[i].hw * (dt / rho[i]);
                }
            }
        });
    }

    /// The step's surface normals n_i = H Σ_j m_j/ρ_j ∇W_ij (Akinci 2013, eq. 4; fluid
    /// neighbours only), sorted order, from the stored pairs (g = m_j ∇W_ij).
    pub(super) fn compute_normals(&mut self) {
        let (pairs, rho, big_h) = (&self.pairs, &self.rho, self.surface.big_h);
        self.normals.resize(self.n, V::ZERO);
        par::chunks1(&mut self.normals, |s, out| {
            let p = &pairs[s / CHUNK];
            for (kk, n) in out.iter_mut().enumerate() {
                let mut sum = V::ZERO;
                for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                    sum += p.g[q] * (1.0 / rho[p.j[q] as usize]);
                }
                *n = sum * big_h;
            }
        });
    }

    /// Sorted particle i's acceleration by surface tension and adhesion (`sph::surface`):
    /// −γ Σ_j K_ij [m_j C(r) x̂_ij + c (n_i − n_j)] − β Σ_b Ψ_b A(r) x̂_ib, m/s²; and the virial
    /// pressure of its fluid pairs' surface forces, ρ_i/(2d) Σ_j x_ij·a_ij, Pa (Irving &
    /// Kirkwood 1950: each pair's x_ij·F_ij shared half and half, over the particle's volume
    /// m_i/ρ_i). The cohesion holds the fluid together with a bulk tension of its own (about
    /// −(π/2)ρ0²γ∫C r² dr in 2D, tens of times σ/R): the solvers' pressure carries it, and only
    /// the sum of the two, the mechanical pressure, shows a droplet's Laplace pressure.
    #[inline(always)]
    pub(super) fn surface_acceleration(&self, i: usize, xi: V, ri: Real) -> (V, Real) {
        let (surf, normals, rho0) = (&self.surface, &self.normals, self.p.rho0);
        let (p, kk) = (&self.pairs[i / CHUNK], i % CHUNK);
        let (mut a, mut virial) = (V::ZERO, 0.0);
        if surf.tension() {
            let (xs, m, rho) = (&self.xs, &self.m, &self.rho);
            let ni = normals[i];
            let (mut st, mut vir) = (V::ZERO, 0.0);
            for q in p.start[kk] as usize..p.start[kk + 1] as usize {
                let j = p.j[q] as usize;
                let d = xi - xs[j];
                let r = d.length_squared().sqrt();
                let k_ij = 2.0 * rho0 / (ri + rho[j]);
                // Coincident particles have no direction: no cohesion (the curvature term stays).
                let coh = if r > 0.0 { d * (m[j] * surf.cohesion(r) / r) } else { V::ZERO };
                let pair = (coh + (ni - normals[j]) * surf.c) * k_ij;
                st += pair;
                vir += d.dot(pair);
            }
            a -= st * surf.gamma;
            virial = -surf.gamma * vir * ri / (2.0 * V::DIM as Real);
        }
        if surf.adhesion() {
            let mut ad = V::ZERO;
            let w = f64::walls(&self.walls);
            for run in self.walls.grid.query(self.grid.cells[i]).iter() {
                for b in run {
                    let d = xi - wall_at::<V>(w, b);
                    let r = d.length_squared().sqrt();
                    let k = crate::sph::surface::adhesion_kernel(r, surf.big_h);
                    if k > 0.0 {
                        ad += d * (w.psi[b] * k / r);
                    }
                }
            }
            a -= ad * surf.beta;
        }
        (a, virial)
    }

    /// Density (kg/m^dim) of each particle of the fluid at `x`, particle order, computed now
    /// (scratch of its own).
    pub fn densities(&self, x: &[V], model: &Model) -> Vec<Real> {
        match self.p.kernel {
            KernelKind::CubicSpline => self.densities_with::<CubicSpline>(x, model),
            KernelKind::WendlandC2 => self.densities_with::<WendlandC2>(x, model),
        }
    }

    pub(super) fn densities_with<K: Kernel>(&self, x: &[V], model: &Model) -> Vec<Real> {
        let r = self.first..self.first + self.n;
        let gathered: (Vec<V>, Vec<Real>);
        let (xr, mr) = if self.to_scene.is_empty() {
            (&x[r.clone()], &model.mass[r])
        } else {
            let ts = &self.to_scene;
            gathered =
                (ts.iter().map(|&i| x[i as usize]).collect(), ts.iter().map(|&i| model.mass[i as usize]).collect());
            (&gathered.0[..], &gathered.1[..])
        };
        let mut grid = CellList::new(self.grid.cell_size(), V::DIM).expect("valid cell size");
        grid.build(xr);
        let (h, w) = (self.p.h, f64::walls(&self.walls));
        let (sigma, reach) = (K::sigma(h, V::DIM), 4.0 * h * h);
        let mut rho = vec![0.0; self.n];
        let out = SyncPtr(rho.as_mut_ptr());
        let grid = &grid;
        par::reduce(
            self.n,
            (),
            |_, _| (),
            |ks| {
                for k in ks {
                    let i = grid.order[k] as usize;
                    let c = grid.cells[k];
                    let mut s = 0.0;
                    for run in grid.query(c).iter() {
                        for j in run {
                            let jj = grid.order[j] as usize;
                            let r2 = (xr[i] - xr[jj]).length_squared();
                            if r2 < reach {
                                s += mr[jj] * sigma * K::w(r2.sqrt() / h);
                            }
                        }
                    }
                    for run in self.walls.grid.query(c).iter() {
                        for b in run {
                            let r2 = (xr[i] - wall_at::<V>(w, b)).length_squared();
                            if r2 < reach {
                                s += w.psi[b] * sigma * K::w(r2.sqrt() / h);
                            }
                        }
                    }
                    if let Some(mw) = &self.moving {
                        for run in mw.grid.query(c).iter() {
                            for b in run {
                                let r2 = (xr[i] - wall_at::<V>(&mw.w, b)).length_squared();
                                if r2 < reach {
                                    s += mw.w.psi[b] * sigma * K::w(r2.sqrt() / h);
                                }
                            }
                        }
                    }
                    // SAFETY: each particle i is written by its one sorted slot k.
                    unsafe { *out.get().add(i) = s };
                }
            },
        );
        rho
    }
}
