// Gray–Scott reaction–diffusion on a cell-centred grid (forward Euler, 5- or 7-point Laplacian),
// the CPU's `grids::gray_scott` cell for cell. The host prepends the precision header (`real`,
// `bad`).
//
// Gather only: thread c writes cell c of the new fields from the old ones (two buffers, swapped
// each step by the host's bind groups). The books' reaction sums are reduced in each workgroup
// in one fixed tree order and added to that workgroup's own slot: no atomics on floats, so a run
// repeats bit for bit on one adapter. The one atomic is an integer min over the index of the
// first non-finite cell.

struct Params {
    nx: u32,
    ny: u32,
    nz: u32,
    // Bit f set: face f (x-, x+, y-, y+, z-, z+) is free (∂u/∂n = 0: the ghost is the cell
    // itself); clear: periodic (the ghost is the opposite cell).
    free: u32,
    // Workgroups along x (segments of a row) and along y (rows; row r = y + gy·z).
    gx: u32,
    three: u32,
    gy: u32,
    pad1: u32,
    // dt·D_u/dx², dt·D_v/dx², dt, F, F + k, and 2·dim (the Laplacian's centre weight).
    du: real,
    dv: real,
    dt: real,
    f: real,
    fk: real,
    centre: real,
    pad2: real,
    pad3: real,
};

const WG: u32 = 64u;

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> u0: array<real>;
@group(0) @binding(2) var<storage, read> v0: array<real>;
@group(0) @binding(3) var<storage, read_write> u1: array<real>;
@group(0) @binding(4) var<storage, read_write> v1: array<real>;
// Two per workgroup: what the reactions made of u and of v so far, Σ_steps dt Σ_cells (per
// unit cell measure; the host multiplies by dx^dim).
@group(0) @binding(5) var<storage, read_write> made: array<real>;
// [0]: the smallest index of a cell whose u or v is not finite (or 0xffffffff).
@group(0) @binding(6) var<storage, read_write> flag: array<atomic<u32>>;

var<workgroup> su: array<real, WG>;
var<workgroup> sv: array<real, WG>;

// The neighbour of index i (of n) one step back / forward along an axis whose faces are free
// (bits lo, hi of P.free) or periodic.
fn back(i: u32, n: u32, lo: u32) -> u32 {
    if (i > 0u) {
        return i - 1u;
    }
    if ((P.free & (1u << lo)) != 0u) {
        return i;
    }
    return n - 1u;
}

fn fwd(i: u32, n: u32, hi: u32) -> u32 {
    if (i + 1u < n) {
        return i + 1u;
    }
    if ((P.free & (1u << hi)) != 0u) {
        return i;
    }
    return 0u;
}

// The workgroup's row (j + ny·k; ny·nz of them): one workgroup per segment of SPAN cells of a
// row, so that no thread divides (the row's j and k are uniform).
fn row_of(wid: vec3<u32>) -> u32 {
    return wid.y + P.gy * wid.z;
}

// Each thread updates CPT cells of its row, WG apart (each pass of the workgroup reads WG
// consecutive cells), and sums their reactions in that order before the workgroup's tree: the
// books' reduction (six barriers) runs once per SPAN cells, not once per WG.
const CPT: u32 = 4u;
const SPAN: u32 = WG * CPT;

@compute @workgroup_size(WG)
fn step(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let rr = row_of(wid);
    let nxy = P.nx * P.ny;
    var ru: real = 0.0;
    var rv: real = 0.0;
    if (rr < P.ny * P.nz) {
        let j = rr % P.ny;
        let k = rr / P.ny;
        let row = rr * P.nx;
        // The rows (and planes) either side: the same for every cell of the row.
        let south = back(j, P.ny, 2u) * P.nx + k * nxy;
        let north = fwd(j, P.ny, 3u) * P.nx + k * nxy;
        let down = j * P.nx + back(k, P.nz, 4u) * nxy;
        let up = j * P.nx + fwd(k, P.nz, 5u) * nxy;
        for (var m = 0u; m < CPT; m = m + 1u) {
            let i = wid.x * SPAN + m * WG + lid.x;
            if (i < P.nx) {
                let c = row + i;
                let l = row + back(i, P.nx, 0u);
                let r = row + fwd(i, P.nx, 1u);
                let s = south + i;
                let t = north + i;
                let uc = u0[c];
                let vc = v0[c];
                // The CPU's order of operations (grids::gray_scott, `Stencil`).
                var lu = u0[l] + u0[r] + u0[s] + u0[t] - P.centre * uc;
                var lv = v0[l] + v0[r] + v0[s] + v0[t] - P.centre * vc;
                if (P.three != 0u) {
                    lu = lu + (u0[down + i] + u0[up + i]);
                    lv = lv + (v0[down + i] + v0[up + i]);
                }
                let uvv = uc * vc * vc;
                let cu = P.f * (1.0 - uc) - uvv;
                let cv = uvv - P.fk * vc;
                u1[c] = uc + P.du * lu + P.dt * cu;
                v1[c] = vc + P.dv * lv + P.dt * cv;
                ru = ru + cu;
                rv = rv + cv;
            }
        }
    }
    // The workgroup's reaction sums, in one fixed tree order.
    su[lid.x] = ru;
    sv[lid.x] = rv;
    workgroupBarrier();
    for (var w = WG / 2u; w > 0u; w = w / 2u) {
        if (lid.x < w) {
            su[lid.x] = su[lid.x] + su[lid.x + w];
            sv[lid.x] = sv[lid.x] + sv[lid.x + w];
        }
        workgroupBarrier();
    }
    if (lid.x == 0u) {
        let g = wid.x + P.gx * rr;
        made[2u * g] = made[2u * g] + P.dt * su[0];
        made[2u * g + 1u] = made[2u * g + 1u] + P.dt * sv[0];
    }
}

@compute @workgroup_size(WG)
fn check(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let rr = row_of(wid);
    if (rr >= P.ny * P.nz) {
        return;
    }
    for (var m = 0u; m < CPT; m = m + 1u) {
        let i = wid.x * SPAN + m * WG + lid.x;
        let c = rr * P.nx + i;
        if (i < P.nx && (bad(u0[c]) || bad(v0[c]))) {
            atomicMin(&flag[0], c);
        }
    }
}
