//! DFSPH's pair build: each sorted particle's density, factor, wall gradient sum and stored
//! pairs (the module's step 1), on the SIMD layer (`BuildChunk`), and the sums over stored pairs.
use super::*;

/// Wall particle `b`'s position (the wall arrays are by component).
#[inline(always)]
pub(super) fn wall_at<V: Vector>(w: &WallArrays<f64>, b: usize) -> V {
    let mut c = [0.0; 3];
    for (d, cd) in c.iter_mut().enumerate().take(V::DIM) {
        *cd = w.pos[d][b];
    }
    V::from_slice(&c[..V::DIM])
}

/// Σ_q f(j_q, g_q) over sorted particle `kk`'s stored pairs (`kk` within the chunk of `p`), in
/// two sums of alternate pairs added at the end: two independent chains of additions, so a pass
/// is not bound by one chain's latency. The order is fixed (the same bits for any thread count).
#[inline(always)]
pub(super) fn pair_sum<V: Vector>(p: &Pairs<V>, kk: usize, f: impl Fn(usize, V) -> V) -> V {
    let (a, b) = (p.start[kk] as usize, p.start[kk + 1] as usize);
    let (js, gs) = (&p.j[a..b], &p.g[a..b]);
    let (mut s0, mut s1) = (V::ZERO, V::ZERO);
    let (jc, gc) = (js.chunks_exact(2), gs.chunks_exact(2));
    let (jr, gr) = (jc.remainder(), gc.remainder());
    for (j, g) in jc.zip(gc) {
        s0 += f(j[0] as usize, g[0]);
        s1 += f(j[1] as usize, g[1]);
    }
    if let (Some(&j), Some(&g)) = (jr.first(), gr.first()) {
        s0 += f(j as usize, g);
    }
    s0 + s1
}

/// `out[order[k]] = f(k)` for every sorted slot k, in parallel (`order` is a permutation of
/// `0..out.len()`).
pub(super) fn unsort(order: &[u32], out: &mut [Real], f: impl Fn(usize) -> Real + Sync) {
    assert_eq!(order.len(), out.len());
    let ptr = SyncPtr(out.as_mut_ptr());
    par::reduce(
        order.len(),
        (),
        |_, _| (),
        |ks| {
            for k in ks {
                debug_assert!((order[k] as usize) < order.len());
                // SAFETY: `order` is a permutation of the indices of `out` (checked length):
                // each slot is written once, by its one sorted k.
                unsafe { *ptr.get().add(order[k] as usize) = f(k) };
            }
        },
    );
}

/// x + y (+ z).
#[inline(always)]
pub(super) fn components_sum<V: Vector>(v: V) -> Real {
    (1..V::DIM).fold(v.comp(0), |s, c| s + v.comp(c))
}

/// One chunk of sorted particles of the pair build (`Dfsph::build`), compiled per SIMD level:
/// each particle's candidates are tested a vector at a time from the sorted positions by
/// component (`Dfsph::xc`) and the passing ones compacted into `pairs.j` from the mask's bits
/// (`Mask::bits`); then the kernel is evaluated on those pairs a vector at a time
/// (`Kernel::wg_exact`), and the density, Σ ∇W and Σ|∇W|² are summed in pair order. Every lane
/// does the scalar operations in the scalar order (no FMA), so every level finds the same pairs
/// and stores the same bits (`tests::the_build_is_the_same_at_every_level`).
///
/// Measured on the state of the 41k dam break at T* = 2 (Zen 4, 2 threads unless said, min of
/// 31 builds, binaries alternated): the scalar build with its cubic-spline branch (LLVM turned
/// the select of q < 1 into a branch around the division, which mispredicts on a disordered
/// flow) 16.0 ms at 1 thread, 13.9 with the branch taken out (`Float::pick`); at 2 threads the
/// scalar build 7.9–8.0 ms, the SIMD kernel 5.4, with the SIMD candidate test, the walls' dense
/// cell list and no zeroing of the pair buffers 5.2–5.3 (against 6.4–7.5 for the one before in
/// that noisier hour).
pub(super) struct BuildChunk<'a, V: Vector, K> {
    grid: &'a CellList,
    walls: &'a Walls,
    moving: Option<&'a MovingWalls<V>>,
    xs: &'a [V],
    xc: &'a [Vec<Real>; 3],
    m: &'a [Real],
    h: Real,
    /// The Jacobi relaxation ω (`DfsphParams::relaxation`), folded into the factor: ω/D_i.
    relax: Real,
    n_min: u32,
    /// The step's gravity (m/s²), for the walls' hydrostatic pressure (`Site::hw`).
    g: V,
    /// The chunk's first sorted particle.
    s: usize,
    pairs: &'a mut Pairs<V>,
    sites: &'a mut [Site<V>],
    rho: &'a mut [Real],
    _k: PhantomData<K>,
}

impl<V: Vector, K: Kernel> SimdKernel for BuildChunk<'_, V, K> {
    type Output = ();
    #[inline(always)]
    fn run<S: Simd>(self, simd: S) {
        let BuildChunk { grid, walls, moving, xs, xc, m, h, relax, n_min, g, s, pairs, sites, rho: rho_out, .. } = self;
        let (sigma, reach) = (K::sigma(h, V::DIM), 4.0 * h * h);
        let gscale = sigma / (h * h);
        let (w, flat, lanes) = (f64::walls(walls), V::flat(xs), P::<S, f64>::lanes());
        let splat = |x: f64| P::<S, f64>::splat(simd, x);
        let (v_sigma, v_gscale, v_inv_h, v_reach) = (splat(sigma), splat(gscale), splat(1.0 / h), splat(reach));
        // `j` and `g` keep their length from step to step (no zeroing): the chunk's pairs are
        // `..top`, and `start` bounds every particle's.
        pairs.start.clear();
        let mut top = 0;
        let mut last = [i64::MIN; 3];
        let (mut fluid, mut wall) = (grid.query(last), walls.grid.query(last));
        let mut mwall = moving.map(|mw| mw.grid.query(last));
        for (kk, (site, rho_out)) in sites.iter_mut().zip(rho_out.iter_mut()).enumerate() {
            let k = s + kk;
            let cell = grid.cells[k];
            if cell != last {
                fluid = grid.query(cell);
                wall = walls.grid.query(cell);
                mwall = moving.map(|mw| mw.grid.query(cell));
                last = cell;
            }
            pairs.start.push(top as u32);
            let xk = xs[k];
            let (mut rho, mut sum, mut sq, mut count) = (m[k] * sigma * K::w(0.0), V::ZERO, 0.0, 0u32);
            // The candidates within reach, a vector of them at a time (|d|² lane by lane as
            // `Vector::dot` sums it: the same pairs at every level), compacted without a
            // branch (about a third of them pass, at random: a branch there mispredicts): each
            // candidate is written, and the count moves past it only if it passed.
            let base = top;
            // Loops here and below, not `std::array::from_fn`: its closures can stay out of line
            // (a call per splat or lane) in a build of several codegen units.
            let mut xkv = [splat(0.0); 3];
            for (c, x) in xkv.iter_mut().enumerate().take(V::DIM) {
                *x = splat(xk.comp(c));
            }
            for run in fluid.iter() {
                if pairs.j.len() < top + run.len() + lanes {
                    pairs.j.resize(top + run.len() + lanes, 0);
                }
                let (out, mut c) = (&mut pairs.j[top..], 0);
                let mut j = run.start;
                while j < run.end {
                    let d0 = xkv[0] - P::load(simd, &xc[0][j..]);
                    let mut r2 = d0 * d0;
                    for (xkc, xcc) in xkv.iter().zip(xc).take(V::DIM).skip(1) {
                        let dc = *xkc - P::load(simd, &xcc[j..]);
                        r2 = r2 + dc * dc;
                    }
                    let mut bits = r2.lt(v_reach).bits(simd);
                    if run.end - j < lanes {
                        bits &= (1 << (run.end - j)) - 1;
                    }
                    if (j..j + lanes).contains(&k) {
                        bits &= !(1 << (k - j));
                    }
                    for t in 0..lanes {
                        out[c] = (j + t) as u32;
                        c += ((bits >> t) & 1) as usize;
                    }
                    j += lanes;
                }
                top += c;
            }
            let end = top;
            if pairs.g.len() < end {
                pairs.g.resize(end, V::ZERO);
            }
            let mut q = base;
            while q < end {
                // A vector of pairs; lanes past the particle's last pair take j = k (d = 0:
                // finite, and dropped).
                let cnt = lanes.min(end - q);
                let mut idx = [k; 16];
                for (t, i) in idx.iter_mut().enumerate().take(cnt) {
                    *i = pairs.j[q + t] as usize;
                }
                let mut d = [P::zero(simd); 3];
                for c in 0..V::DIM {
                    d[c] = xkv[c] - P::from_fn(simd, |t| flat[idx[t] * V::DIM + c]);
                }
                // |d|² as `Vector::dot` sums it: ((x x + y y) + z z).
                let mut r2 = d[0] * d[0];
                for dc in &d[1..V::DIM] {
                    r2 = r2 + *dc * *dc;
                }
                let (wq, gq) = K::wg_exact(r2.sqrt() * v_inv_h);
                let mj = P::from_fn(simd, |t| m[idx[t]]);
                let (wr, f) = ((mj * v_sigma * wq).to_array(), mj * v_gscale * gq);
                let mut gc = [[0.0; 16]; 3];
                for c in 0..3 {
                    gc[c] = (d[c] * f).to_array();
                }
                for t in 0..cnt {
                    let g = V::from_slice(&[gc[0][t], gc[1][t], gc[2][t]][..V::DIM]);
                    pairs.g[q + t] = g;
                    rho += wr[t];
                    sum += g;
                    sq += g.length_squared();
                }
                q += cnt;
            }
            count += (end - base) as u32;
            let (mut gw, mut hw) = (V::ZERO, V::ZERO);
            for run in wall.iter() {
                for b in run {
                    let d = xk - wall_at::<V>(w, b);
                    let r2 = d.length_squared();
                    if r2 < reach {
                        let q = r2.sqrt() / h;
                        rho += w.psi[b] * sigma * K::w(q);
                        let gb = d * (w.psi[b] * gscale * K::g(q));
                        gw += gb;
                        hw += gb * g.dot(d);
                        count += 1;
                    }
                }
            }
            // The bodies' boundary: as the walls (their motion is the solves', `Site::wv`).
            if let (Some(mw), Some(runs)) = (moving, &mwall) {
                for run in runs.iter() {
                    for b in run {
                        let d = xk - wall_at::<V>(&mw.w, b);
                        let r2 = d.length_squared();
                        if r2 < reach {
                            let q = r2.sqrt() / h;
                            rho += mw.w.psi[b] * sigma * K::w(q);
                            gw += d * (mw.w.psi[b] * gscale * K::g(q));
                            count += 1;
                        }
                    }
                }
            }
            // Own push v_i −= dt κ_i/ρ_i (Σ_j m_j ∇W_ij + 2 Σ_b Ψ_b ∇W_ib) (walls mirror the
            // pressure), so Dρ_i/Dt changes by −dt κ_i/ρ_i D_i with this D_i (taken no
            // smaller than the neighbours' part, which is > 0, where a wall makes it so).
            // The relaxation ω scales it (`relax`; exactly 1/D_i at ω = 1).
            let dd = ((sum + gw * 2.0).dot(sum + gw) + sq).max(sq);
            *site =
                Site { dinv: if dd > 0.0 { relax / dd } else { 0.0 }, gw, gs: sum, inner: count >= n_min, hw, wv: 0.0 };
            *rho_out = rho;
        }
        pairs.start.push(top as u32);
    }
}

impl<V: Vector> Solver<V> {
    /// Sorts the fluid at `x` into cells and computes, per sorted particle, its density, factor,
    /// wall gradient sum and stored pairs (module doc, step 1).
    pub(super) fn build(&mut self, x: &[V], model: &Model) {
        self.build_at(x, model, simd::level());
    }

    /// `build` at SIMD level `level` (every level gives the same bits).
    pub(super) fn build_at(&mut self, x: &[V], model: &Model, level: simd::Level) {
        let t0 = Instant::now();
        match self.p.kernel {
            KernelKind::CubicSpline => self.build_with::<CubicSpline>(x, model, level),
            KernelKind::WendlandC2 => self.build_with::<WendlandC2>(x, model, level),
        }
        self.built = true;
        self.clock[0] += t0.elapsed().as_secs_f64();
    }

    pub(super) fn build_with<K: Kernel>(&mut self, x: &[V], model: &Model, level: simd::Level) {
        let n = self.n;
        if !self.to_scene.is_empty() {
            // Several fluids: their particles gathered into the solve's order, and α c0.
            let ts = &self.to_scene;
            self.xg.clear();
            self.xg.extend(ts.iter().map(|&i| x[i as usize]));
            self.mg.clear();
            self.mg.extend(ts.iter().map(|&i| model.mass[i as usize]));
            self.img.clear();
            self.img.extend(ts.iter().map(|&i| model.inv_mass[i as usize]));
        }
        let r = self.first..self.first + n;
        let (xr, mr, im) = if self.to_scene.is_empty() {
            (&x[r.clone()], &model.mass[r.clone()], &model.inv_mass[r])
        } else {
            (&self.xg[..], &self.mg[..], &self.img[..])
        };
        self.grid.build(xr);
        let order = &self.grid.order;
        self.xs.resize(n, V::ZERO);
        self.m.resize(n, 0.0);
        self.free.resize(n, true);
        par::chunks3(&mut self.xs, &mut self.m, &mut self.free, |s, xs, m, free| {
            for k in 0..xs.len() {
                let i = order[s + k] as usize;
                xs[k] = xr[i];
                m[k] = mr[i];
                free[k] = im[i] != 0.0;
            }
        });
        if !self.to_scene.is_empty() {
            let visc_u = &self.visc_u;
            self.visc.clear();
            self.visc.extend(order.iter().map(|&u| visc_u[u as usize]));
        }
        for (c, xc) in self.xc.iter_mut().enumerate().take(V::DIM) {
            xc.clear();
            xc.extend(self.xs.iter().map(|x| x.comp(c)));
            xc.resize(n + PAD, 0.0);
        }
        let h = self.p.h;
        // A full neighbourhood holds about ω_d (2h)^d ρ0/m particles; the divergence solve
        // takes those with at least 57 % of that (12 of 21 in 2D at h = 1.3 Δx).
        let mean_m = if n > 0 { self.m.iter().sum::<Real>() / n as Real } else { 1.0 };
        let ball = if V::DIM == 2 {
            std::f64::consts::PI * 4.0 * h * h
        } else {
            4.0 / 3.0 * std::f64::consts::PI * 8.0 * h * h * h
        };
        self.n_min = (0.57 * ball * self.p.rho0 / mean_m).round() as u32;
        let chunks = n.div_ceil(CHUNK);
        self.pairs.resize_with(chunks, Pairs::default);
        self.sites.resize(n, Site::default());
        self.rho.resize(n, 0.0);
        let (grid, xs, xc, m, walls) = (&self.grid, &self.xs, &self.xc, &self.m, &self.walls);
        let moving = self.moving.as_ref();
        let (n_min, g, relax) = (self.n_min, self.gravity, self.p.relaxation);
        let chunk = |c: usize, pairs: &mut Pairs<V>, sites: &mut [Site<V>], rho: &mut [Real]| {
            let (s, _k) = (c * CHUNK, PhantomData::<K>);
            simd::dispatch(
                level,
                BuildChunk { grid, walls, moving, xs, xc, m, h, relax, n_min, g, s, pairs, sites, rho, _k },
            );
        };
        let (pairs, sites, rho) = (&mut self.pairs, &mut self.sites, &mut self.rho);
        let count = pairs.len().min(sites.len().div_ceil(CHUNK)).min(rho.len().div_ceil(CHUNK));
        let (pp, ps, pr) = (par::Shared::new(pairs), par::Shared::new(sites), par::Shared::new(rho));
        // SAFETY: chunk c's pairs, sites and densities go to index c alone.
        par::each(n >= par::PAR_MIN, count, 1, |c| unsafe {
            chunk(c, pp.at(c), ps.piece(CHUNK, c), pr.piece(CHUNK, c))
        });
        if self.moving.is_some() {
            self.pair_up::<K>();
        }
        // The measured compression of this step's positions (the density solve's real result).
        let (rho0, rho) = (self.p.rho0, &self.rho);
        let e = par::sum(n, 0.0, |r| r.map(|k| (rho[k] - rho0).max(0.0)).sum::<Real>());
        let b = &mut self.books;
        b.measured = if n > 0 { e / (n as Real * rho0) } else { 0.0 };
        b.measured_max = b.measured_max.max(b.measured);
    }
}
