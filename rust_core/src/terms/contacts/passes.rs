//! The contacts' passes over the Verlet lists: pair forces (`pair_pass`, SIMD lanes in
//! `lanes`), the grains' sums (`grain_pass`), rolling resistance (`roll_pass`) and the commit
//! of a step's springs and books (`commit_pass`, deferred to the next evaluation: `settle_now`).
use super::*;

impl<V: Vector> Contacts<V> {
    /// The pass over pairs: commits the last step's live contacts if `commit` (its dt) is set,
    /// then, if `eval`, evaluates every touching pair into its force slot (else only commits).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pair_pass(
        &mut self,
        x: &[V],
        v: &[V],
        model: &Model,
        r: &[Real],
        commit: Option<Commit>,
        eval: bool,
    ) -> Sums {
        let n = x.len();
        let Some(l) = self.lists.as_mut() else { return Sums::default() };
        let (mat, omega, dt) = (&self.material, &self.omega, self.dt);
        let (pj, pstart) = (&l.pj, &l.pstart);
        let kn = mat.stiffness;
        // Equal masses (the usual case): the coefficients of a free pair and of a grain
        // against a pinned one, once.
        let uniform = self.uniform.map(|(m, im0)| {
            let c = |inv_m: Real, m_eff: Real| mat.coef(inv_m, (kn * m_eff).sqrt(), mat.zeta, mat.friction, dt);
            (c(im0 + im0, 0.5 * m), c(im0, m))
        });
        let im = &model.inv_mass;
        // The semi-implicit steps go lane by lane (`lanes`: the same bits as the loop below).
        let level = match self.path {
            PairPath::Lanes(l) => l,
            _ => simd::level(),
        };
        let full = match commit {
            None => Some(None),
            Some(Commit::Full(dt)) => Some(Some(dt)),
            Some(_) => None,
        }
        .filter(|_| self.path != PairPath::Loop);
        let full_commit = matches!(commit, Some(Commit::Full(_)));
        let (xf, vf, wf, pi) = (V::flat(x), V::flat(v), V::axial_flat(omega), &l.pi);
        let body = |c: usize, links: &mut [Link<V>], forces: &mut [PairForce<V>]| -> Sums {
            let (s0, s1) = (c * CHUNK, ((c + 1) * CHUNK).min(n));
            let base = pstart[s0] as usize;
            if let Some(commit) = full {
                let (a, b) = (base, pstart[s1] as usize);
                let k = lanes::Lanes {
                    x: xf,
                    v: vf,
                    omega: wf,
                    r,
                    im,
                    pi: &pi[a..b],
                    pj: &pj[a..b],
                    links,
                    forces,
                    mat,
                    uniform,
                    dt,
                    commit,
                    eval,
                };
                return simd::dispatch(level, k);
            }
            let mut sums = Sums::default();
            for i in s0..s1 {
                let (a, b) = (pstart[i] as usize, pstart[i + 1] as usize);
                let (xi, vi, wi, ri, imi) = (x[i], v[i], omega[i], r[i], im[i]);
                for p in a..b {
                    let j = pj[p] as usize;
                    let (l, pf) = (&mut links[p - base], &mut forces[p - base]);
                    let dx = x[j] - xi;
                    let d2 = dx.length_squared();
                    let s = ri + r[j];
                    let overlap = d2 < s * s && d2 > 0.0 && imi + im[j] != 0.0;
                    let touching = eval && overlap;
                    let committing = commit.is_some() && l.live();
                    // A contact that formed in the step being committed (module docs, energy books).
                    let formed = full_commit && !l.live() && overlap;
                    if !(touching || committing || formed) || d2 == 0.0 {
                        if eval {
                            end_contact(l, &mut sums);
                            *pf = PairForce::ZERO;
                        }
                        continue;
                    }
                    let dist = d2.sqrt();
                    let nrm = dx * (1.0 / dist);
                    let d = s - dist;
                    let (ai, aj) = (ri - 0.5 * d, r[j] - 0.5 * d);
                    let vc = vi - v[j] + spin::<V>(wi * ai + omega[j] * aj, nrm);
                    if let (Some(c), true) = (commit, l.live()) {
                        let vr = vi - v[j];
                        // The tangential force's power as applied (`Material::commit`).
                        let pt = l.ft.dot(vr) + axial_dot::<V>(pf.ti, wi) + axial_dot::<V>(pf.tj, omega[j]);
                        mat.commit(l, nrm, d, vc, mat.friction, c, pf.f, vr, pt, &mut sums);
                    } else if formed {
                        sums.lost_n += -mat.normal_energy(d);
                    }
                    if touching {
                        let c = match &uniform {
                            Some((free, pinned)) => {
                                if imi != 0.0 && im[j] != 0.0 {
                                    *free
                                } else {
                                    *pinned
                                }
                            }
                            None => {
                                let inv_m = imi + im[j];
                                mat.coef(inv_m, (kn / inv_m).sqrt(), mat.zeta, mat.friction, dt)
                            }
                        };
                        let (f, ft) = mat.evaluate(l, nrm, d, vc, &c, dt);
                        let t = moment(nrm, ft);
                        *pf = PairForce { f, ti: t * ai, tj: t * aj };
                        sums.pairs += 1;
                        sums.max_overlap = sums.max_overlap.max(d);
                    } else if eval {
                        end_contact(l, &mut sums);
                        *pf = PairForce::ZERO;
                    }
                }
            }
            sums
        };
        let bounds: Vec<usize> = (0..=n.div_ceil(CHUNK)).map(|c| pstart[(c * CHUNK).min(n)] as usize).collect();
        let links = split_at(&mut l.links, &bounds);
        let forces = split_at(&mut l.forces, &bounds);
        let parts: Vec<Sums> = par::map_vec(n, links.into_iter().zip(forces).collect(), |c, (a, b)| body(c, a, b));
        parts.into_iter().fold(Sums::default(), Sums::add)
    }

    /// The pass over grains: commits the last step's live wall contacts if `commit` is set;
    /// then, if `eval`, evaluates the wall contacts and gathers each grain's force into `f`
    /// and torque (its pairs as the first grain, then as the second, then its walls).
    ///
    /// Walls that are all planes (the usual case) take a loop of their own, the plane's
    /// arithmetic inline and nothing else: with any shape possible in the loop (a `match`, a
    /// call for the rounded ones, the normal kept for "xpbd") the pass ran 10 % more
    /// instructions (callgrind, 3,600 spheres over a floor) even where no grain touched a
    /// wall; through its own loop, within 1 % of the plane walls' pass before the shapes.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn grain_pass(
        &mut self,
        x: &[V],
        v: &[V],
        model: &Model,
        r: &[Real],
        commit: Option<Commit>,
        f: &mut [V],
        write: Write,
        eval: bool,
    ) -> Sums {
        match self.planes() {
            Some(planes) => self.grain_pass_with::<true>(&planes, x, v, model, r, commit, f, write, eval),
            None => self.grain_pass_with::<false>(&[], x, v, model, r, commit, f, write, eval),
        }
    }

    /// `grain_pass`, with `PLANES`: every wall is the half-space `planes[w]`.
    #[allow(clippy::too_many_arguments)]
    fn grain_pass_with<const PLANES: bool>(
        &mut self,
        planes: &[HalfSpace<V>],
        x: &[V],
        v: &[V],
        model: &Model,
        r: &[Real],
        commit: Option<Commit>,
        f: &mut [V],
        write: Write,
        eval: bool,
    ) -> Sums {
        let n = x.len();
        let Some(l) = self.lists.as_mut() else { return Sums::default() };
        let (mat, omega, walls, dt) = (&self.material, &self.omega, &self.walls, self.dt);
        let (pstart, rstart, rpair, wall, wstart, forces) =
            (&l.pstart, &l.rstart, &l.rpair, &l.wall, &l.wstart, &l.forces);
        let kn = mat.stiffness;
        let wall_coef: Option<Vec<Coef>> = self
            .uniform
            .map(|(m, im0)| walls.iter().map(|w| mat.coef(im0, (kn * m).sqrt(), w.zeta, w.friction, dt)).collect());
        let im = &model.inv_mass;
        let full_commit = matches!(commit, Some(Commit::Full(_)));
        type Kept<'a, V> = (&'a mut [Link<V>], &'a mut [V], &'a mut [Real]);
        let body = |c: usize, f: &mut [V], tq: &mut [V::Axial], (wl, wn, wa): Kept<'_, V>| -> Sums {
            let s0 = c * CHUNK;
            let base = wstart[s0] as usize;
            let mut sums = Sums::default();
            for k in 0..tq.len() {
                let i = s0 + k;
                let ri = r[i];
                let (a, b) = (wstart[i] as usize, wstart[i + 1] as usize);
                if im[i] == 0.0 || ri <= 0.0 {
                    if eval {
                        write.put(&mut f[k], V::ZERO);
                        tq[k] = V::AXIAL_ZERO;
                        wl[a - base..b - base].iter_mut().for_each(|l| end_contact(l, &mut sums));
                    }
                    continue;
                }
                let mut force = V::ZERO;
                let mut torque = V::AXIAL_ZERO;
                if eval {
                    for q in &forces[pstart[i] as usize..pstart[i + 1] as usize] {
                        force += q.f;
                        torque = torque + q.ti;
                    }
                    for &p in &rpair[rstart[i] as usize..rstart[i + 1] as usize] {
                        let q = &forces[p as usize];
                        force -= q.f;
                        torque = torque + q.tj;
                    }
                }
                for q in a..b {
                    let w = &walls[wall[q] as usize];
                    let l = &mut wl[q - base];
                    // Signed distance and normal into the allowed side (a plane: (x − p)·n and
                    // n, as this pass always computed them).
                    let surface = if PLANES { planes[wall[q] as usize].closest(x[i]) } else { w.closest(x[i]) };
                    let sd = surface.distance;
                    let touching = eval && sd < ri;
                    let formed = full_commit && !l.live() && sd < ri;
                    if !(touching || formed || (commit.is_some() && l.live())) {
                        if eval {
                            end_contact(l, &mut sums);
                        }
                        continue;
                    }
                    let nrm = -surface.normal;
                    let d = ri - sd;
                    let ai = ri - 0.5 * d;
                    let vc = v[i] + spin::<V>(omega[i] * ai, nrm);
                    if let (Some(c), true) = (commit, l.live()) {
                        // The force of the last evaluation, f_t − n f_n with that evaluation's
                        // normal (a plane's is fixed).
                        let n0 = if PLANES { surface.normal } else { wn[q - base] };
                        let fp = l.ft + n0 * l.fn_;
                        // Friction's power as applied: its torque (n₀' × f_t)·a₀ with the
                        // evaluation's normal into the wall n₀' = −n₀ and lever a₀.
                        let pt = l.ft.dot(v[i]) + axial_dot::<V>(moment(n0 * -1.0, l.ft) * wa[q - base], omega[i]);
                        mat.commit(l, nrm, d, vc, w.friction, c, fp, v[i], pt, &mut sums);
                    } else if formed {
                        sums.lost_n += -mat.normal_energy(d);
                    }
                    if touching {
                        let c = match &wall_coef {
                            Some(c) => c[wall[q] as usize],
                            None => mat.coef(im[i], (kn * model.mass[i]).sqrt(), w.zeta, w.friction, dt),
                        };
                        let (fw, ft) = mat.evaluate(l, nrm, d, vc, &c, dt);
                        if !PLANES {
                            wn[q - base] = surface.normal;
                        }
                        wa[q - base] = ai;
                        force += fw;
                        torque = torque + moment(nrm, ft) * ai;
                        sums.walls += 1;
                        sums.max_overlap = sums.max_overlap.max(d);
                    } else if eval {
                        end_contact(l, &mut sums);
                    }
                }
                if eval {
                    write.put(&mut f[k], force);
                    tq[k] = torque;
                }
            }
            sums
        };
        let bounds: Vec<usize> = (0..=n.div_ceil(CHUNK)).map(|c| wstart[(c * CHUNK).min(n)] as usize).collect();
        let torque = &mut self.torque;
        let wls = split_at(&mut l.wlinks, &bounds);
        let wns = split_at(&mut l.wnormal, &bounds);
        let was = split_at(&mut l.wlever, &bounds);
        let kept = wls.into_iter().zip(wns).zip(was).map(|((a, b), c)| (a, b, c));
        let items = f.chunks_mut(CHUNK).zip(torque.chunks_mut(CHUNK)).zip(kept).collect();
        let parts: Vec<Sums> = par::map_vec(n, items, |c, ((f, t), w)| body(c, f, t, w));
        parts.into_iter().fold(Sums::default(), Sums::add)
    }

    /// The walls as half-spaces, if every one is a plane.
    fn planes(&self) -> Option<Vec<HalfSpace<V>>> {
        self.walls
            .iter()
            .map(|w| match &w.shape {
                AnyShape::HalfSpace(h) => Some(h.clone()),
                _ => None,
            })
            .collect()
    }

    /// Entries per live contact in `history`: first grain, partner, ξ, its energy, and with
    /// rolling resistance θ_r and its energy.
    pub(super) fn record_width(&self) -> usize {
        3 + V::DIM + if self.material.rolling_friction > 0.0 { V::AXIAL_DIM + 1 } else { 0 }
    }

    /// The rolling resistance pass (only with μ_r > 0), after the pair and grain passes: commits
    /// the last step's live rolling springs if `commit` (its dt) is set, then, if `eval`,
    /// evaluates each touching contact's rolling torque (the pair and grain passes have set
    /// its normal force) and adds it to the grains' torques, each grain gathering in the fixed
    /// order of `grain_pass`. A contact's relative rolling velocity is the tangential part of
    /// ω_i − ω_j (Ai et al. 2011; ω_j = 0 for a wall), its rolling radius
    /// R* = r_i r_j/(r_i + r_j) (r_i for a wall), and I_r = 1/(1/(I_i + m_i r_i²) +
    /// 1/(I_j + m_j r_j²)) the moment of inertia of its dashpot (a pinned grain or a wall: ∞).
    pub(super) fn roll_pass(&mut self, x: &[V], model: &Model, r: &[Real], commit: Option<Real>, eval: bool) -> Sums {
        // Plane walls alone take their own loop, as in `grain_pass` (4 % more instructions
        // through the one for any shape, 3,600 spheres rolling on a floor).
        match self.planes() {
            Some(planes) => self.roll_pass_with::<true>(&planes, x, model, r, commit, eval),
            None => self.roll_pass_with::<false>(&[], x, model, r, commit, eval),
        }
    }

    /// `roll_pass`, with `PLANES`: every wall is the half-space `planes[w]`.
    fn roll_pass_with<const PLANES: bool>(
        &mut self,
        planes: &[HalfSpace<V>],
        x: &[V],
        model: &Model,
        r: &[Real],
        commit: Option<Real>,
        eval: bool,
    ) -> Sums {
        let n = x.len();
        let Some(l) = self.lists.as_mut() else { return Sums::default() };
        let (mat, omega, walls, dt) = (&self.material, &self.omega, &self.walls, self.dt);
        let Lists { pj, pstart, rstart, rpair, wall, wstart, links, wlinks, roll, wroll, rt, .. } = l;
        let (pj, pstart, rstart, rpair, wall, wstart, links, wlinks) =
            (&*pj, &*pstart, &*rstart, &*rpair, &*wall, &*wstart, &*links, &*wlinks);
        let im = &model.inv_mass;
        let spin_in = 1.0 / (mat.inertia_factor + 1.0);
        // 1/(I + m r²) of grain i (0: pinned).
        let inv_ic = |i: usize| im[i] * spin_in / (r[i] * r[i]);
        // The pairs: their springs and torques.
        let pairs = |c: usize, rolls: &mut [Roll<V>], rts: &mut [V::Axial]| -> Sums {
            let (s0, s1) = (c * CHUNK, ((c + 1) * CHUNK).min(n));
            let base = pstart[s0] as usize;
            let mut sums = Sums::default();
            for i in s0..s1 {
                for p in pstart[i] as usize..pstart[i + 1] as usize {
                    let (lk, rl, rtp) = (&links[p], &mut rolls[p - base], &mut rts[p - base]);
                    let on = eval && lk.live();
                    if !(rl.live || on) {
                        continue;
                    }
                    let j = pj[p] as usize;
                    let dx = x[j] - x[i];
                    let d2 = dx.length_squared();
                    let nrm = if d2 > 0.0 { dx * (1.0 / d2.sqrt()) } else { dx };
                    let d = r[i] + r[j] - d2.sqrt();
                    let reff = r[i] * r[j] / (r[i] + r[j]);
                    let wrel = omega[i] + omega[j] * -1.0;
                    let wr = rolling_part::<V>(wrel, nrm);
                    if let (Some(h), true) = (commit, rl.live) {
                        mat.roll_commit(rl, d, reff, wr, wrel, h, &mut sums);
                    }
                    if on {
                        if !rl.live {
                            *rl = Roll { live: true, ..Roll::NONE };
                        }
                        let inv_ir = inv_ic(i) + inv_ic(j);
                        *rtp = mat.roll_evaluate(rl, nrm, d, wr, lk.fn_, reff, inv_ir, dt);
                    } else if eval {
                        sums.broken += rl.b;
                        *rl = Roll::NONE;
                        *rtp = V::AXIAL_ZERO;
                    }
                }
            }
            sums
        };
        let bounds: Vec<usize> = (0..=n.div_ceil(CHUNK)).map(|c| pstart[(c * CHUNK).min(n)] as usize).collect();
        let (a, b) = (split_at(roll, &bounds), split_at(rt, &bounds));
        let parts: Vec<Sums> = par::map_vec(n, a.into_iter().zip(b).collect(), |c, (a, b)| pairs(c, a, b));
        let mut sums = parts.into_iter().fold(Sums::default(), Sums::add);
        // The grains: their walls' springs, and each grain's rolling torques gathered.
        let rt = &*rt;
        let grains = |c: usize, tq: &mut [V::Axial], wr_: &mut [Roll<V>]| -> Sums {
            let s0 = c * CHUNK;
            let base = wstart[s0] as usize;
            let mut sums = Sums::default();
            for k in 0..tq.len() {
                let i = s0 + k;
                let mut t = V::AXIAL_ZERO;
                if eval {
                    for q in &rt[pstart[i] as usize..pstart[i + 1] as usize] {
                        t = t + *q;
                    }
                    for &p in &rpair[rstart[i] as usize..rstart[i + 1] as usize] {
                        t = t + rt[p as usize] * -1.0;
                    }
                }
                for q in wstart[i] as usize..wstart[i + 1] as usize {
                    let (lk, rl) = (&wlinks[q], &mut wr_[q - base]);
                    let on = eval && lk.live();
                    if !(rl.live || on) {
                        continue;
                    }
                    let w = wall[q] as usize;
                    let surface = if PLANES { planes[w].closest(x[i]) } else { walls[w].closest(x[i]) };
                    let nrm = -surface.normal;
                    let d = r[i] - surface.distance;
                    let wr = rolling_part::<V>(omega[i], nrm);
                    if let (Some(h), true) = (commit, rl.live) {
                        mat.roll_commit(rl, d, r[i], wr, omega[i], h, &mut sums);
                    }
                    if on {
                        if !rl.live {
                            *rl = Roll { live: true, ..Roll::NONE };
                        }
                        t = t + mat.roll_evaluate(rl, nrm, d, wr, lk.fn_, r[i], inv_ic(i), dt);
                    } else if eval {
                        sums.broken += rl.b;
                        *rl = Roll::NONE;
                    }
                }
                if eval && im[i] != 0.0 && r[i] > 0.0 {
                    tq[k] = tq[k] + t;
                }
            }
            sums
        };
        let bounds: Vec<usize> = (0..=n.div_ceil(CHUNK)).map(|c| wstart[(c * CHUNK).min(n)] as usize).collect();
        let torque = &mut self.torque;
        let w = split_at(wroll, &bounds);
        let parts: Vec<Sums> = par::map_vec(n, torque.chunks_mut(CHUNK).zip(w).collect(), |c, (t, w)| grains(c, t, w));
        sums = sums.add(parts.into_iter().fold(Sums::default(), Sums::add));
        sums
    }

    /// Commits the last step's contacts now (the deferred part of `end_step`).
    pub(super) fn settle_now(&mut self, x: &[V], v: &[V], model: &Model) {
        let Some(c) = self.take_pending() else { return };
        self.commit_pass(x, v, model, c);
    }

    /// The pending commit, if any (cleared).
    pub(super) fn take_pending(&mut self) -> Option<Commit> {
        let prebooked = std::mem::take(&mut self.prebooked);
        self.pending.take().map(|dt| if prebooked { Commit::Springs(dt) } else { Commit::Full(dt) })
    }

    /// A pass of `c` over the live contacts alone (no evaluation).
    pub(super) fn commit_pass(&mut self, x: &[V], v: &[V], model: &Model, c: Commit) {
        let Some(r) = radii(model) else { return };
        if self.lists.as_ref().is_none_or(|l| l.x.len() != x.len()) {
            return;
        }
        // Nothing is evaluated: the forces go to a scratch that is not written (kept: "xpbd"
        // commits twice per substep).
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.resize(x.len(), V::ZERO);
        let s = self.pair_pass(x, v, model, r, Some(c), false);
        let mut s = s.add(self.grain_pass(x, v, model, r, Some(c), &mut scratch, Write::Overwrite, false));
        self.scratch = scratch;
        if let (true, Some(h)) = (self.material.rolling_friction > 0.0, roll_step(c)) {
            s = s.add(self.roll_pass(x, model, r, Some(h), false));
        }
        self.dissipated[0] += s.lost_n;
        self.dissipated[1] += s.lost_t;
    }
}
