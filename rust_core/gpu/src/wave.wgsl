// The damped wave equation by leapfrog on a cell-centred grid, the CPU's `grids::wave` step cell
// for cell: u⁺ = (2u − (1 − a) u⁻ + k L u) / (1 + a), a = γ dt / 2, k = (c dt / dx)², with
// damping layers (γ per cell), obstacles (u⁺ times 0) and driven sources. The host prepends the
// precision header (`real`, `bad`).
//
// Gather only: a thread writes u⁺ of its own cells over their u⁻ (the buffer `up`); the roles of
// the two buffers swap each step through the host's two bind groups. The damping books are
// reduced in each workgroup in one fixed tree order into that workgroup's own slot, and the
// sources are applied by one thread in the CPU's order: no atomics on floats, so a run repeats
// bit for bit on one adapter. The one atomic is an integer min over the index of the first
// non-finite cell.

struct Params {
    nx: u32,
    ny: u32,
    nz: u32,
    // Two bits per face f (x-, x+, y-, y+, z-, z+) at bit 2f: 0 fixed (the ghost is −u, an odd
    // reflection), 1 free (the ghost is u), 2 periodic (the opposite cell).
    edges: u32,
    // Workgroups along x (segments of WG cells of a row) and along y (blocks of CPT rows; block
    // b = y + gy·z holds rows CPT·b .. CPT·b + CPT − 1).
    gx: u32,
    three: u32,
    gy: u32,
    // Bit 0: γ per cell (`gam`, damping layers); bit 1: obstacles (`keep`); bit 2: damping
    // anywhere (else the books' reduction, all zeros, is skipped).
    flags: u32,
    // Source entries (cells of the oscillators' profiles, all oscillators in order) and the
    // number of oscillators.
    entries: u32,
    nosc: u32,
    pad0: u32,
    pad1: u32,
    // k = (c dt/dx)², 2·dim (the Laplacian's centre weight), dt/2, the uniform γ, dt, 1/(4 dt),
    // and for the uniform γ the CPU's 1 / (1 + a) and 1 − a (a = γ dt/2), computed on the host
    // as the CPU computes them once a row: no division per cell.
    k: real,
    centre: real,
    half: real,
    gamma: real,
    dt: real,
    inv4dt: real,
    inv0: real,
    oma0: real,
};

const WG: u32 = 64u;
// The host sets CPT by the grid's size (4, 8 or 16: `grid::rows_for`).
const CPT: u32 = 4u;

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> u: array<real>;
// u⁻ before a step, u⁺ after it.
@group(0) @binding(2) var<storage, read_write> up: array<real>;
@group(0) @binding(3) var<storage, read> gam: array<real>;
// 1 on free cells, 0 on obstacles.
@group(0) @binding(4) var<storage, read> keep: array<real>;
// One per workgroup: Σ_steps Σ_cells γ (u⁺ − u⁻)² / (4 dt) (per unit cell measure).
@group(0) @binding(5) var<storage, read_write> diss: array<real>;
// [0]: the smallest index of a cell whose u is not finite (or 0xffffffff).
@group(0) @binding(6) var<storage, read_write> flag: array<atomic<u32>>;
// [0]: the step within the submission (the sources' row of forcing); then per source entry e:
// its cell (1 + 2e) and its oscillator (2 + 2e).
@group(0) @binding(7) var<storage, read_write> ints: array<u32>;
// [0], [1]: the sources' damping and work, Σ_steps (per unit cell measure); then per entry its
// u⁻ before the step (2 + e) and its weight (2 + E + e); then the forcing of each step and
// oscillator (2 + 2E + step·nosc + o), computed on the host.
@group(0) @binding(8) var<storage, read_write> src: array<real>;

var<workgroup> sd: array<real, WG>;

fn edge(f: u32) -> u32 {
    return (P.edges >> (2u * f)) & 3u;
}

// A neighbour of a cell: its index and whether its value is taken negated (a fixed face's ghost
// is minus the cell itself). Only indices are chosen in branches and every value is then loaded
// unconditionally, so that a thread's five (seven) loads are in flight together. The sign is
// applied by a select, not by a product with ±1: each such product is exact, yet with them
// lavapipe's 3D fields came out 4e-15 from the CPU's in f64 (its compiler rounded the stencil's
// other products differently); with the select they are the CPU's bit for bit again.
struct Nb {
    at: u32,
    neg: bool,
};

fn value(n: Nb) -> real {
    let v = u[n.at];
    return select(v, -v, n.neg);
}

// The neighbour across x− (side 0) or x+ (side 1) of cell i of the row starting at `row`, as the
// CPU's `Grid::ghost_x` gives it beyond the row's ends.
fn along_x(row: u32, i: u32, side: u32) -> Nb {
    if (side == 0u && i > 0u) {
        return Nb(row + i - 1u, false);
    }
    if (side == 1u && i + 1u < P.nx) {
        return Nb(row + i + 1u, false);
    }
    let e = edge(side);
    if (e == 2u) {
        return Nb(select(row, row + P.nx - 1u, side == 0u), false);
    }
    return Nb(row + i, e == 0u);
}

// The neighbour one step back (`fwd` false) or forward along an axis of n cells and `stride`,
// cell c at coordinate q: the CPU's `Grid::neighbour_row`.
fn across(c: u32, q: u32, n: u32, stride: u32, face: u32, fwd: bool) -> Nb {
    if (fwd && q + 1u < n) {
        return Nb(c + stride, false);
    }
    if (!fwd && q > 0u) {
        return Nb(c - stride, false);
    }
    let e = edge(face);
    if (e == 2u) {
        return Nb(select(c + (n - 1u) * stride, c - (n - 1u) * stride, fwd), false);
    }
    return Nb(c, e == 0u);
}

fn block_of(wid: vec3<u32>) -> u32 {
    return wid.y + P.gy * wid.z;
}

// A workgroup updates WG cells of a row in each of CPT consecutive rows (as Gray–Scott's).
@compute @workgroup_size(WG)
fn step(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let rows = P.ny * P.nz;
    let r0 = block_of(wid) * CPT;
    let i = wid.x * WG + lid.x;
    let nxy = P.nx * P.ny;
    var d: real = 0.0;
    if (i < P.nx && r0 < rows) {
        var j = r0 % P.ny;
        var k = r0 / P.ny;
        for (var m = 0u; m < CPT; m = m + 1u) {
            let rr = r0 + m;
            if (rr < rows) {
                let row = rr * P.nx;
                let c = row + i;
                let uc = u[c];
                // The CPU's order of operations (grids::wave, `span`).
                var lap = value(along_x(row, i, 0u)) + value(along_x(row, i, 1u))
                    + value(across(c, j, P.ny, P.nx, 2u, false)) + value(across(c, j, P.ny, P.nx, 3u, true))
                    - P.centre * uc;
                if (P.three != 0u) {
                    lap = lap + (value(across(c, k, P.nz, nxy, 4u, false)) + value(across(c, k, P.nz, nxy, 5u, true)));
                }
                var g = P.gamma;
                var inv = P.inv0;
                var oma = P.oma0;
                if ((P.flags & 1u) != 0u) {
                    g = gam[c];
                    let a = g * P.half;
                    inv = 1.0 / (1.0 + a);
                    oma = 1.0 - a;
                }
                let um = up[c];
                var nw = (2.0 * uc - oma * um + P.k * lap) * inv;
                if ((P.flags & 2u) != 0u) {
                    nw = nw * keep[c];
                }
                up[c] = nw;
                d = d + g * (nw - um) * (nw - um);
            }
            j = j + 1u;
            if (j == P.ny) {
                j = 0u;
                k = k + 1u;
            }
        }
    }
    if ((P.flags & 4u) == 0u) {
        return; // undamped: nothing to book (a uniform branch: the whole dispatch returns here)
    }
    sd[lid.x] = d;
    workgroupBarrier();
    for (var w = WG / 2u; w > 0u; w = w / 2u) {
        if (lid.x < w) {
            sd[lid.x] = sd[lid.x] + sd[lid.x + w];
        }
        workgroupBarrier();
    }
    if (lid.x == 0u) {
        let g = wid.x + P.gx * block_of(wid);
        diss[g] = diss[g] + P.inv4dt * sd[0];
    }
}

// Before the step: u⁻ at each source entry's cell (the step overwrites it with u⁺).
@compute @workgroup_size(WG)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    if (e < P.entries) {
        src[2u + e] = up[ints[1u + 2u * e]];
    }
}

// After the step, one thread: each entry's forcing added to u⁺ in the CPU's order (entries may
// share a cell), its work and the damping it changes booked.
@compute @workgroup_size(1)
fn sources() {
    let s = ints[0];
    let n = P.entries;
    for (var e = 0u; e < n; e = e + 1u) {
        let c = ints[1u + 2u * e];
        if ((P.flags & 2u) != 0u && keep[c] == 0.0) {
            continue;
        }
        let um = src[2u + e];
        let w = src[2u + n + e];
        let f = src[2u + 2u * n + s * P.nosc + ints[2u + 2u * e]];
        var g = P.gamma;
        if ((P.flags & 1u) != 0u) {
            g = gam[c];
        }
        let before = up[c];
        let after = before + P.dt * P.dt * f * w / (1.0 + 0.5 * g * P.dt);
        up[c] = after;
        let vb0 = (before - um) / (2.0 * P.dt);
        let vb1 = (after - um) / (2.0 * P.dt);
        src[0] = src[0] + P.dt * g * (vb1 * vb1 - vb0 * vb0);
        src[1] = src[1] + P.dt * f * w * vb1;
    }
    ints[0] = s + 1u;
}

@compute @workgroup_size(WG)
fn check(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = wid.x * WG + lid.x;
    if (i >= P.nx) {
        return;
    }
    for (var m = 0u; m < CPT; m = m + 1u) {
        let rr = block_of(wid) * CPT + m;
        let c = rr * P.nx + i;
        if (rr < P.ny * P.nz && bad(u[c])) {
            atomicMin(&flag[0], c);
        }
    }
}
