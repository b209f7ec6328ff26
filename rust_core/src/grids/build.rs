//! Grid systems built from named parameters (what the Python bindings pass; plain Rust here).
//!
//! Every kind takes `shape` (cell counts, x first), `dx` (m) and `edges` (one rule per face,
//! "x-,x+,y-,y+[,z-,z+]", each `fixed`, `free` or `periodic`). Arrays over cells are in the
//! grid's layout (x fastest). Lists of sources come as flat arrays plus a count per source.
use super::fluid::{Advection, FluidConfig, Projection, Source, StableFluid};
use super::gray_scott::{GrayScottConfig, GrayScottSystem};
use super::wave::{Drop, Oscillator, WaveConfig, WaveSystem};
use super::{Edge, Grid};
use crate::alloc::{count, Need};
use crate::error::{invalid, Result};
use crate::systems::System;
use crate::terms::registry::Params;
use crate::vector::Real;

/// The kinds `build` knows.
pub const KINDS: [&str; 3] = ["wave", "gray_scott", "stable_fluid"];

/// The configuration of a Gray–Scott system from its parameters (also what a device's copy is
/// built from: `systems::device`).
pub fn gray_scott_config(name: &str, dim: usize, mut p: Params) -> Result<GrayScottConfig> {
    let grid = grid_of(&mut p, dim)?;
    let c = gray_scott_of(name, grid, &mut p)?;
    c.validate()?;
    Ok(c)
}

fn gray_scott_of(name: &str, grid: Grid, p: &mut Params) -> Result<GrayScottConfig> {
    let mut c =
        GrayScottConfig::new(name, grid, p.number("du")?, p.number("dv")?, p.number("feed")?, p.number("kill")?);
    c.cfl = p.number("cfl")?;
    Ok(c)
}

/// The configuration of a wave system from its parameters (also what a device's copy is built
/// from: `systems::device`).
pub fn wave_config(name: &str, dim: usize, mut p: Params) -> Result<WaveConfig> {
    let grid = grid_of(&mut p, dim)?;
    let c = wave_of(name, grid, dim, &mut p)?;
    c.validate()?;
    Ok(c)
}

fn wave_of(name: &str, grid: Grid, dim: usize, p: &mut Params) -> Result<WaveConfig> {
    let mut c = WaveConfig::new(name, grid, p.number("c")?);
    c.gamma = p.number("damping")?;
    c.cfl = p.number("cfl")?;
    c.layer = p.count("layer", 1 << 20)?;
    c.layer_strength = p.number("layer_strength")?;
    let absorbing = p.take_floats("absorbing")?;
    if absorbing.len() != 2 * dim {
        return Err(invalid("absorbing", format!("needs one flag per face ({}), got {}", 2 * dim, absorbing.len())));
    }
    for (f, a) in absorbing.iter().enumerate() {
        c.absorbing[f] = *a != 0.0;
    }
    c.mask = p.take_floats("mask").ok().map(|m| flags("add_wave", &m)).transpose()?;
    let t = p.take_floats("drop_t")?;
    let amp = p.take_floats("drop_amplitude")?;
    let shapes = profiles(p, "drop", t.len())?;
    c.drops =
        t.iter().zip(&amp).zip(shapes).map(|((&t, &amplitude), profile)| Drop { t, amplitude, profile }).collect();
    let amp = p.take_floats("osc_amplitude")?;
    let freq = p.take_floats("osc_frequency")?;
    let phase = p.take_floats("osc_phase")?;
    if freq.len() != amp.len() || phase.len() != amp.len() {
        return Err(invalid("oscillators", "amplitude, frequency and phase must have one entry per oscillator"));
    }
    let shapes = profiles(p, "osc", amp.len())?;
    c.oscillators = (0..amp.len())
        .zip(shapes)
        .map(|(k, profile)| Oscillator { amplitude: amp[k], frequency: freq[k], phase: phase[k], profile })
        .collect();
    Ok(c)
}

/// The stable fluid's configuration from the parameters `build` takes (validated).
pub fn fluid_config(name: &str, dim: usize, mut p: Params) -> Result<FluidConfig> {
    let grid = grid_of(&mut p, dim)?;
    let c = fluid_of(name, grid, dim, &mut p)?;
    c.validate()?;
    Ok(c)
}

fn fluid_of(name: &str, grid: Grid, dim: usize, p: &mut Params) -> Result<FluidConfig> {
    if dim != 2 {
        return Err(invalid("shape", "the grid fluid is 2D only"));
    }
    let advection = p.text("advection")?;
    let mut c = FluidConfig {
        name: name.to_string(),
        shape: [grid.n[0], grid.n[1]],
        dx: grid.dx,
        viscosity: p.number("nu")?,
        buoyancy_alpha: p.number("buoyancy_alpha")?,
        buoyancy_beta: p.number("buoyancy_beta")?,
        ambient_temperature: p.number("ambient_temperature")?,
        vorticity: p.number("vorticity")?,
        advection: Advection::by_name(advection)?,
        // Absent (a caller from before issue 64): Chorin's, as such a caller's runs were.
        projection: if p.has("projection") { Projection::by_name(p.text("projection")?)? } else { Projection::Chorin },
        tolerance: p.number("tolerance")?,
        max_iterations: p.count("max_iterations", 1 << 30)?,
        no_slip: p.flag("no_slip")?,
        lid: if p.flag("has_lid")? { Some(p.number("lid")?) } else { None },
        inflow: if p.flag("has_inflow")? { Some(p.number("inflow")?) } else { None },
        obstacles: p.take_floats("obstacles").ok().map(|m| flags("fluid", &m)).transpose()?.unwrap_or_default(),
        sources: Vec::new(),
        n_tracers: p.count("n_tracers", 1 << 26)?,
        cfl: p.number("cfl")?,
    };
    let density = p.take_floats("src_density")?;
    let temperature = p.take_floats("src_temperature")?;
    let velocity = p.take_floats("src_velocity")?;
    if temperature.len() != density.len() || velocity.len() != 2 * density.len() {
        return Err(invalid("sources", "density, temperature and velocity must have one entry per source"));
    }
    let shapes = profiles(p, "src", density.len())?;
    c.sources = shapes
        .into_iter()
        .enumerate()
        .map(|(k, cells)| Source {
            cells,
            density: density[k],
            temperature: temperature[k],
            velocity: [velocity[2 * k], velocity[2 * k + 1]],
        })
        .collect();
    Ok(c)
}

/// Builds a grid system of `kind` named `name` for a world of dimension `dim`.
pub fn build(kind: &str, name: &str, dim: usize, mut p: Params) -> Result<Box<dyn System>> {
    let grid = grid_of(&mut p, dim)?;
    match kind {
        "wave" => Ok(Box::new(WaveSystem::new(wave_of(name, grid, dim, &mut p)?)?)),
        "gray_scott" => Ok(Box::new(GrayScottSystem::new(gray_scott_of(name, grid, &mut p)?)?)),
        "stable_fluid" => Ok(Box::new(StableFluid::new(fluid_of(name, grid, dim, &mut p)?)?)),
        _ => Err(invalid("kind", format!("unknown grid kind {kind:?}; valid: {}", KINDS.join(", ")))),
    }
}

/// A 1/0 array over the cells as flags, allocated fallibly (`what`: the call that needs it).
fn flags(what: &'static str, m: &[Real]) -> Result<Vec<bool>> {
    let need = Need::new(what, Need::bytes_of::<bool>(m.len()), format!("a mask of {} cells", count(m.len() as u128)));
    need.collect(m.iter().map(|&x| x != 0.0))
}

/// The step limits of a grid of `kind` from the same parameters `build` takes (only the grid and
/// the numbers a limit needs are read; nothing is allocated): `("cfl_limit", s)` for "wave",
/// `("diffusion_limit", s)` for "gray_scott", none for "stable_fluid" (its limit follows the flow).
pub fn limits(kind: &str, dim: usize, mut p: Params) -> Result<Vec<(&'static str, Real)>> {
    let grid = grid_of(&mut p, dim)?;
    Ok(match kind {
        "wave" => {
            let c = WaveConfig::new("limits", grid, p.number("c")?);
            vec![("cfl_limit", c.cfl_limit())]
        }
        "gray_scott" => {
            let c = GrayScottConfig::new("limits", grid, p.number("du")?, p.number("dv")?, 0.0, 0.0);
            vec![("diffusion_limit", c.diffusion_limit())]
        }
        "stable_fluid" => Vec::new(),
        _ => return Err(invalid("kind", format!("unknown grid kind {kind:?}; valid: {}", KINDS.join(", ")))),
    })
}

fn grid_of(p: &mut Params, dim: usize) -> Result<Grid> {
    let shape = p.take_floats("shape")?;
    if shape.len() != dim {
        return Err(invalid("shape", format!("a {dim}D scene needs {dim} cell counts, got {}", shape.len())));
    }
    if let Some(n) = shape.iter().find(|n| !(n.fract() == 0.0 && **n >= 0.0 && **n < 1e12)) {
        return Err(invalid("shape", format!("cell counts must be whole numbers, got {n}")));
    }
    let shape: Vec<usize> = shape.iter().map(|&n| n as usize).collect();
    let edges = p
        .text("edges")?
        .split(',')
        .map(|e| {
            Edge::by_name(e.trim())
                .ok_or_else(|| invalid("edges", format!("unknown rule {e:?}; valid: fixed, free, periodic")))
        })
        .collect::<Result<Vec<_>>>()?;
    Grid::new(&shape, p.number("spacing")?, &edges)
}

/// `n` profiles from `{prefix}_counts` (cells per source), `{prefix}_cells`, `{prefix}_weights`.
fn profiles(p: &mut Params, prefix: &str, n: usize) -> Result<Vec<Vec<(usize, Real)>>> {
    let arg = match prefix {
        "drop" => "drops",
        "osc" => "oscillators",
        _ => "sources",
    };
    let counts = p.take_floats(&format!("{prefix}_counts"))?;
    let cells = p.take_indices(&format!("{prefix}_cells"))?;
    let weights = p.take_floats(&format!("{prefix}_weights"))?;
    if counts.len() != n || cells.len() != weights.len() || counts.iter().sum::<Real>() != cells.len() as Real {
        return Err(invalid(arg, "profile arrays do not match (counts, cells, weights)"));
    }
    let mut out = Vec::with_capacity(n);
    let mut at = 0;
    for &k in &counts {
        let k = k as usize;
        out.push(cells[at..at + k].iter().zip(&weights[at..at + k]).map(|(&c, &w)| (c as usize, w)).collect());
        at += k;
    }
    Ok(out)
}
