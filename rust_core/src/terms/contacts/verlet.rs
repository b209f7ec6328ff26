//! The contacts' Verlet lists: when a grain has moved far enough for them to be stale, and
//! their rebuild (candidates within the skin, sorted so that pairs and their books keep one order).
use super::*;

impl<V: Vector> Contacts<V> {
    /// Whether the lists must be rebuilt: none yet, another particle count, radii changed, or
    /// a grain moved more than half the skin since the build.
    pub(super) fn stale(&self, x: &[V], r: &[Real]) -> bool {
        let Some(l) = &self.lists else { return true };
        if l.x.len() != x.len() {
            return true;
        }
        let lim = 0.25 * l.skin * l.skin;
        let level = simd::level();
        // Branch-free (the largest move, any radius changed) so that it vectorises.
        par::reduce(
            x.len(),
            false,
            |a, b| a || b,
            |range| {
                simd::vectorized(
                    level,
                    #[inline(always)]
                    || {
                        let (mut far, mut changed) = (0.0, false);
                        for i in range {
                            let d = (x[i] - l.x[i]).length_squared();
                            far = if d > far { d } else { far };
                            changed |= r[i] != l.r[i];
                        }
                        far > lim || changed
                    },
                )
            },
        )
    }

    /// Builds the candidate lists at `x` and carries the live contacts (or the loaded ones)
    /// over; returns the energy of springs whose pair is no longer a candidate (moved apart
    /// since the last build by more than the skin: the grains were placed by hand).
    pub(super) fn rebuild(&mut self, x: &[V], r: &[Real]) -> Real {
        let n = x.len();
        let r_max = r.iter().fold(0.0, |a: Real, &b| a.max(b));
        let skin = SKIN * r_max;
        let reach = 2.0 * r_max + skin;
        if r_max > 0.0 && self.cells.as_ref().is_none_or(|c| c.cell_size() != reach) {
            // [alloc] The list `reserve` made room in keeps that room at its new size.
            if self.cells.as_mut().is_none_or(|c| c.set_cell_size(reach).is_err()) {
                self.cells = CellList::new(reach, V::DIM).ok();
            }
        }
        if let Some(c) = self.cells.as_mut().filter(|_| r_max > 0.0) {
            c.build(x);
        }
        if let Err(e) = self.room_for_lists(x, r, skin) {
            // Nothing taken or built: the step is refused (`OwnState::refused`) and rolled back.
            self.refused = Some(e);
            self.lists = None;
            return 0.0;
        }
        let carry = match self.seed.take() {
            Some(s) => s,
            None => self.carry(),
        };
        let (cells, walls) = (self.cells.as_ref().filter(|_| r_max > 0.0), &self.walls);
        let carry = &carry;
        let rolling = self.material.rolling_friction > 0.0;
        let part = |c: usize| -> Part<V> {
            let (s0, s1) = (c * CHUNK, ((c + 1) * CHUNK).min(n));
            let lo = carry.partition_point(|k| (k.i as usize) < s0);
            let hi = carry.partition_point(|k| (k.i as usize) < s1);
            let mut carried = carry[lo..hi].iter().peekable();
            let mut out = Part::default();
            let mut cand: Vec<u32> = Vec::with_capacity(32);
            for i in s0..s1 {
                let ri = r[i];
                cand.clear();
                if let Some(cl) = cells.filter(|_| ri > 0.0) {
                    for range in cl.query(cl.cell_of(x[i])).iter() {
                        for &j in &cl.order[range] {
                            let ju = j as usize;
                            if ju <= i || r[ju] <= 0.0 {
                                continue;
                            }
                            let s = ri + r[ju] + skin;
                            if (x[ju] - x[i]).length_squared() < s * s {
                                cand.push(j);
                            }
                        }
                    }
                }
                cand.sort_unstable();
                let p0 = out.pj.len();
                out.pj.extend_from_slice(&cand);
                out.links.resize(out.pj.len(), Link::NONE);
                if rolling {
                    out.roll.resize(out.pj.len(), Roll::NONE);
                }
                out.pcount.push(cand.len() as u32);
                let w0 = out.wall.len();
                if ri > 0.0 {
                    for (w, wall) in walls.iter().enumerate() {
                        // The distance changes by at most a grain's move, less than the skin
                        // until the next build.
                        if wall.closest(x[i]).distance < ri + skin {
                            out.wall.push(w as u32);
                        }
                    }
                }
                out.wlinks.resize(out.wall.len(), Link::NONE);
                if rolling {
                    out.wroll.resize(out.wall.len(), Roll::NONE);
                }
                out.wcount.push((out.wall.len() - w0) as u32);
                while let Some(k) = carried.next_if(|k| k.i as usize == i) {
                    let (ids, links, rolls, at) = if k.wall {
                        (&out.wall[w0..], &mut out.wlinks, &mut out.wroll, w0)
                    } else {
                        (&out.pj[p0..], &mut out.links, &mut out.roll, p0)
                    };
                    match ids.binary_search(&k.j) {
                        Ok(q) => {
                            links[at + q] = Link::carried(k.xi, k.u);
                            if rolling {
                                rolls[at + q] = Roll { theta: k.theta, m: V::AXIAL_ZERO, b: k.ur, live: true };
                            }
                        }
                        Err(_) => out.dropped += k.u + k.ur,
                    }
                }
            }
            out
        };
        let chunks = n.div_ceil(CHUNK);
        let parts: Vec<Part<V>> = par::map_chunks(n, chunks, part);
        let mut l = self.lists.take().or_else(|| self.room.take()).unwrap_or_default();
        for v in [&mut l.pi, &mut l.pj, &mut l.pstart, &mut l.rpair, &mut l.rstart, &mut l.wall, &mut l.wstart] {
            v.clear();
        }
        l.links.clear();
        l.wlinks.clear();
        l.roll.clear();
        l.wroll.clear();
        l.pstart.push(0);
        l.wstart.push(0);
        let mut dropped = 0.0;
        for p in &parts {
            for &k in &p.pcount {
                l.pstart.push(l.pstart.last().copied().unwrap_or(0) + k);
            }
            for &k in &p.wcount {
                l.wstart.push(l.wstart.last().copied().unwrap_or(0) + k);
            }
            l.pj.extend_from_slice(&p.pj);
            l.links.extend_from_slice(&p.links);
            l.wall.extend_from_slice(&p.wall);
            l.wlinks.extend_from_slice(&p.wlinks);
            l.roll.extend_from_slice(&p.roll);
            l.wroll.extend_from_slice(&p.wroll);
            dropped += p.dropped;
        }
        for i in 0..n {
            let k = (l.pstart[i + 1] - l.pstart[i]) as usize;
            l.pi.extend(std::iter::repeat_n(i as u32, k));
        }
        // The pairs by second grain, in pair order (a counting sort).
        l.rstart.resize(n + 1, 0);
        for &j in &l.pj {
            l.rstart[j as usize + 1] += 1;
        }
        for j in 0..n {
            l.rstart[j + 1] += l.rstart[j];
        }
        let mut fill = std::mem::take(&mut l.fill);
        fill.clear();
        fill.extend_from_slice(&l.rstart[..n]);
        l.rpair.resize(l.pj.len(), 0);
        for (p, &j) in l.pj.iter().enumerate() {
            l.rpair[fill[j as usize] as usize] = p as u32;
            fill[j as usize] += 1;
        }
        l.fill = fill;
        l.wnormal.clear();
        l.wnormal.resize(l.wall.len(), V::ZERO);
        l.wlever.clear();
        l.wlever.resize(l.wall.len(), 0.0);
        l.forces.clear();
        l.forces.resize(l.pj.len(), PairForce::ZERO);
        l.rt.clear();
        if rolling {
            l.rt.resize(l.pj.len(), V::AXIAL_ZERO);
        }
        l.x.clear();
        l.x.extend_from_slice(x);
        l.r.clear();
        l.r.extend_from_slice(r);
        l.skin = skin;
        self.lists = Some(l);
        dropped
    }

    /// (`crate::alloc`) Whether the memory of a build at `x` can be had. Its lists grow inside
    /// parallel parts, where a refused allocation would abort the process, by some 160 bytes a
    /// candidate pair (the parts' and the lists' copies). Between builds of the same grains and
    /// radii no grain moves more than half the skin, so room for 4 times the last build's
    /// pairs and 16 a grain answers at once. Else a bound on the candidates (every grain of the
    /// neighbouring cells) is checked, at the cost of the cells' ranges alone; only where that
    /// much cannot be had are the candidates counted, and their bytes checked.
    /// `Error::OutOfMemory` naming the pairs if those cannot be had either.
    fn room_for_lists(&self, x: &[V], r: &[Real], skin: Real) -> Result<()> {
        let Some(cl) = self.cells.as_ref().filter(|_| r.iter().any(|&ri| ri > 0.0)) else { return Ok(()) };
        let rolling = self.material.rolling_friction > 0.0;
        let per_pair = Need::bytes_of::<u32>(5)
            + Need::bytes_of::<Link<V>>(2)
            + Need::bytes_of::<PairForce<V>>(1)
            + if rolling { Need::bytes_of::<Roll<V>>(2) + Need::bytes_of::<V::Axial>(1) } else { 0 };
        let need = |pairs: u64| {
            let what = format!("the contact lists of {} candidate pairs", count(pairs as u128));
            Need::new("step", pairs as u128 * per_pair, what)
        };
        let pairs = |exact: bool| {
            par::reduce(
                x.len(),
                0u64,
                |a, b| a + b,
                |range| {
                    let mut c = 0u64;
                    for i in range.filter(|&i| r[i] > 0.0) {
                        for q in cl.query(cl.cell_of(x[i])).iter() {
                            if !exact {
                                c += q.len() as u64;
                                continue;
                            }
                            for &j in &cl.order[q] {
                                let ju = j as usize;
                                let s = r[i] + r[ju] + skin;
                                c += (ju > i && r[ju] > 0.0 && (x[ju] - x[i]).length_squared() < s * s) as u64;
                            }
                        }
                    }
                    c
                },
            )
        };
        if let Some(l) = self.lists.as_ref().filter(|l| l.x.len() == x.len() && l.r == r) {
            let likely = need(4 * (l.pj.len() + l.wall.len()) as u64 + 16 * x.len() as u64);
            if likely.room(likely.bytes()).is_ok() {
                return Ok(());
            }
        }
        let bound = need(pairs(false));
        if bound.room(bound.bytes()).is_ok() {
            return Ok(());
        }
        let exact = need(pairs(true));
        exact.check()?;
        exact.room(exact.bytes())
    }
}
