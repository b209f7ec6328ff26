//! Python bindings (the only module that knows pyo3). Arrays cross in bulk; the Python facade
//! (`physcore.Scene`) validates inputs first, and everything is validated again here so the
//! private module is safe to call directly. The GIL is released around stepping.
use crate::integrators;
use crate::world::World;
use glam::{DVec2, DVec3};
use numpy::{IntoPyArray, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

macro_rules! with_sim {
    ($self:expr, $s:ident => $body:expr) => {
        match $self {
            Inner::D2($s) => $body,
            Inner::D3($s) => $body,
        }
    };
}

mod batch;
mod convert;
mod errors;
mod formulas;
mod simulation;
mod watch;

use convert::*;
use errors::*;
use simulation::PySimulation;

/// A simulation of either dimension (the core is generic over the vector type).
enum Inner {
    D2(World<DVec2>),
    D3(World<DVec3>),
}

/// All pairs i < j of `points` ((N, 2) or (N, 3) float64, C-contiguous) closer than `radius`:
/// two (M,) int64 arrays, sorted by i then j. OutOfMemoryError (a MemoryError) if the pairs do
/// not fit in memory: they are counted before any is stored.
#[pyfunction]
fn neighbors<'py>(py: Python<'py>, points: PyReadonlyArray2<'py, f64>, radius: f64) -> PyResult<Pairs<'py>> {
    let dim = if points.shape()[1] == 3 { 3 } else { 2 };
    let flat = flat2(&points, dim, "points")?;
    let pool = crate::par::default_pool().ok();
    let r = if dim == 3 {
        let x = try_from_flat::<DVec3>(flat, "neighbors", "points").map_err(|e| to_py(py, e))?;
        py.detach(|| crate::par::install(pool.as_ref(), || crate::neighbors::neighbor_pairs(&x, radius)))
    } else {
        let x = try_from_flat::<DVec2>(flat, "neighbors", "points").map_err(|e| to_py(py, e))?;
        py.detach(|| crate::par::install(pool.as_ref(), || crate::neighbors::neighbor_pairs(&x, radius)))
    };
    let (i, j) = r.map_err(|e| to_py(py, e))?;
    Ok((i.into_pyarray(py), j.into_pyarray(py)))
}

/// A shaded triangle mesh drawn over `background` (height, width, 3) uint8, in place (see
/// `crate::raster`): `verts` (V, 3) float32 pixel column, row, depth (larger = nearer); `faces`
/// (T, 3) uint32; `front`, `back` (V, 4) float32 colour multiplier and highlight per vertex;
/// `ss` supersamples per pixel and axis; `uv` (V, 2) and `texture` (H', W', 3) float32, both
/// or neither. InvalidInputError for inconsistent shapes or face indices out of range.
#[pyfunction]
#[pyo3(signature = (verts, faces, front, back, background, ss, uv=None, texture=None))]
#[allow(clippy::too_many_arguments)]
fn rasterise_mesh<'py>(
    py: Python<'py>,
    verts: PyReadonlyArray2<'py, f32>,
    faces: PyReadonlyArray2<'py, u32>,
    front: PyReadonlyArray2<'py, f32>,
    back: PyReadonlyArray2<'py, f32>,
    mut background: numpy::PyReadwriteArray3<'py, u8>,
    ss: usize,
    uv: Option<PyReadonlyArray2<'py, f32>>,
    texture: Option<numpy::PyReadonlyArray3<'py, f32>>,
) -> PyResult<()> {
    let contiguous = |name: &str| err(crate::error::invalid(name, "array must be C-contiguous"));
    let v = verts.as_slice().map_err(|_| contiguous("verts"))?;
    let f = faces.as_slice().map_err(|_| contiguous("faces"))?;
    let fr = front.as_slice().map_err(|_| contiguous("front"))?;
    let bk = back.as_slice().map_err(|_| contiguous("back"))?;
    let uv_s = match &uv {
        Some(a) => Some(a.as_slice().map_err(|_| contiguous("uv"))?),
        None => None,
    };
    let tex = match &texture {
        Some(t) => {
            let shape = t.shape();
            if shape[2] != 3 {
                return Err(err(crate::error::invalid("texture", "texture must be (H, W, 3)")));
            }
            Some(crate::raster::Texture {
                rgb: t.as_slice().map_err(|_| contiguous("texture"))?,
                width: shape[1],
                height: shape[0],
            })
        }
        None => None,
    };
    if verts.shape()[1] != 3 || faces.shape()[1] != 3 || front.shape()[1] != 4 || back.shape()[1] != 4 {
        return Err(err(crate::error::invalid("verts", "verts, faces: (N, 3); front, back: (N, 4)")));
    }
    let shape = background.shape().to_vec();
    if shape[2] != 3 || !(1..=4).contains(&ss) {
        return Err(err(crate::error::invalid("background", "background must be (H, W, 3) and ss in 1..=4")));
    }
    let (height, width) = (shape[0], shape[1]);
    let bg = background.as_slice_mut().map_err(|_| contiguous("background"))?;
    let mesh = crate::raster::Mesh { verts: v, faces: f, front: fr, back: bk, uv: uv_s, texture: tex };
    let pool = crate::par::default_pool().ok();
    py.detach(|| {
        let bytes = crate::alloc::Need::bytes_of::<f32>(width * height) * 4;
        let need = crate::alloc::Need::new("rasterise", bytes, format!("a {width} × {height} mesh image"));
        need.check()?;
        let mut rgb = need.filled(3 * width * height, 0f32)?;
        let mut cover = need.filled(width * height, 0f32)?;
        crate::par::install(pool.as_ref(), || {
            crate::raster::rasterise(&mesh, width, height, ss, &mut rgb, &mut cover)
        })?;
        crate::raster::composite(bg, &rgb, &cover);
        Ok(())
    })
    .map_err(|e| to_py(py, e))
}

/// Antialiased discs drawn over `image` (H, W, 3) uint8 in place, in the order given (see
/// `crate::raster::draw_discs`): centres `col`, `row` (N,) float32 in pixels, `radius` (N,)
/// float32 in pixels, `colours` (N, 3) uint8. InvalidInputError for inconsistent shapes.
#[pyfunction]
fn draw_discs<'py>(
    py: Python<'py>,
    mut image: numpy::PyReadwriteArray3<'py, u8>,
    col: numpy::PyReadonlyArray1<'py, f32>,
    row: numpy::PyReadonlyArray1<'py, f32>,
    radius: numpy::PyReadonlyArray1<'py, f32>,
    colours: PyReadonlyArray2<'py, u8>,
) -> PyResult<()> {
    let (img, height, width) = rgb_image(&mut image)?;
    let (c, r, rad) = (slice1(&col, "col")?, slice1(&row, "row")?, slice1(&radius, "radius")?);
    let cs = colours.as_slice().map_err(|_| not_contiguous("colours"))?;
    py.detach(|| crate::raster::draw_discs(img, width, height, c, r, rad, cs)).map_err(|e| to_py(py, e))
}

/// InvalidInputError naming an array that is not C-contiguous.
fn not_contiguous(name: &str) -> PyErr {
    err(crate::error::invalid(name, "array must be C-contiguous"))
}

/// The bytes of an (H, W, 3) uint8 RGB `image` drawn on in place, with H and W; InvalidInputError
/// for another shape or a non-contiguous array.
fn rgb_image<'a>(image: &'a mut numpy::PyReadwriteArray3<'_, u8>) -> PyResult<(&'a mut [u8], usize, usize)> {
    let shape = image.shape().to_vec();
    if shape[2] != 3 {
        return Err(err(crate::error::invalid("image", "image must be (H, W, 3)")));
    }
    Ok((image.as_slice_mut().map_err(|_| not_contiguous("image"))?, shape[0], shape[1]))
}

/// Filled, lit convex polygons on `image` (H, W, 3) uint8 in place, in order
/// (`crate::raster::fill_polygons`): `verts` (V, 2) float64 pixel (column, row) of every
/// polygon's vertices one after another, `starts` (P + 1,) uint64 where each begins (0 first, V
/// last), `colours` (P, 3) uint8. InvalidInputError for inconsistent shapes.
#[pyfunction]
fn fill_polygons<'py>(
    py: Python<'py>,
    mut image: numpy::PyReadwriteArray3<'py, u8>,
    verts: PyReadonlyArray2<'py, f64>,
    starts: numpy::PyReadonlyArray1<'py, u64>,
    colours: PyReadonlyArray2<'py, u8>,
) -> PyResult<()> {
    if verts.shape()[1] != 2 {
        return Err(err(crate::error::invalid("verts", "verts must be (V, 2)")));
    }
    let (img, height, width) = rgb_image(&mut image)?;
    let v = verts.as_slice().map_err(|_| not_contiguous("verts"))?;
    let st = starts.as_slice().map_err(|_| not_contiguous("starts"))?;
    let st: Vec<usize> = st.iter().map(|&x| usize::try_from(x).unwrap_or(usize::MAX)).collect();
    let cs = colours.as_slice().map_err(|_| not_contiguous("colours"))?;
    py.detach(|| crate::raster::fill_polygons(img, width, height, v, &st, cs)).map_err(|e| to_py(py, e))
}

/// Points `col`, `row` (N,) float64 in pixels splatted bilinearly on an (H, W) float32 grid
/// (`crate::raster::splat`): counts, or `weights` (N,) float32. InvalidInputError for
/// inconsistent shapes.
#[pyfunction]
#[pyo3(signature = (col, row, height, width, weights=None))]
fn splat<'py>(
    py: Python<'py>,
    col: numpy::PyReadonlyArray1<'py, f64>,
    row: numpy::PyReadonlyArray1<'py, f64>,
    height: usize,
    width: usize,
    weights: Option<numpy::PyReadonlyArray1<'py, f32>>,
) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
    let (c, r) = (slice1(&col, "col")?, slice1(&row, "row")?);
    let w = match &weights {
        Some(w) => Some(slice1(w, "weights")?),
        None => None,
    };
    let out = py.detach(|| crate::raster::splat(c, r, w, width, height)).map_err(|e| to_py(py, e))?;
    Ok(numpy::ndarray::Array2::from_shape_vec((height, width), out).expect("shape matches").into_pyarray(py))
}

/// `passes` box means of 2r + 1 pixels down the columns then along the rows of `a` (H, W)
/// float32, zeros beyond the edges (`crate::raster::blur`: the renderer's numpy `_blur` bit for
/// bit). Returns (H, W) float32. InvalidInputError for a non-contiguous array or r above
/// `raster::MAX_BLUR_RADIUS`.
#[pyfunction]
#[pyo3(signature = (a, r, passes=3))]
fn blur<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f32>,
    r: usize,
    passes: usize,
) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
    let (height, width) = (a.shape()[0], a.shape()[1]);
    let src = convert::c_order(&a, "a")?;
    let pool = crate::par::default_pool().ok();
    let out = py
        .detach(|| crate::par::install(pool.as_ref(), || crate::raster::blur(src, width, height, r, passes)))
        .map_err(|e| to_py(py, e))?;
    Ok(numpy::ndarray::Array2::from_shape_vec((height, width), out).expect("shape matches").into_pyarray(py))
}

/// The nearest sphere surfaces over an (H, W) image (`crate::raster::sphere_depths`): points
/// `col`, `row` (N,) float64 in pixels with `depth` (N,) float64 (pixels, larger = nearer),
/// spheres of `radius` pixels. Returns (H, W) float32 depths (−inf where empty) and (H, W)
/// int32 point indices (−1 there). InvalidInputError for inconsistent shapes or a radius out of
/// range.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn sphere_depths<'py>(
    py: Python<'py>,
    col: numpy::PyReadonlyArray1<'py, f64>,
    row: numpy::PyReadonlyArray1<'py, f64>,
    depth: numpy::PyReadonlyArray1<'py, f64>,
    radius: f64,
    height: usize,
    width: usize,
) -> PyResult<(Bound<'py, numpy::PyArray2<f32>>, Bound<'py, numpy::PyArray2<i32>>)> {
    let (c, r, d) = (slice1(&col, "col")?, slice1(&row, "row")?, slice1(&depth, "depth")?);
    let pool = crate::par::default_pool().ok();
    let (z, ids) = py
        .detach(|| crate::par::install(pool.as_ref(), || crate::raster::sphere_depths(c, r, d, radius, width, height)))
        .map_err(|e| to_py(py, e))?;
    let z = numpy::ndarray::Array2::from_shape_vec((height, width), z).expect("shape matches");
    let ids = numpy::ndarray::Array2::from_shape_vec((height, width), ids).expect("shape matches");
    Ok((z.into_pyarray(py), ids.into_pyarray(py)))
}

/// Unit vertex normals (V, 3) float64 of the mesh `faces` (T, 3) uint32 over `x` (V, 3) float64
/// (area-weighted face normals; see `crate::raster::vertex_normals`). InvalidInputError for an
/// index out of range or a non-contiguous array.
#[pyfunction]
fn mesh_normals<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    faces: PyReadonlyArray2<'py, u32>,
) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let xs = flat2(&x, 3, "x")?;
    if faces.shape()[1] != 3 {
        return Err(err(crate::error::invalid("faces", "faces must be (T, 3)")));
    }
    let f = faces.as_slice().map_err(|_| err(crate::error::invalid("faces", "array must be C-contiguous")))?;
    let mut out = vec![0f64; xs.len()];
    py.detach(|| crate::raster::vertex_normals(xs, f, &mut out)).map_err(|e| to_py(py, e))?;
    Ok(numpy::ndarray::Array2::from_shape_vec((xs.len() / 3, 3), out).expect("shape matches").into_pyarray(py))
}

/// Name, order, symplectic flag and force evaluations per step of every integrator.
#[pyfunction]
fn integrator_table<'py>(py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
    integrators::NAMES.iter().map(|n| info_dict(py, integrators::by_name::<DVec2>(n).expect("listed").info())).collect()
}

/// Number of threads of the pool of scenes built with threads=None (1 if it cannot start).
#[pyfunction]
fn default_threads() -> usize {
    crate::par::default_pool().map_or(1, |p| p.current_num_threads())
}

/// The SIMD level the kernels run at ("scalar", "avx2", "avx512" or "neon"); InvalidInputError
/// if PHYSCORE_SIMD names a level that is unknown or that this CPU lacks.
#[pyfunction]
fn simd_level(py: Python<'_>) -> PyResult<&'static str> {
    crate::simd::check().map(|l| l.name()).map_err(|e| to_py(py, e))
}

/// The SIMD levels this CPU supports, slowest first.
#[pyfunction]
fn simd_levels() -> Vec<&'static str> {
    crate::simd::Level::available().into_iter().map(|l| l.name()).collect()
}

/// Forces the SIMD level for this process (None: back to PHYSCORE_SIMD, else the best).
#[pyfunction]
#[pyo3(signature = (level=None))]
fn set_simd_level(py: Python<'_>, level: Option<&str>) -> PyResult<()> {
    let l = match level {
        None => None,
        Some(name) => Some(crate::simd::Level::by_name(name).ok_or_else(|| {
            to_py(
                py,
                crate::error::invalid(
                    "level",
                    format!("unknown SIMD level {name:?}; valid: scalar, avx2, avx512, neon"),
                ),
            )
        })?),
    };
    crate::simd::set_level(l).map_err(|e| to_py(py, e))
}

/// A short description of this CPU.
#[pyfunction]
fn cpu_name() -> String {
    crate::simd::cpu_name()
}

/// The optional per-particle attributes a scene may carry: name -> SI unit.
#[pyfunction]
fn particle_attributes() -> Vec<(&'static str, &'static str)> {
    crate::state::ATTRIBUTES.to_vec()
}

/// The GPU adapters wgpu sees (Vulkan, Metal, DX12), CPU ones included: one dict each with
/// name, backend, kind ("discrete", "integrated", "virtual", "cpu", "other"), driver, f64 and
/// the largest storage binding and buffer (bytes). Empty without a GPU backend or a driver.
#[pyfunction]
fn gpu_adapters(py: Python<'_>) -> PyResult<Vec<Bound<'_, pyo3::types::PyDict>>> {
    #[cfg(feature = "gpu")]
    let found = py.detach(physcore_gpu::adapters);
    #[cfg(not(feature = "gpu"))]
    let found: Vec<()> = Vec::new();
    #[cfg(feature = "gpu")]
    return found
        .into_iter()
        .map(|a| {
            let d = pyo3::types::PyDict::new(py);
            d.set_item("name", a.name)?;
            d.set_item("backend", a.backend)?;
            d.set_item("kind", a.kind)?;
            d.set_item("driver", a.driver)?;
            d.set_item("f64", a.f64)?;
            d.set_item("max_storage_binding", a.max_storage_binding)?;
            d.set_item("max_buffer", a.max_buffer)?;
            Ok(d)
        })
        .collect();
    #[cfg(not(feature = "gpu"))]
    {
        let _ = (py, found);
        Ok(Vec::new())
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimulation>()?;
    m.add_function(wrap_pyfunction!(integrator_table, m)?)?;
    m.add_function(wrap_pyfunction!(default_threads, m)?)?;
    m.add_function(wrap_pyfunction!(simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(simd_levels, m)?)?;
    m.add_function(wrap_pyfunction!(set_simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(cpu_name, m)?)?;
    m.add_function(wrap_pyfunction!(particle_attributes, m)?)?;
    m.add_function(wrap_pyfunction!(gpu_adapters, m)?)?;
    m.add_function(wrap_pyfunction!(neighbors, m)?)?;
    m.add_function(wrap_pyfunction!(rasterise_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_normals, m)?)?;
    m.add_function(wrap_pyfunction!(draw_discs, m)?)?;
    m.add_function(wrap_pyfunction!(fill_polygons, m)?)?;
    m.add_function(wrap_pyfunction!(splat, m)?)?;
    m.add_function(wrap_pyfunction!(sphere_depths, m)?)?;
    m.add_function(wrap_pyfunction!(blur, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_kernel, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_lattice_sum, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_particle_mass, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_wall_psi, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_sound_speed, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::sph_max_dt, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::grid_limits, m)?)?;
    m.add_function(wrap_pyfunction!(formulas::check_integrator, m)?)?;
    m.add_function(wrap_pyfunction!(batch::step_batch, m)?)?;
    #[cfg(feature = "gpu")]
    m.add_class::<batch::PyDeviceBatch>()?;
    m.add_function(wrap_pyfunction!(batch::reference_energies, m)?)?;
    m.add_function(wrap_pyfunction!(batch::batch_rows, m)?)?;
    m.add("build_profile", if cfg!(debug_assertions) { "debug" } else { "release" })?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    let _ = MAIN_THREAD.set(std::thread::current().id());
    crate::stop::on_signals(python_signalled);
    Ok(())
}

/// Python's signal handlers, run from the thread that imported the module (Python's main
/// thread, where they run at all; elsewhere `check_signals` does nothing, and taking the GIL on
/// a thread that a GIL holder waits on would never return): whether one raised (Ctrl-C). The
/// raised exception itself is dropped; the caller reports `Error::Interrupted`.
fn python_signalled() -> bool {
    if MAIN_THREAD.get() != Some(&std::thread::current().id()) {
        return false;
    }
    Python::attach(|py| py.check_signals().is_err())
}

/// The thread that imported the module.
static MAIN_THREAD: std::sync::OnceLock<std::thread::ThreadId> = std::sync::OnceLock::new();
