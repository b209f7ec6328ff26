//! Triangle rasterisation for the renderer's shaded meshes (`physcore.render.Mesh`: cloth and
//! soft bodies drawn as lit surfaces). Not physics, but per pixel and per frame: numpy took
//! 180–300 ms a frame for a 40² or 256² cloth (fragment arrays of a million entries), and no
//! library draws 10⁵ Gouraud triangles from arrays without a Python object per vertex
//! (skia-python's `Vertices` needs `Point` objects: 0.44 s for 4·10⁵ of them).
//!
//! Method: edge functions over each triangle's bounding box (J. Pineda, "A parallel algorithm
//! for polygon rasterization", SIGGRAPH 1988), barycentric interpolation of per-vertex colours
//! (Gouraud shading; the lighting itself is computed per vertex by the caller), a depth buffer,
//! and `ss × ss` supersamples per pixel averaged into colour and coverage (antialiased edges).
//! The image is cut into bands of rows, each drawn by one task from the triangles binned to it
//! in their given order: bit-identical for any thread count.
use crate::alloc::Need;
use crate::error::{invalid, Result};
use rayon::prelude::*;

/// Output rows per band (one task each).
const BAND: usize = 8;

/// A texture: `rgb` is `height × width` texels of 3 floats, row 0 at the top (v = 1).
pub struct Texture<'a> {
    pub rgb: &'a [f32],
    pub width: usize,
    pub height: usize,
}

/// Triangles to draw. Per vertex `i`: `verts[3i..3i+3]` = pixel column, pixel row (pixel k spans
/// [k, k+1)) and depth (larger = nearer); `front`/`back[4i..4i+4]` = a colour multiplier
/// (r, g, b) and an additive highlight, used on the side the triangle shows (front: its
/// corners turn counter-clockwise on screen, i.e. its normal (p1 − p0) × (p2 − p0) faces the
/// viewer of a right-handed view). A sample's colour is `base · (r, g, b) + highlight`, base = the texture
/// at the interpolated `uv[2i..2i+2]` (u right, v up the texture) or 1.
pub struct Mesh<'a> {
    pub verts: &'a [f32],
    pub faces: &'a [u32],
    pub front: &'a [f32],
    pub back: &'a [f32],
    pub uv: Option<&'a [f32]>,
    pub texture: Option<Texture<'a>>,
}

/// Antialiased discs over `image` (`height × width × 3` bytes), in the order given (later ones
/// over earlier ones): disc i centred at (`col[i]`, `row[i]`) in pixels (pixel k spans
/// [k, k+1)), of radius `radius[i]` pixels, in colour `colours[3i..3i+3]`. A pixel's coverage is
/// clamp(r + ½ − d, 0, 1), d the distance from its centre to the disc's (the area of a
/// one-pixel-wide ramp across the edge; exact for a straight edge through the pixel), and its
/// colour is blended by it. Discs with a non-finite centre or radius, or none, are skipped.
/// Serial: the painter's order is the drawing order (about 5 ms for 10⁵ discs of radius 2).
pub fn draw_discs(
    image: &mut [u8],
    width: usize,
    height: usize,
    col: &[f32],
    row: &[f32],
    radius: &[f32],
    colours: &[u8],
) -> Result<()> {
    let n = col.len();
    if row.len() != n || radius.len() != n || colours.len() != 3 * n {
        return Err(invalid("col", "col, row, radius and colours must describe the same discs"));
    }
    if image.len() != 3 * width * height {
        return Err(invalid("image", "image must be height × width × 3"));
    }
    for i in 0..n {
        let (cx, cy, r) = (col[i], row[i], radius[i]);
        if !(cx.is_finite() && cy.is_finite() && r.is_finite() && r > 0.0) {
            continue;
        }
        let reach = r + 0.5;
        let c0 = floor_i(cx - reach).max(0);
        let c1 = ceil_i(cx + reach).min(width as i64 - 1);
        let r0 = floor_i(cy - reach).max(0);
        let r1 = ceil_i(cy + reach).min(height as i64 - 1);
        let rgb = [colours[3 * i] as f32, colours[3 * i + 1] as f32, colours[3 * i + 2] as f32];
        for y in r0..=r1 {
            let dy = y as f32 + 0.5 - cy;
            for x in c0..=c1 {
                let dx = x as f32 + 0.5 - cx;
                let a = (reach - (dx * dx + dy * dy).sqrt()).clamp(0.0, 1.0);
                if a > 0.0 {
                    let p = 3 * (y as usize * width + x as usize);
                    for ch in 0..3 {
                        let v = image[p + ch] as f32 * (1.0 - a) + rgb[ch] * a;
                        image[p + ch] = (v + 0.5) as u8;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Filled convex polygons over `image` (`height × width × 3` bytes), in order (the renderer's 2D
/// rigid bodies, `physcore.render._bodies`): polygon p's vertices are `verts[2s..2e]` (pixel
/// column, row pairs; pixel k spans [k, k+1)) for s, e = `starts[p]`, `starts[p + 1]`, its colour
/// `colours[3p..3p+3]`. Each is antialiased by the signed distance to its edges (coverage
/// clamp(½ − d, 0, 1), d the largest of the edges' outward half-plane distances), lit from above
/// (the colour × (1.18 − 0.33 t), t from 0 at its top vertex to 1 at its foot) and rimmed darker
/// (× 0.55 within 1.6 px of its edge). This is the numpy `_fill` the renderer kept as its
/// reference, operation for operation in its precisions (f64, the rim colour in f32, the
/// result truncated to a byte), so the bytes are the same, without numpy's per-polygon
/// overhead (some 0.24 ms each: 51 bodies took 12 ms a frame). Degenerate edges (≤ 1e-9 px)
/// are dropped; a polygon with fewer than 3 edges left, or off the image, draws nothing.
/// Serial: the painter's order is the drawing order.
/// InvalidInput for inconsistent lengths or starts not increasing.
pub fn fill_polygons(
    image: &mut [u8],
    width: usize,
    height: usize,
    verts: &[f64],
    starts: &[usize],
    colours: &[u8],
) -> Result<()> {
    if image.len() != 3 * width * height {
        return Err(invalid("image", "image must be height × width × 3"));
    }
    let n = starts.len().saturating_sub(1);
    if starts.is_empty()
        || starts[0] != 0
        || starts.windows(2).any(|w| w[1] < w[0])
        || starts[n].checked_mul(2) != Some(verts.len())
    {
        return Err(invalid("starts", "starts must rise from 0 to the vertex count"));
    }
    if colours.len() != 3 * n {
        return Err(invalid("colours", "one colour (3 bytes) per polygon"));
    }
    let mut edges: Vec<[f64; 4]> = Vec::new(); // px, py, nx, ny
    for p in 0..n {
        let poly = &verts[2 * starts[p]..2 * starts[p + 1]];
        let v = poly.len() / 2;
        if v == 0 || poly.iter().any(|x| !x.is_finite()) {
            continue;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut sum = [0.0f64; 2];
        for i in 0..v {
            for a in 0..2 {
                lo[a] = lo[a].min(poly[2 * i + a]);
                hi[a] = hi[a].max(poly[2 * i + a]);
                sum[a] += poly[2 * i + a];
            }
        }
        let c0 = ((lo[0] - 1.0).floor() as i64).max(0);
        let r0 = ((lo[1] - 1.0).floor() as i64).max(0);
        let c1 = ((hi[0] + 1.0).ceil() as i64).min(width as i64);
        let r1 = ((hi[1] + 1.0).ceil() as i64).min(height as i64);
        if c0 >= c1 || r0 >= r1 {
            continue;
        }
        let centre = [sum[0] / v as f64, sum[1] / v as f64];
        edges.clear();
        let (mut top, mut foot) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..v {
            let j = (i + 1) % v;
            let (px, py) = (poly[2 * i], poly[2 * i + 1]);
            let (ex, ey) = (poly[2 * j] - px, poly[2 * j + 1] - py);
            let length = ex.hypot(ey);
            if length.partial_cmp(&1e-9) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let (mut nx, mut ny) = (ey / length, -ex / length);
            if (centre[0] - px) * nx + (centre[1] - py) * ny > 0.0 {
                (nx, ny) = (-nx, -ny); // point outward, whatever the winding
            }
            edges.push([px, py, nx, ny]);
            top = top.min(py);
            foot = foot.max(py);
        }
        if edges.len() < 3 {
            continue;
        }
        let span = if foot - top > 1.0 { foot - top } else { 1.0 };
        let base: [f32; 3] = [colours[3 * p] as f32, colours[3 * p + 1] as f32, colours[3 * p + 2] as f32];
        let rim_colour = base.map(|b| (b * 0.55f32) as f64);
        for r in r0..r1 {
            let row = r as f64 + 0.5;
            let t = ((row - top) / span).clamp(0.0, 1.0);
            let light = 1.18 - 0.33 * t;
            for c in c0..c1 {
                let col = c as f64 + 0.5;
                let mut d = f64::NEG_INFINITY;
                for e in &edges {
                    d = d.max((col - e[0]) * e[2] + (row - e[1]) * e[3]);
                }
                let cover = (0.5 - d).clamp(0.0, 1.0);
                if cover == 0.0 {
                    continue; // region · 1 + shade · 0: the pixel as it was
                }
                let inside_rim = (-d).max(0.0) < 1.6;
                let at = 3 * (r as usize * width + c as usize);
                for ch in 0..3 {
                    let shade = if inside_rim { rim_colour[ch] } else { base[ch] as f64 * light };
                    let region = image[at + ch] as f32 as f64;
                    image[at + ch] = (region * (1.0 - cover) + shade * cover).clamp(0.0, 255.0) as u8;
                }
            }
        }
    }
    Ok(())
}

/// ⌊v⌋ by truncation, for v within i64's range: f64::floor is a libm call on baseline x86-64
/// (three pixel boxes a point took 70 % of `sphere_depths`' time with it).
fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    if (t as f64) > v {
        t - 1
    } else {
        t
    }
}

/// Each point shared bilinearly among the four pixels around it (the renderer's splat: counts,
/// or `weights`, per pixel; pixel k's centre at k + ½), on a `height × width` grid returned as
/// f32. Accumulated in f64 on a grid one pixel wider each side (no bounds checks), in the order
/// numpy's `bincount` over the four corners' concatenated arrays adds them (every point's first
/// corner, then every point's second, ...), so the result is the numpy version's bit for bit,
/// in a few milliseconds for 10⁶ points instead of 110 (its 4N-entry temporaries). Points off
/// the grid (or not finite) are left out. Sequential: one order, any thread count.
pub fn splat(col: &[f64], row: &[f64], weights: Option<&[f32]>, width: usize, height: usize) -> Result<Vec<f32>> {
    let n = col.len();
    if row.len() != n || weights.is_some_and(|w| w.len() != n) {
        return Err(invalid("col", "col, row and weights must describe the same points"));
    }
    let wp = width + 2;
    // Every buffer allocated fallibly: a refusal is an error the renderer reports
    // (OutOfMemoryError), where an infallible one aborted the process.
    let bytes = (height as u128 + 2) * wp as u128 * 8 + n as u128 * 24 + (width * height) as u128 * 4;
    let need = Need::new("splat", bytes, format!("a {width} × {height} splat of {n} points"));
    need.check()?;
    let mut grid = need.filled((height + 2) * wp, 0f64)?;
    // Per point, once: its base cell and the fractions, as numpy computes them (fx in f64, the
    // fractions rounded to f32, the products in f32). Computing each point's corner four times,
    // with two libm floors each, took 28 ms of a 10⁶-point splat.
    let floor = |v: f64| floor_i64(v) as f64;
    let mut points: Vec<(usize, f32, f32, f32)> = Vec::new();
    need.reserve(&mut points, n)?;
    points.extend((0..n).filter_map(|i| {
        let (fx, fy) = (col[i] - 0.5, row[i] - 0.5);
        if !(fx > -1.0 && fx < width as f64 && fy > -1.0 && fy < height as f64) {
            return None;
        }
        let (x0, y0) = (floor(fx), floor(fy));
        let (ax, ay) = ((fx - x0) as f32, (fy - y0) as f32);
        let base = ((y0 as i64 + 1) * wp as i64 + (x0 as i64 + 1)) as usize;
        Some((base, ax, ay, weights.map_or(1.0, |w| w[i])))
    }));
    let weighted = weights.is_some();
    for corner in 0..4 {
        for &(base, ax, ay, w) in &points {
            let bx = 1.0 - ax;
            let (at, f) = match corner {
                0 => (base, bx * (1.0 - ay)),
                1 => (base + 1, ax * (1.0 - ay)),
                2 => (base + wp, bx * ay),
                _ => (base + wp + 1, ax * ay),
            };
            let f = if weighted { f * w } else { f };
            grid[at] += f as f64;
        }
    }
    let mut out = Vec::new();
    need.reserve(&mut out, width * height)?;
    for y in 1..=height {
        out.extend(grid[y * wp + 1..y * wp + 1 + width].iter().map(|&v| v as f32));
    }
    Ok(out)
}

/// Widest box `blur` takes (a window of 2r + 1 pixels): far above any blur the renderer draws.
pub const MAX_BLUR_RADIUS: usize = 4096;

/// `passes` times a box mean over 2r + 1 pixels down the columns, then along the rows, of the
/// `height × width` image `a` (zeros beyond the edges): three passes approach a Gaussian of
/// σ ≈ r (the central limit), each O(1) a pixel. This is the renderer's `_blur` (numpy, kept in
/// `physcore.render._raster._box_blur` as the reference) done in f32 with numpy's operations in
/// numpy's order, so the result is its bit for bit: a window of r ≤ 2 sums the shifted rows
/// (padding zeros included) in order; a wider one takes the difference of two entries of a
/// running sum over the zero-padded line (r + 1 zeros before, r after), times the f32 of
/// 1/(2r + 1). Rows in parallel, each by one task: the same bits for any thread count. It
/// replaces 6 numpy passes of about 2 ms each (a 480 × 360 frame) that the fluids' surfaces
/// and the 3D liquid's smoothing run several times a frame.
/// InvalidInput for a length other than height·width or r above MAX_BLUR_RADIUS.
pub fn blur(a: &[f32], width: usize, height: usize, r: usize, passes: usize) -> Result<Vec<f32>> {
    if a.len() != width * height {
        return Err(invalid("a", format!("{} values for a {height} × {width} image", a.len())));
    }
    if r > MAX_BLUR_RADIUS {
        return Err(invalid("r", format!("{r} pixels (at most {MAX_BLUR_RADIUS})")));
    }
    // The image, a scratch copy and the columns' running sums allocated fallibly; the padded
    // line each thread grows is checked first (as `splat`).
    let ring = if r > 2 { 2 * r + 2 } else { 0 };
    let bytes = 2 * a.len() as u128 * 4 + (ring + 1) as u128 * width as u128 * 4;
    let lines = 64 * (width.max(height) as u128 + 2 * r as u128 + 2) * 8;
    let need = Need::new("blur", bytes + lines, format!("a {width} × {height} blur"));
    need.check()?;
    let mut cur = need.copy(a)?;
    if width == 0 || height == 0 {
        return Ok(cur);
    }
    let mut tmp = need.filled(cur.len(), 0f32)?;
    let zeros = need.filled(width, 0f32)?;
    let mut sums = need.filled(ring * width, 0f32)?;
    need.room(lines)?;
    for _ in 0..passes {
        box_columns(&cur, &mut tmp, width, height, r, &zeros, &mut sums);
        let line = |scratch: &mut Vec<f32>, (src, dst): (&[f32], &mut [f32])| box_line(src, dst, r, scratch);
        if crate::par::fork_if(cur.len(), || {
            tmp.par_chunks(width).zip(cur.par_chunks_mut(width)).for_each_init(Vec::new, line)
        })
        .is_none()
        {
            let mut scratch = Vec::new();
            tmp.chunks(width).zip(cur.chunks_mut(width)).for_each(|p| line(&mut scratch, p));
        }
    }
    Ok(cur)
}

/// The f32 factor numpy's `_box_blur` multiplies by.
fn box_factor(r: usize) -> f32 {
    (1.0 / (2 * r + 1) as f64) as f32
}

/// One box pass along a line `src` into `dst` (`_box_blur` on one row), `scratch` for the
/// zero-padded line and its running sum.
fn box_line(src: &[f32], dst: &mut [f32], r: usize, scratch: &mut Vec<f32>) {
    let n = src.len();
    let inv = box_factor(r);
    scratch.clear();
    if r <= 2 {
        // out = p[0..n] + p[1..n+1] + … in that order, p the line with r zeros each side.
        scratch.resize(r, 0.0);
        scratch.extend_from_slice(src);
        scratch.resize(n + 2 * r, 0.0);
        dst.copy_from_slice(&scratch[..n]);
        for k in 1..=2 * r {
            for (o, &v) in dst.iter_mut().zip(&scratch[k..k + n]) {
                *o += v;
            }
        }
        for o in dst.iter_mut() {
            *o *= inv;
        }
        return;
    }
    // numpy's cumsum over r + 1 zeros, the line, r zeros: c_0 = p_0, c_t = c_{t−1} + p_t.
    scratch.resize(r + 1, 0.0);
    scratch.extend_from_slice(src);
    scratch.resize(n + 2 * r + 1, 0.0);
    for t in 1..scratch.len() {
        scratch[t] += scratch[t - 1];
    }
    for ((o, &hi), &lo) in dst.iter_mut().zip(&scratch[2 * r + 1..]).zip(&scratch[..n]) {
        *o = (hi - lo) * inv;
    }
}

/// One box pass down the columns of `src` into `dst` (`_box_blur` along axis 0), a whole row of
/// columns at a time (the same operations per column as `box_line`). `zeros`: a row of zeros;
/// `c`: (2r + 2) rows for the running sums where r > 2.
fn box_columns(src: &[f32], dst: &mut [f32], width: usize, height: usize, r: usize, zeros: &[f32], c: &mut [f32]) {
    let inv = box_factor(r);
    let row = |t: usize, pad: usize| -> &[f32] {
        if t >= pad && t - pad < height {
            &src[(t - pad) * width..(t - pad + 1) * width]
        } else {
            zeros
        }
    };
    if r <= 2 {
        let one = |(i, out): (usize, &mut [f32])| {
            out.copy_from_slice(row(i, r));
            for k in 1..=2 * r {
                for (o, &v) in out.iter_mut().zip(row(i + k, r)) {
                    *o += v;
                }
            }
            for o in out.iter_mut() {
                *o *= inv;
            }
        };
        if crate::par::fork_if(dst.len(), || dst.par_chunks_mut(width).enumerate().for_each(one)).is_none() {
            dst.chunks_mut(width).enumerate().for_each(one);
        }
        return;
    }
    // The running sum over the padded rows, kept for the 2r + 2 rows a difference reads (a
    // ring), so the pass streams through the image once, a row (vector-wide) at a time.
    let ring = 2 * r + 2;
    for t in 0..height + 2 * r + 1 {
        let (prev, cur) = ((t + ring - 1) % ring, t % ring);
        let p = row(t, r + 1);
        if t == 0 {
            c[..width].copy_from_slice(p);
        } else {
            let (before, to) = rows2(c, prev, cur, width);
            for ((o, &q), &v) in to.iter_mut().zip(before).zip(p) {
                *o = q + v;
            }
        }
        if t > 2 * r {
            let i = t - 2 * r - 1;
            let lo = &c[(i % ring) * width..(i % ring + 1) * width];
            let hi = &c[cur * width..(cur + 1) * width];
            for ((o, &h), &l) in dst[i * width..(i + 1) * width].iter_mut().zip(hi).zip(lo) {
                *o = (h - l) * inv;
            }
        }
    }
}

/// Rows `a` (read) and `b` (written, ≠ a) of the row-major `c`.
fn rows2(c: &mut [f32], a: usize, b: usize, width: usize) -> (&[f32], &mut [f32]) {
    if a < b {
        let (x, y) = c.split_at_mut(b * width);
        (&x[a * width..(a + 1) * width], &mut y[..width])
    } else {
        let (x, y) = c.split_at_mut(a * width);
        (&y[..width], &mut x[b * width..(b + 1) * width])
    }
}

/// Largest sphere radius `sphere_depths` takes, pixels: a bound on its work per point
/// ((2r + 1)² pixels), far above a liquid's particle spacing at any image size.
pub const MAX_SPHERE_RADIUS: f64 = 64.0;

/// A depth buffer of spheres: point `i` at pixel (`col[i]`, `row[i]`) with depth `depth[i]`
/// (pixels, larger = nearer) is a sphere of `radius` pixels, and each pixel (centre k + ½)
/// keeps the nearest sphere surface over it, `depth + √(r² − d²)`, and that point's index.
/// Returns `height × width` depths (−∞ where no sphere covers the pixel) and indices (−1 there).
/// The renderer's 3D liquid lights this buffer (screen-space fluid rendering: W. J. van der
/// Laan, S. Green, M. Sainz, "Screen space fluid rendering with curvature flow", I3D 2009).
/// Points not finite are left out; of equal depths the first point wins. Bands of rows in
/// parallel, each taking its points in their order: the sequential loop's result for any
/// thread count.
/// InvalidInput for inconsistent lengths or a radius not in (0, MAX_SPHERE_RADIUS].
pub fn sphere_depths(
    col: &[f64],
    row: &[f64],
    depth: &[f64],
    radius: f64,
    width: usize,
    height: usize,
) -> Result<(Vec<f32>, Vec<i32>)> {
    let n = col.len();
    if row.len() != n || depth.len() != n {
        return Err(invalid("col", "col, row and depth must describe the same points"));
    }
    if !(radius > 0.0 && radius <= MAX_SPHERE_RADIUS) {
        return Err(invalid("radius", format!("radius must be in (0, {MAX_SPHERE_RADIUS}] pixels, got {radius}")));
    }
    if i32::try_from(n).is_err() {
        return Err(invalid("col", "at most 2³¹ − 1 points"));
    }
    // The depths, ids and the points' bins, allocated fallibly (as `splat`).
    let bytes = (width * height) as u128 * 8 + n as u128 * 48;
    let need = Need::new("sphere_depths", bytes, format!("a {width} × {height} depth buffer of {n} spheres"));
    need.check()?;
    let mut z = need.filled(width * height, f32::NEG_INFINITY)?;
    let mut ids = need.filled(width * height, -1i32)?;
    if width == 0 || height == 0 {
        return Ok((z, ids));
    }
    // Per point its pixel box (centres k + ½ within the radius), once: [x0, x1, y0, y1], or
    // x0 = u32::MAX off the image. Floors by truncation, of coordinates first clamped to just
    // beyond the image (which leaves a point off it off it): f64::floor and ceil are libm calls
    // on baseline x86-64, and three boxes a point took 70 % of the time.
    let floor = floor_i64;
    let spans: Vec<[u32; 4]> = need.collect((0..n).map(|i| {
        let (c, r, d) = (col[i], row[i], depth[i]);
        if !(c.is_finite() && r.is_finite() && d.is_finite()) {
            return [u32::MAX; 4];
        }
        let c = c.clamp(-radius - 2.0, width as f64 + radius + 2.0);
        let r = r.clamp(-radius - 2.0, height as f64 + radius + 2.0);
        // ceil(a) = −floor(−a)
        let x0 = (-floor(radius + 0.5 - c)).max(0);
        let x1 = floor(c + radius - 0.5).min(width as i64 - 1);
        let y0 = (-floor(radius + 0.5 - r)).max(0);
        let y1 = floor(r + radius - 0.5).min(height as i64 - 1);
        if x0 <= x1 && y0 <= y1 {
            [x0 as u32, x1 as u32, y0 as u32, y1 as u32]
        } else {
            [u32::MAX; 4]
        }
    }))?;
    // Bin the points to bands of rows in their order (a counting sort, as `rasterise`): each
    // band then keeps the first nearest point of the sequential loop, for any thread count.
    let bands = height.div_ceil(BAND);
    let mut start = need.filled(bands + 1, 0usize)?;
    for b in spans.iter().filter(|b| b[0] != u32::MAX) {
        for band in b[2] as usize / BAND..=b[3] as usize / BAND {
            start[band + 1] += 1;
        }
    }
    for b in 0..bands {
        start[b + 1] += start[b];
    }
    let mut fill = need.copy(&start)?;
    let mut binned = need.filled(start[bands], 0u32)?;
    for (i, b) in spans.iter().enumerate().filter(|(_, b)| b[0] != u32::MAX) {
        for band in b[2] as usize / BAND..=b[3] as usize / BAND {
            binned[fill[band]] = i as u32;
            fill[band] += 1;
        }
    }
    let r2 = radius * radius;
    let draw = |band: usize, z: &mut [f32], ids: &mut [i32]| {
        let (lo, hi) = (band * BAND, (band * BAND + BAND).min(height));
        for &i in &binned[start[band]..start[band + 1]] {
            let i = i as usize;
            let b = spans[i].map(|v| v as usize);
            let (c, r, d) = (col[i], row[i], depth[i]);
            // The sphere's top: no pixel of it is nearer (rounding to f32 keeps the order), so
            // a pixel already as near skips the square root.
            let top = (d + radius) as f32;
            for y in b[2].max(lo)..=b[3].min(hi - 1) {
                let dy = y as f64 + 0.5 - r;
                let line = (y - lo) * width;
                for x in b[0]..=b[1] {
                    if top <= z[line + x] {
                        continue;
                    }
                    let dx = x as f64 + 0.5 - c;
                    let q = r2 - dx * dx - dy * dy;
                    if q < 0.0 {
                        continue;
                    }
                    let s = (d + q.sqrt()) as f32;
                    if s > z[line + x] {
                        z[line + x] = s;
                        ids[line + x] = i as i32;
                    }
                }
            }
        }
    };
    let chunk = BAND * width;
    if binned.len() < 1 << 12
        || crate::par::fork(|| {
            z.par_chunks_mut(chunk).zip(ids.par_chunks_mut(chunk)).enumerate().for_each(|(b, (zc, ic))| draw(b, zc, ic))
        })
        .is_none()
    {
        z.chunks_mut(chunk).zip(ids.chunks_mut(chunk)).enumerate().for_each(|(b, (zc, ic))| draw(b, zc, ic));
    }
    Ok((z, ids))
}

/// Unit vertex normals of a triangle mesh: each vertex the normalised sum of its faces'
/// (p1 − p0) × (p2 − p0), which weights them by area. `x`: N × 3 positions; `faces`: T × 3
/// indices, checked by the caller (InvalidInput otherwise); `out`: N × 3, zero where the sum
/// vanishes or is not finite. Sequential: the scatter-add order is the face order, so the
/// result is the same for any thread count (about 1 ms for 1.3·10⁵ faces).
pub fn vertex_normals(x: &[f64], faces: &[u32], out: &mut [f64]) -> Result<()> {
    let n = x.len() / 3;
    if x.len() != 3 * n || out.len() != 3 * n || !faces.len().is_multiple_of(3) {
        return Err(invalid("x", "x and out must be N × 3, faces T × 3"));
    }
    if faces.iter().any(|&i| i as usize >= n) {
        return Err(invalid("faces", format!("face indices must lie in [0, {n})")));
    }
    out.fill(0.0);
    let p = |i: usize| [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
    for f in faces.chunks_exact(3) {
        let (a, b, c) = (p(f[0] as usize), p(f[1] as usize), p(f[2] as usize));
        let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        let nrm = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        for &i in f {
            for k in 0..3 {
                out[3 * i as usize + k] += nrm[k];
            }
        }
    }
    for v in out.chunks_exact_mut(3) {
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if len > 0.0 && len.is_finite() {
            v.iter_mut().for_each(|c| *c /= len);
        } else {
            v.fill(0.0);
        }
    }
    Ok(())
}

/// One triangle, set up in sample coordinates.
struct Setup {
    face: usize,
    /// Barycentric weights w0, w1 as affine functions of the sample centre: (a, b, c) each.
    w0: [f32; 3],
    w1: [f32; 3],
    bbox: [usize; 4], // col0, col1, row0, row1 (inclusive), clipped to the image
    front: bool,
}

/// Draws `mesh` into `rgb` (`height × width × 3`, linear colour, 0 where uncovered) and `cover`
/// (`height × width`, the covered fraction of each pixel's `ss²` samples). InvalidInput if the
/// arrays' lengths disagree or a face names a vertex that does not exist. Triangles with a
/// non-finite corner or no area are skipped.
pub fn rasterise(
    mesh: &Mesh,
    width: usize,
    height: usize,
    ss: usize,
    rgb: &mut [f32],
    cover: &mut [f32],
) -> Result<()> {
    let nv = mesh.verts.len() / 3;
    if mesh.verts.len() != 3 * nv || mesh.front.len() != 4 * nv || mesh.back.len() != 4 * nv {
        return Err(invalid("verts", "verts, front and back must describe the same vertices"));
    }
    if !mesh.faces.len().is_multiple_of(3) || mesh.faces.iter().any(|&i| i as usize >= nv) {
        return Err(invalid("faces", format!("face indices must lie in [0, {nv})")));
    }
    // The supersampled bands' depth, colour and hit buffers (17 bytes a sample, every band at
    // once at worst) and the triangles' setups and bins, checked at once (as `splat`).
    let bytes = (width * height) as u128 * (ss * ss) as u128 * 17 + mesh.faces.len() as u128 * 64;
    let need = Need::new("rasterise", bytes, format!("a {width} × {height} mesh image at {ss}× supersampling"));
    need.room(bytes)?;
    if let Some(uv) = mesh.uv {
        if uv.len() != 2 * nv {
            return Err(invalid("uv", "uv must have one (u, v) per vertex"));
        }
    }
    if let Some(t) = &mesh.texture {
        if t.width == 0 || t.height == 0 || t.rgb.len() != 3 * t.width * t.height || mesh.uv.is_none() {
            return Err(invalid("texture", "texture must be height × width × 3, with uv given"));
        }
    }
    if ss == 0 || rgb.len() != 3 * width * height || cover.len() != width * height {
        return Err(invalid("ss", "ss must be >= 1 and the images width × height"));
    }
    let tris = setup(mesh, width, height, ss);
    // Bin the triangles to bands, keeping their order (a counting sort).
    let bands = height.div_ceil(BAND);
    let band_rows = BAND * ss;
    let mut start = need.filled(bands + 1, 0usize)?;
    for t in &tris {
        for b in t.bbox[2] / band_rows..=t.bbox[3] / band_rows {
            start[b + 1] += 1;
        }
    }
    for b in 0..bands {
        start[b + 1] += start[b];
    }
    let mut fill = need.copy(&start)?;
    let mut binned = need.filled(start[bands], 0u32)?;
    for (k, t) in tris.iter().enumerate() {
        for b in t.bbox[2] / band_rows..=t.bbox[3] / band_rows {
            binned[fill[b]] = k as u32;
            fill[b] += 1;
        }
    }
    let draw = |b: usize, rgb: &mut [f32], cover: &mut [f32]| {
        let list = &binned[start[b]..start[b + 1]];
        draw_band(mesh, &tris, list, b * BAND, width, ss, rgb, cover);
    };
    let chunk = BAND * width;
    if width * height * ss * ss < 1 << 16
        || crate::par::fork(|| {
            rgb.par_chunks_mut(3 * chunk)
                .zip(cover.par_chunks_mut(chunk))
                .enumerate()
                .for_each(|(b, (c, v))| draw(b, c, v))
        })
        .is_none()
    {
        rgb.chunks_mut(3 * chunk).zip(cover.chunks_mut(chunk)).enumerate().for_each(|(b, (c, v))| draw(b, c, v));
    }
    Ok(())
}

/// Blends a drawn mesh over `background` (height × width × 3 bytes, sRGB as stored) in place:
/// each pixel `round(background · (1 − cover) + 255 · rgb · cover)`, the colour clamped to
/// [0, 1] (highlights may exceed 1). Lengths as `rasterise` wrote them.
pub fn composite(background: &mut [u8], rgb: &[f32], cover: &[f32]) {
    for ((px, c), &a) in background.chunks_exact_mut(3).zip(rgb.chunks_exact(3)).zip(cover) {
        if a > 0.0 {
            for ch in 0..3 {
                let v = px[ch] as f32 * (1.0 - a) + 255.0 * c[ch].clamp(0.0, 1.0) * a;
                px[ch] = (v + 0.5).clamp(0.0, 255.0) as u8; // round half up; v >= 0
            }
        }
    }
}

/// ⌈x⌉ and ⌊x⌋ as integers without `f32::ceil`/`floor`, which are libm calls on baseline
/// x86-64 (no SSE4.1 `roundps`) and were most of the set-up's time. `as` saturates.
#[inline]
fn ceil_i(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) < x {
        t + 1
    } else {
        t
    }
}

#[inline]
fn floor_i(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x {
        t - 1
    } else {
        t
    }
}

/// Per-triangle set-up in sample coordinates (pixel coordinates × `ss`), in face order; in
/// parallel on the pool of the call (rayon's ordered collect: the same list for any count).
fn setup(mesh: &Mesh, width: usize, height: usize, ss: usize) -> Vec<Setup> {
    let one = |face: usize| one_setup(mesh, face, width * ss, height * ss, ss as f32);
    let n = mesh.faces.len() / 3;
    if n >= crate::par::PAR_MIN {
        if let Some(v) = crate::par::fork(|| (0..n).into_par_iter().filter_map(one).collect()) {
            return v;
        }
    }
    (0..n).filter_map(one).collect()
}

fn one_setup(mesh: &Mesh, face: usize, sw: usize, sh: usize, scale: f32) -> Option<Setup> {
    let f = &mesh.faces[3 * face..3 * face + 3];
    let s = |i: usize, k: usize| if k < 2 { mesh.verts[3 * i + k] * scale } else { mesh.verts[3 * i + k] };
    let (i0, i1, i2) = (f[0] as usize, f[1] as usize, f[2] as usize);
    let (x0, y0, x1, y1, x2, y2) = (s(i0, 0), s(i0, 1), s(i1, 0), s(i1, 1), s(i2, 0), s(i2, 1));
    if ![x0, y0, x1, y1, x2, y2, s(i0, 2), s(i1, 2), s(i2, 2)].iter().all(|v| v.is_finite()) {
        return None;
    }
    // Twice the signed area in (column, row) coordinates, computed in f64: thin slivers of a
    // large image cancel badly in f32.
    let (x0d, y0d, x1d, y1d, x2d, y2d) = (x0 as f64, y0 as f64, x1 as f64, y1 as f64, x2 as f64, y2 as f64);
    let area = (x1d - x0d) * (y2d - y0d) - (x2d - x0d) * (y1d - y0d);
    if !(area.abs() > 1e-12) {
        return None;
    }
    // Sample centres k + 0.5 inside the box, clipped to the image.
    let c0 = ceil_i(x0.min(x1).min(x2) - 0.5).max(0);
    let c1 = floor_i(x0.max(x1).max(x2) - 0.5).min(sw as i64 - 1);
    let r0 = ceil_i(y0.min(y1).min(y2) - 0.5).max(0);
    let r1 = floor_i(y0.max(y1).max(y2) - 0.5).min(sh as i64 - 1);
    if c1 < c0 || r1 < r0 {
        return None;
    }
    let inv = 1.0 / area;
    let w0 = [((y1d - y2d) * inv) as f32, ((x2d - x1d) * inv) as f32, ((x1d * y2d - x2d * y1d) * inv) as f32];
    let w1 = [((y2d - y0d) * inv) as f32, ((x0d - x2d) * inv) as f32, ((x2d * y0d - x0d * y2d) * inv) as f32];
    Some(Setup {
        face,
        w0,
        w1,
        bbox: [c0 as usize, c1 as usize, r0 as usize, r1 as usize],
        // Rows grow downwards: a counter-clockwise turn on screen has a negative area here.
        front: area < 0.0,
    })
}

/// Draws band `row0 / BAND` (output rows `row0..`) from the triangles `list` (indices into
/// `tris`, in drawing order), then resolves its samples into `rgb` / `cover`.
#[allow(clippy::too_many_arguments)]
fn draw_band(
    mesh: &Mesh,
    tris: &[Setup],
    list: &[u32],
    row0: usize,
    width: usize,
    ss: usize,
    rgb: &mut [f32],
    cover: &mut [f32],
) {
    let rows = cover.len() / width; // output rows in this band (the last band may be short)
    if list.is_empty() {
        rgb.fill(0.0);
        cover.fill(0.0);
        return;
    }
    let (sw, srows, srow0) = (width * ss, rows * ss, row0 * ss);
    let mut depth = vec![f32::NEG_INFINITY; sw * srows];
    let mut col = vec![0f32; 3 * sw * srows];
    let mut hit = vec![false; sw * srows];
    for &k in list {
        let t = &tris[k as usize];
        let f = &mesh.faces[3 * t.face..3 * t.face + 3];
        let (i0, i1, i2) = (f[0] as usize, f[1] as usize, f[2] as usize);
        let attr = if t.front { mesh.front } else { mesh.back };
        // The corners' attributes, loaded once per triangle rather than per sample.
        let load = |i: usize| [attr[4 * i], attr[4 * i + 1], attr[4 * i + 2], attr[4 * i + 3]];
        let (a0, a1, a2) = (load(i0), load(i1), load(i2));
        let (z0, z1, z2) = (mesh.verts[3 * i0 + 2], mesh.verts[3 * i1 + 2], mesh.verts[3 * i2 + 2]);
        let tex_uv = match (&mesh.texture, mesh.uv) {
            (Some(tex), Some(uv)) => {
                Some((tex, [uv[2 * i0], uv[2 * i0 + 1], uv[2 * i1], uv[2 * i1 + 1], uv[2 * i2], uv[2 * i2 + 1]]))
            }
            _ => None,
        };
        let r_lo = t.bbox[2].max(srow0);
        let r_hi = t.bbox[3].min(srow0 + srows - 1);
        for r in r_lo..=r_hi {
            let py = r as f32 + 0.5;
            let row_base = (r - srow0) * sw;
            for c in t.bbox[0]..=t.bbox[1] {
                let px = c as f32 + 0.5;
                let w0 = t.w0[0] * px + t.w0[1] * py + t.w0[2];
                let w1 = t.w1[0] * px + t.w1[1] * py + t.w1[2];
                let w2 = 1.0 - w0 - w1;
                // A sample on a shared edge goes to both triangles; the depth test (ties to
                // the later one) picks.
                const EPS: f32 = -1e-5;
                if w0 < EPS || w1 < EPS || w2 < EPS {
                    continue;
                }
                let zz = w0 * z0 + w1 * z1 + w2 * z2;
                let p = row_base + c;
                if zz < depth[p] {
                    continue;
                }
                depth[p] = zz;
                hit[p] = true;
                let base = match &tex_uv {
                    Some((tex, uv)) => {
                        let u = w0 * uv[0] + w1 * uv[2] + w2 * uv[4];
                        let v = w0 * uv[1] + w1 * uv[3] + w2 * uv[5];
                        // Nearest texel; + 0.5 then truncation rounds these non-negative values.
                        let tx = (u.clamp(0.0, 1.0) * (tex.width - 1) as f32 + 0.5) as usize;
                        let ty = ((1.0 - v.clamp(0.0, 1.0)) * (tex.height - 1) as f32 + 0.5) as usize;
                        let q = 3 * (ty * tex.width + tx);
                        [tex.rgb[q], tex.rgb[q + 1], tex.rgb[q + 2]]
                    }
                    None => [1.0; 3],
                };
                let spec = w0 * a0[3] + w1 * a1[3] + w2 * a2[3];
                let out = &mut col[3 * p..3 * p + 3];
                for ch in 0..3 {
                    out[ch] = base[ch] * (w0 * a0[ch] + w1 * a1[ch] + w2 * a2[ch]) + spec;
                }
            }
        }
    }
    // Resolve: the mean colour of the covered samples and the covered fraction.
    let norm = 1.0 / (ss * ss) as f32;
    for r in 0..rows {
        for c in 0..width {
            let mut acc = [0f32; 3];
            let mut n = 0u32;
            for dy in 0..ss {
                for dx in 0..ss {
                    let p = (r * ss + dy) * sw + c * ss + dx;
                    if hit[p] {
                        n += 1;
                        for ch in 0..3 {
                            acc[ch] += col[3 * p + ch];
                        }
                    }
                }
            }
            let o = r * width + c;
            cover[o] = n as f32 * norm;
            if n > 0 {
                for ch in 0..3 {
                    rgb[3 * o + ch] = acc[ch] / n as f32;
                }
            } else {
                for ch in 0..3 {
                    rgb[3 * o + ch] = 0.0;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// The box blur against the exact sums (f64) of its definition: each pass a mean over the
    /// window, zeros beyond the edges, within f32 rounding for narrow (r ≤ 2, shifted sums) and
    /// wide (running sums) windows, at image sizes smaller and larger than the window; the
    /// same bits for 1 and 3 threads; bad input refused.
    #[test]
    fn blur_is_the_box_mean_and_the_same_for_any_thread_count() {
        let mut seed = 11u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) as f32
        };
        for &(w, h, r, passes) in &[
            (37usize, 23usize, 1usize, 1usize),
            (37, 23, 2, 3),
            (64, 90, 5, 3),
            (7, 5, 9, 2),
            (1, 1, 3, 1),
            (200, 3, 4, 1),
        ] {
            let a: Vec<f32> = (0..w * h).map(|_| rnd()).collect();
            // The definition, pass by pass in f64 from the f32 image.
            let mut want: Vec<f64> = a.iter().map(|&v| v as f64).collect();
            let win = (2 * r + 1) as f64;
            for _ in 0..passes {
                let mut down = vec![0.0; w * h];
                for y in 0..h {
                    for x in 0..w {
                        let lo = y.saturating_sub(r);
                        down[y * w + x] = (lo..(y + r + 1).min(h)).map(|t| want[t * w + x]).sum::<f64>() / win;
                    }
                }
                for y in 0..h {
                    for x in 0..w {
                        let lo = x.saturating_sub(r);
                        want[y * w + x] = (lo..(x + r + 1).min(w)).map(|t| down[y * w + t]).sum::<f64>() / win;
                    }
                }
            }
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let three = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
            let got = crate::par::install(Some(&Arc::new(one)), || blur(&a, w, h, r, passes)).unwrap();
            let got3 = crate::par::install(Some(&Arc::new(three)), || blur(&a, w, h, r, passes)).unwrap();
            assert!(
                got.iter().zip(&got3).all(|(p, q)| p.to_bits() == q.to_bits()),
                "{w}×{h} r {r}: thread counts differ"
            );
            assert_eq!(got, blur(&a, w, h, r, passes).unwrap(), "serial");
            // Running sums over a line lose up to about (line length) ulps of the line's sum.
            let tol = 4.0 * f32::EPSILON as f64 * (w.max(h) + 2 * r + 2) as f64;
            for (k, (&g, &e)) in got.iter().zip(&want).enumerate() {
                assert!((g as f64 - e).abs() <= tol, "{w}×{h} r {r} passes {passes} pixel {k}: {g} against {e}");
            }
        }
        assert!(blur(&[0.0; 6], 4, 2, 1, 3).is_err());
        assert!(blur(&[0.0; 4], 2, 2, MAX_BLUR_RADIUS + 1, 1).is_err());
        assert_eq!(blur(&[], 0, 5, 3, 3).unwrap(), Vec::<f32>::new());
    }

    #[test]
    fn sphere_depths_are_the_sequential_loops_for_any_thread_count() {
        // 3000 points over a 97 × 61 image (bands cut through spheres), with repeated depths
        // so ties occur: the banded, parallel buffer is the plain loop's, first point winning.
        let (w, h, rad) = (97usize, 61usize, 2.7);
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let n = 3000;
        let col: Vec<f64> = (0..n).map(|_| rnd() * 110.0 - 6.0).collect();
        let row: Vec<f64> = (0..n).map(|_| rnd() * 74.0 - 6.0).collect();
        let depth: Vec<f64> = (0..n).map(|_| (rnd() * 8.0).floor()).collect();
        let (mut z0, mut id0) = (vec![f32::NEG_INFINITY; w * h], vec![-1i32; w * h]);
        for i in 0..n {
            for y in 0..h {
                for x in 0..w {
                    let (dx, dy) = (x as f64 + 0.5 - col[i], y as f64 + 0.5 - row[i]);
                    let q = rad * rad - dx * dx - dy * dy;
                    if q >= 0.0 && ((depth[i] + q.sqrt()) as f32) > z0[y * w + x] {
                        z0[y * w + x] = (depth[i] + q.sqrt()) as f32;
                        id0[y * w + x] = i as i32;
                    }
                }
            }
        }
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let (z, ids) = pool.install(|| sphere_depths(&col, &row, &depth, rad, w, h)).unwrap();
            assert_eq!(ids, id0, "threads {threads}");
            assert!(z.iter().zip(&z0).all(|(a, b)| a.to_bits() == b.to_bits()), "threads {threads}");
        }
    }

    #[test]
    fn sphere_depths_keep_the_nearest_surface() {
        // Two spheres of radius 3 over one another: the nearer (depth 10) wins where both
        // cover, its surface height is depth + √(r² − d²), and the far one shows beside it.
        let (col, row, depth) = ([5.0, 8.0], [5.0, 5.0], [2.0, 10.0]);
        let (z, ids) = sphere_depths(&col, &row, &depth, 3.0, 16, 10).unwrap();
        let at = |x: usize, y: usize| (z[y * 16 + x], ids[y * 16 + x]);
        // Pixel (7, 4) has its centre (7.5, 4.5) 0.707 from the near sphere's centre.
        let (s, id) = at(7, 4);
        assert_eq!(id, 1);
        assert!((s as f64 - (10.0 + (9.0f64 - 0.5).sqrt())).abs() < 1e-5, "{s}");
        // Pixel (3, 4): only the far sphere, 1.58 from its centre.
        let (s, id) = at(3, 4);
        assert_eq!(id, 0);
        assert!((s as f64 - (2.0 + (9.0f64 - 2.5).sqrt())).abs() < 1e-5, "{s}");
        // Outside both: empty.
        assert_eq!(at(0, 0), (f32::NEG_INFINITY, -1));
        assert_eq!(at(15, 9), (f32::NEG_INFINITY, -1));
        // Every covered pixel lies within the radius of its point's centre.
        for y in 0..10 {
            for x in 0..16 {
                let (_, id) = at(x, y);
                if id >= 0 {
                    let (dx, dy) = (x as f64 + 0.5 - col[id as usize], y as f64 + 0.5 - row[id as usize]);
                    assert!(dx * dx + dy * dy <= 9.0);
                }
            }
        }
    }

    #[test]
    fn sphere_depths_refuse_bad_input_and_skip_points_off_the_image() {
        assert!(sphere_depths(&[1.0], &[1.0, 2.0], &[0.0], 1.0, 4, 4).is_err());
        for r in [0.0, -1.0, f64::NAN, MAX_SPHERE_RADIUS * 2.0] {
            assert!(sphere_depths(&[1.0], &[1.0], &[0.0], r, 4, 4).is_err(), "{r}");
        }
        let (z, ids) = sphere_depths(&[f64::NAN, -50.0, 1e300], &[1.0, 1.0, 1.0], &[0.0, 0.0, 0.0], 2.0, 4, 4).unwrap();
        assert!(z.iter().all(|v| *v == f32::NEG_INFINITY) && ids.iter().all(|i| *i == -1));
    }

    fn draw(
        verts: &[f32],
        faces: &[u32],
        front: &[f32],
        back: &[f32],
        w: usize,
        h: usize,
        ss: usize,
    ) -> (Vec<f32>, Vec<f32>) {
        let mut rgb = vec![0.0; 3 * w * h];
        let mut cover = vec![0.0; w * h];
        let mesh = Mesh { verts, faces, front, back, uv: None, texture: None };
        rasterise(&mesh, w, h, ss, &mut rgb, &mut cover).unwrap();
        (rgb, cover)
    }

    /// Per-vertex attributes: every vertex the same colour multiplier and no highlight.
    fn flat(n: usize, c: [f32; 3]) -> Vec<f32> {
        (0..n).flat_map(|_| [c[0], c[1], c[2], 0.0]).collect()
    }

    #[test]
    fn a_square_covers_its_area_and_edges_are_fractional() {
        // Two triangles making the square [2.25, 7.75] × [1.5, 6.5] (pixel units).
        let v = [2.25, 1.5, 0.0, 7.75, 1.5, 0.0, 2.25, 6.5, 0.0, 7.75, 6.5, 0.0];
        let f = [0, 1, 2, 1, 3, 2];
        let (_, cover) = draw(&v, &f, &flat(4, [1.0; 3]), &flat(4, [1.0; 3]), 10, 8, 4);
        let total: f32 = cover.iter().sum();
        assert!((total - 5.5 * 5.0).abs() < 0.3, "covered area {total}");
        // Interior pixels fully covered, a pixel cut by the left edge a quarter or more uncovered.
        assert_eq!(cover[3 * 10 + 4], 1.0);
        assert!(cover[3 * 10 + 2] > 0.6 && cover[3 * 10 + 2] < 0.9, "{}", cover[3 * 10 + 2]);
        assert_eq!(cover[0], 0.0);
    }

    #[test]
    fn gouraud_interpolates_linearly() {
        // One big triangle with red 0 at x = 0 and 1 at x = 40: the middle pixel reads ~0.5.
        let v = [0.0, 0.0, 0.0, 40.0, 0.0, 0.0, 0.0, 40.0, 0.0];
        let attrs = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (rgb, _) = draw(&v, &[0, 1, 2], &attrs, &attrs, 40, 40, 1);
        let red = |c: usize, r: usize| rgb[3 * (r * 40 + c)];
        assert!((red(20, 5) - 20.5 / 40.0).abs() < 1e-5, "{}", red(20, 5));
        assert!((red(10, 5) - 10.5 / 40.0).abs() < 1e-5);
    }

    #[test]
    fn nearer_triangle_wins_whatever_the_order_and_sides_pick_their_colours() {
        // Two overlapping triangles at depths 1 (red) and 2 (green), both orders.
        let tri = |x: f32, z: f32| [x, 0.0, z, x + 20.0, 0.0, z, x, 20.0, z];
        let mut v = tri(0.0, 1.0).to_vec();
        v.extend(tri(2.0, 2.0));
        let mut front = flat(3, [1.0, 0.0, 0.0]);
        front.extend(flat(3, [0.0, 1.0, 0.0]));
        let back = flat(6, [0.0, 0.0, 1.0]);
        for faces in [[0u32, 1, 2, 3, 4, 5], [3, 4, 5, 0, 1, 2]] {
            let (rgb, _) = draw(&v, &faces, &back, &front, 20, 20, 1);
            // These corners turn clockwise on screen, so their back side (red, green) shows;
            // the pixel at (5, 5) is covered by both triangles and the nearer, green, wins.
            let p = 3 * (5 * 20 + 5);
            assert_eq!(&rgb[p..p + 3], &[0.0, 1.0, 0.0], "order {faces:?}");
        }
        // Reversing the winding shows the front side's colour.
        let (rgb, _) = draw(&v[..9], &[0, 2, 1], &back[..12], &front[..12], 20, 20, 1);
        assert_eq!(&rgb[3 * (5 * 20 + 5)..3 * (5 * 20 + 5) + 3], &[0.0, 0.0, 1.0]);
    }

    #[test]
    fn same_result_for_any_thread_count() {
        // A fan of many small triangles over a large image.
        let (w, h) = (300, 200);
        let mut v = Vec::new();
        let mut f = Vec::new();
        for k in 0..2000u32 {
            let (x, y) = ((k * 37 % 290) as f32 + 0.3, (k * 53 % 190) as f32 + 0.7);
            v.extend([x, y, (k % 7) as f32, x + 9.5, y + 1.0, 0.0, x + 2.0, y + 8.25, 1.0]);
            f.extend([3 * k, 3 * k + 1, 3 * k + 2]);
        }
        let attrs: Vec<f32> = (0..6000).flat_map(|i| [(i % 5) as f32 * 0.2, 0.5, 0.25, 0.1]).collect();
        let mesh = Mesh { verts: &v, faces: &f, front: &attrs, back: &attrs, uv: None, texture: None };
        let run = |threads: usize| {
            let pool = std::sync::Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap());
            let mut rgb = vec![0.0; 3 * w * h];
            let mut cover = vec![0.0; w * h];
            crate::par::install(Some(&pool), || rasterise(&mesh, w, h, 2, &mut rgb, &mut cover)).unwrap();
            (rgb, cover)
        };
        let (a, ca) = run(1);
        let (b, cb) = run(3);
        assert!(ca.iter().sum::<f32>() > 1000.0);
        assert_eq!(
            a.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            b.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(ca, cb);
    }

    #[test]
    fn bad_input_is_refused_and_non_finite_triangles_skipped() {
        let v = [0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 4.0, 0.0];
        let a = flat(3, [1.0; 3]);
        let mut rgb = vec![0.0; 3 * 16];
        let mut cover = vec![0.0; 16];
        let bad = Mesh { verts: &v, faces: &[0, 1, 3], front: &a, back: &a, uv: None, texture: None };
        assert!(rasterise(&bad, 4, 4, 1, &mut rgb, &mut cover).is_err());
        let nan = [f32::NAN, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 4.0, 0.0];
        let skip = Mesh { verts: &nan, faces: &[0, 1, 2], front: &a, back: &a, uv: None, texture: None };
        rasterise(&skip, 4, 4, 1, &mut rgb, &mut cover).unwrap();
        assert!(cover.iter().all(|&c| c == 0.0) && rgb.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn discs_cover_their_area_with_soft_edges() {
        // A white disc of radius 5.3 on black: the summed coverage is its area, interior pixels
        // are white, edge pixels grey, far ones black; a later disc covers an earlier one.
        let (w, h) = (24usize, 24usize);
        let mut img = vec![0u8; 3 * w * h];
        draw_discs(&mut img, w, h, &[12.2], &[11.7], &[5.3], &[255, 255, 255]).unwrap();
        let total: f32 = img.chunks_exact(3).map(|p| p[0] as f32 / 255.0).sum();
        assert!((total - std::f32::consts::PI * 5.3 * 5.3).abs() < 0.5, "{total}");
        assert_eq!(img[3 * (11 * w + 12)], 255);
        assert!(img.chunks_exact(3).any(|p| p[0] > 30 && p[0] < 225));
        assert_eq!(img[0], 0);
        draw_discs(&mut img, w, h, &[12.2, f32::NAN], &[11.7, 0.0], &[2.0, 3.0], &[255, 0, 0, 0, 255, 0]).unwrap();
        assert_eq!(&img[3 * (11 * w + 12)..3 * (11 * w + 12) + 3], &[255, 0, 0]);
        assert!(draw_discs(&mut img, w, h, &[1.0], &[1.0], &[1.0], &[0, 0]).is_err());
    }

    #[test]
    fn composite_blends_by_coverage() {
        let mut bg = [200u8, 100, 0, 50, 50, 50];
        composite(&mut bg, &[0.0, 0.0, 1.0, 2.0, 0.5, 0.0], &[0.5, 0.0]);
        assert_eq!(bg, [100, 50, 128, 50, 50, 50]);
    }

    #[test]
    fn vertex_normals_of_a_folded_sheet() {
        // Two triangles folded 90° along the shared edge (0,0,0)-(0,1,0): one in z = 0, one in
        // x = 0. The shared vertices' normal is the bisector; the others' are their faces'.
        let x = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let faces = [0, 2, 1, 0, 1, 3];
        let mut n = [0.0; 12];
        vertex_normals(&x, &faces, &mut n).unwrap();
        let h = 0.5f64.sqrt();
        let expect = [h, 0.0, h, h, 0.0, h, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0];
        for (a, b) in n.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{n:?}");
        }
        assert!(vertex_normals(&x, &[0, 1, 4], &mut n).is_err());
    }

    #[test]
    fn texture_is_sampled_at_the_interpolated_uv() {
        // A 2×1 texture (left red, right blue) over a square: left half red, right half blue.
        let v = [0.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.0, 20.0, 0.0, 20.0, 20.0, 0.0];
        let uv = [0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
        let tex = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let a = flat(4, [1.0; 3]);
        let mesh = Mesh {
            verts: &v,
            faces: &[0, 1, 2, 1, 3, 2],
            front: &a,
            back: &a,
            uv: Some(&uv),
            texture: Some(Texture { rgb: &tex, width: 2, height: 1 }),
        };
        let mut rgb = vec![0.0; 3 * 400];
        let mut cover = vec![0.0; 400];
        rasterise(&mesh, 20, 20, 1, &mut rgb, &mut cover).unwrap();
        assert_eq!(&rgb[3 * (10 * 20 + 3)..3 * (10 * 20 + 3) + 3], &[1.0, 0.0, 0.0]);
        assert_eq!(&rgb[3 * (10 * 20 + 16)..3 * (10 * 20 + 16) + 3], &[0.0, 0.0, 1.0]);
    }
}
