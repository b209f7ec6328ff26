//! What the two particle fluids on the device (WCSPH `sph::Sph`, DFSPH `dfsph::Dfsph`) keep
//! alike: the particles' positions and velocities, checked and uploaded; the cell list of cells
//! 2h wide over the box and its build (`cells.wgsl`); the static wall particles sorted by cell;
//! each particle's neighbour list. Each fluid adds its own fields, kernels and books; both bind
//! these buffers in their shaders' order.
use crate::cells::{write_cell_params, CellBuild};
use crate::sph::invalid;
use crate::{Gpu, GpuError, Precision, Result};

/// The box a fluid lives in and its resolution: `dim` (2 or 3), smoothing length `h` (m), the
/// box's corners (m; z ignored in 2D), and the particles per unit volume ρ0/m (1/m^dim), which
/// sizes the neighbour lists.
pub(crate) struct Region {
    pub dim: usize,
    pub h: f64,
    pub lower: [f64; 3],
    pub upper: [f64; 3],
    pub number_density: f64,
}

/// The state, cell list, walls and neighbour lists of a fluid on the device (module docs).
pub(crate) struct Tank {
    /// Fluid particles.
    pub n: usize,
    /// Wall particles kept (within reach, 2h, of the box).
    pub walls: usize,
    /// Cells along x, y, z (z = 1 in 2D), each 2h wide.
    pub cells: [usize; 3],
    /// Entries of each particle's neighbour list (`list_cap`; 0: the passes read the cells).
    pub cap: u32,
    /// The state in the caller's order, `dim` values a particle (m, m/s).
    pub pos: wgpu::Buffer,
    pub vel: wgpu::Buffer,
    /// The cell list (`cells.wgsl`): each particle's cell, each cell's first slot, the particles
    /// by cell.
    pub cell_of: wgpu::Buffer,
    pub start: wgpu::Buffer,
    pub order: wgpu::Buffer,
    /// The walls as `sort_walls` returns them: `dim` coordinates then Ψ_b each, and per cell
    /// its first wall.
    pub wall: wgpu::Buffer,
    pub wall_start: wgpu::Buffer,
    /// The neighbour lists (`cap` entries a particle, j-major) and their lengths.
    pub nbr: wgpu::Buffer,
    pub nlen: wgpu::Buffer,
    /// `cells.wgsl`'s build over `pos`.
    pub cell_build: CellBuild,
    /// Bound by the build only: the counts, the unused neighbour counts, the cell parameters.
    _keep: [wgpu::Buffer; 3],
}

impl Tank {
    /// Checks and uploads `n` particles (`positions`, `velocities` flat, n·dim; m, m/s; every
    /// position in the box) and the wall particles `walls` (flat, M·dim, m) with their Ψ_b
    /// `psi` (kg, one each), and builds the cell list's buffers; `label` ("SPH", "DFSPH")
    /// begins every buffer's name.
    ///
    /// Errors: `Unsupported` for ragged or non-finite arrays, a position outside the box, more
    /// than 2^31 particles or cells, bad walls (`sort_walls`), buffers over the adapter's
    /// limits; `OutOfMemory` naming the buffer.
    pub(crate) fn new(
        gpu: &Gpu,
        precision: Precision,
        label: &str,
        region: &Region,
        (positions, velocities): (&[f64], &[f64]),
        (walls, psi): (&[f64], &[f64]),
    ) -> Result<Self> {
        let d = region.dim;
        if !positions.len().is_multiple_of(d) || velocities.len() != positions.len() {
            return Err(invalid(
                "positions",
                format_args!(
                    "{} positions and {} velocities: both must hold dim = {d} values per particle",
                    positions.len(),
                    velocities.len()
                ),
            ));
        }
        let n = positions.len() / d;
        if n as u64 >= 1 << 31 {
            return Err(invalid("positions", format_args!("{n} particles: at most 2^31")));
        }
        if let Some(k) = positions.iter().chain(velocities).position(|v| !v.is_finite()) {
            let (what, k) = if k < positions.len() { ("positions", k) } else { ("velocities", k - positions.len()) };
            return Err(invalid(what, format_args!("particle {} has a non-finite value", k / d)));
        }
        let (lo, hi) = (&region.lower, &region.upper);
        for (i, x) in positions.chunks_exact(d).enumerate() {
            if (0..d).any(|a| !(x[a] >= lo[a] && x[a] <= hi[a])) {
                return Err(invalid("positions", format_args!("particle {i} at {x:?} is outside the box")));
            }
        }
        let cells = box_cells(d, region.h, lo, hi)?;
        let ncells = cells.iter().product::<usize>() as u64;
        let (wall_data, wall_starts) = sort_walls((d, region.h, lo), cells, walls, psi)?;
        let rb = precision.bytes();
        let (nn, dd) = (n as u64, d as u64);
        use wgpu::BufferUsages as U;
        let st = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let name = |what: &str| format!("{label} {what}");
        let pos = gpu.buffer(&name("positions"), nn * dd * rb, st)?;
        let vel = gpu.buffer(&name("velocities"), nn * dd * rb, st)?;
        let cell_of = gpu.buffer(&name("cells"), nn * 4, st)?;
        let counts = gpu.buffer(&name("cell counts"), ncells * 4, st)?;
        let start = gpu.buffer(&name("cell starts"), (ncells + 1) * 4, st)?;
        let order = gpu.buffer(&name("cell order"), nn * 4, st)?;
        let found = gpu.buffer(&name("unused neighbour counts"), 16, st)?;
        let cell_params = gpu.buffer(&name("cell list parameters"), 32 + 8 * rb, U::UNIFORM | U::COPY_DST)?;
        let wall = gpu.buffer(&name("wall particles"), wall_data.len() as u64 * rb, st)?;
        let wall_start = gpu.buffer(&name("wall cell starts"), (ncells + 1) * 4, st)?;
        let cap = list_cap(d, region.h, region.number_density, n, gpu.adapter());
        let (cap, nbr) = neighbour_lists(gpu, &name("neighbour lists"), cap, n)?;
        let nlen = gpu.buffer(&name("neighbour counts"), nn.max(1) * 4, st)?;
        let cell_bufs = [&cell_params, &pos, &cell_of, &counts, &start, &order, &found];
        let cell_build = CellBuild::new(gpu, precision, &name("cell list"), cell_bufs, ncells as usize, &[])?;
        write_cell_params(gpu, precision, &cell_params, (n, d), cells, (*lo, 2.0 * region.h));
        if n > 0 {
            gpu.upload(precision, &pos, positions);
            gpu.upload(precision, &vel, velocities);
        }
        let nw = wall_starts.last().copied().unwrap_or(0) as usize;
        if nw > 0 {
            gpu.upload(precision, &wall, &wall_data);
        }
        gpu.queue.write_buffer(&wall_start, 0, bytemuck::cast_slice(&wall_starts));
        Ok(Self {
            n,
            walls: nw,
            cells,
            cap,
            pos,
            vel,
            cell_of,
            start,
            order,
            wall,
            wall_start,
            nbr,
            nlen,
            cell_build,
            _keep: [counts, found, cell_params],
        })
    }

    /// Sets the neighbour lists' length (at most the one `new` chose; 0: none), for tests.
    pub(crate) fn set_list_cap(&mut self, cap: u32) {
        self.cap = cap.min(self.cap);
    }
}

/// Cells along x, y, z (z = 1 in 2D) of a box [lower, upper] in `dim` dimensions, each 2h wide
/// (the support): the cell list covers [lower, lower + cells · 2h] ⊇ the box. `Unsupported`
/// naming `h` past 2^31 cells.
pub(crate) fn box_cells(dim: usize, h: f64, lower: &[f64; 3], upper: &[f64; 3]) -> Result<[usize; 3]> {
    let mut n = [1usize; 3];
    let mut total = 1u64;
    for (a, na) in n.iter_mut().enumerate().take(dim) {
        let m = ((upper[a] - lower[a]) / (2.0 * h)).ceil().max(1.0);
        if m >= 2f64.powi(31) {
            return Err(invalid("h", format_args!("{m} cells of 2h along axis {a}: at most 2^31 cells")));
        }
        *na = m as usize;
        total = total.saturating_mul(m as u64);
    }
    if total >= 1 << 31 {
        return Err(invalid("h", format_args!("{total} cells of 2h in the box: at most 2^31")));
    }
    Ok(n)
}

/// Entries of each particle's neighbour list (`sph.wgsl`, `dfsph.wgsl`): 1.3 × a full
/// neighbourhood, the ball of radius 2h holding `density` particles per unit volume (1/m^dim;
/// a lattice at rest holds a little more than the ball's mean: 80 against 73.6 in 3D at h =
/// 1.3 Δx), a multiple of 4; 0 (no lists) where that is over 4096 or the lists would not fit
/// one binding of the adapter, as lists too short for most particles would be read past for the
/// cells anyway. The lists are an index only: a particle with more neighbours reads the cells.
pub(crate) fn list_cap(dim: usize, h: f64, density: f64, n: usize, adapter: &crate::AdapterSummary) -> u32 {
    use std::f64::consts::PI;
    let ball = if dim == 2 { PI * 4.0 * h * h } else { 4.0 / 3.0 * PI * 8.0 * h * h * h };
    let want = (1.3 * ball * density).ceil().max(8.0);
    let cap = (want as u64).div_ceil(4) * 4;
    let fits = adapter.max_storage_binding.min(adapter.max_buffer) / (4 * n.max(1) as u64);
    if want > 4096.0 || cap > fits {
        0
    } else {
        cap as u32
    }
}

/// The neighbour lists' buffer of `n` particles, `cap` entries each (`list_cap`), and the cap
/// it holds: where the device has no room for it, none (cap 0: the passes read the cells, with
/// the same result, more slowly), as the lists are an index, not state.
pub(crate) fn neighbour_lists(gpu: &Gpu, what: &str, cap: u32, n: usize) -> Result<(u32, wgpu::Buffer)> {
    use wgpu::BufferUsages as U;
    let usage = U::STORAGE | U::COPY_SRC | U::COPY_DST;
    match gpu.buffer(what, (n as u64 * cap as u64).max(1) * 4, usage) {
        Err(GpuError::OutOfMemory { .. }) if cap > 0 => Ok((0, gpu.buffer(what, 4, usage)?)),
        b => Ok((cap, b?)),
    }
}

/// The wall particles `walls` (flat, `dim` each) with their Ψ `psi`, checked, in the order the
/// shaders (sph, dfsph) read them: sorted by (cell, index) over the fluid's `cells` of 2h from the box's lower
/// corner, a wall within one cell outside the grid clamped into its outer cell (still a neighbour
/// cell of every cell within 2h of it), one farther dropped. Returns the walls as `dim`
/// coordinates then Ψ each, and per cell its first wall (`cells` + 1 entries, the last the count).
pub(crate) fn sort_walls(
    (d, h, lower): (usize, f64, &[f64; 3]),
    cells: [usize; 3],
    walls: &[f64],
    psi: &[f64],
) -> Result<(Vec<f64>, Vec<u32>)> {
    if !walls.len().is_multiple_of(d) {
        return Err(invalid(
            "walls",
            format_args!("{} values: must hold dim = {d} values per wall particle", walls.len()),
        ));
    }
    let m = walls.len() / d;
    if m as u64 >= 1 << 31 {
        return Err(invalid("walls", format_args!("{m} wall particles: at most 2^31")));
    }
    if psi.len() != m {
        return Err(invalid("psi", format_args!("{} values for {m} wall particles: one each", psi.len())));
    }
    if let Some(k) = walls.iter().position(|v| !v.is_finite()) {
        return Err(invalid("walls", format_args!("wall particle {} has a non-finite value", k / d)));
    }
    if let Some(b) = psi.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(invalid("psi", format_args!("entry {b} is {} (must be finite and > 0)", psi[b])));
    }
    let cell = 2.0 * h;
    let mut keyed: Vec<(usize, usize)> = Vec::new();
    'walls: for (b, w) in walls.chunks_exact(d).enumerate() {
        let (mut flat, mut stride) = (0usize, 1usize);
        for a in 0..d {
            let f = ((w[a] - lower[a]) / cell).floor();
            if !(f >= -1.0 && f <= cells[a] as f64) {
                continue 'walls;
            }
            flat += stride * (f.max(0.0) as usize).min(cells[a] - 1);
            stride *= cells[a];
        }
        keyed.push((flat, b));
    }
    keyed.sort_unstable();
    let ncells: usize = cells.iter().product();
    let mut starts = vec![0u32; ncells + 1];
    for &(c, _) in &keyed {
        starts[c + 1] += 1;
    }
    for c in 0..ncells {
        starts[c + 1] += starts[c];
    }
    let mut data = Vec::with_capacity(keyed.len() * (d + 1));
    for &(_, b) in &keyed {
        data.extend_from_slice(&walls[d * b..d * b + d]);
        data.push(psi[b]);
    }
    Ok((data, starts))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_neighbour_lists_hold_a_neighbourhood_and_a_margin_or_nothing() {
        let a = |binding: u64| crate::AdapterSummary {
            name: "test".into(),
            backend: "none".into(),
            kind: "cpu".into(),
            driver: String::new(),
            f64: false,
            max_storage_binding: binding,
            max_buffer: binding,
        };
        let (dx, big) = (0.01, a(1 << 31));
        // h = 1.3 Δx: 1.3 × 21.2 and 1.3 × 73.6 neighbours, to a multiple of 4 (a lattice holds 20 and 80).
        assert_eq!(list_cap(2, 1.3 * dx, 1.0 / (dx * dx), 1000, &big), 28);
        assert_eq!(list_cap(3, 1.3 * dx, 1.0 / (dx * dx * dx), 1000, &big), 96);
        // Lists that would not fit one binding, or of more than 4096 entries: none.
        assert_eq!(list_cap(3, 1.3 * dx, 1.0 / (dx * dx * dx), 1000, &a(96 * 4 * 1000 - 1)), 0);
        assert_eq!(list_cap(3, 1.3 * dx, 1.0 / (dx * dx * dx), 1000, &a(96 * 4 * 1000)), 96);
        assert_eq!(list_cap(3, 6.0 * dx, 1.0 / (dx * dx * dx), 10, &big), 0);
    }
}
