// Gray–Scott reaction–diffusion on a cell-centred grid (forward Euler, 5- or 7-point Laplacian),
// the CPU's `grids::gray_scott` cell for cell. The host prepends the precision header (`real`,
// `bad`).
//
// Gather only: each thread writes its own cells of the new fields from the old ones (two
// buffers, swapped each step by the host's bind groups). The books' reaction sums are reduced in each workgroup
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
    // Workgroups along x (segments of WG cells of a row) and along y (blocks of CPT rows; block
    // b = y + gy·z holds rows CPT·b .. CPT·b + CPT − 1).
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

// The workgroup's block of rows: rows (j + ny·k; ny·nz of them) CPT·g .. CPT·g + CPT − 1.
fn block_of(wid: vec3<u32>) -> u32 {
    return wid.y + P.gy * wid.z;
}

// A workgroup updates WG cells of a row in each of CPT consecutive rows (a thread one cell of
// each, going up the column), and each thread sums its cells' reactions in that order before
// the workgroup's tree. Two gains over one row a workgroup: the books' reduction (six
// barriers) runs once per WG·CPT cells, and the rows either side of a row are the workgroup's
// own neighbouring rows, read again from the cache (a row is fetched (CPT + 2)/CPT times, not
// 3 times). No thread divides more than once (j and k are carried up the column).
// The host sets CPT by the grid's size (4, 8 or 16: `grid::rows_for`).
const CPT: u32 = 4u;

@compute @workgroup_size(WG)
fn step(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let rows = P.ny * P.nz;
    let r0 = block_of(wid) * CPT;
    let i = wid.x * WG + lid.x;
    let nxy = P.nx * P.ny;
    var ru: real = 0.0;
    var rv: real = 0.0;
    if (i < P.nx && r0 < rows) {
        let li = back(i, P.nx, 0u);
        let ri = fwd(i, P.nx, 1u);
        var j = r0 % P.ny;
        var k = r0 / P.ny;
        for (var m = 0u; m < CPT; m = m + 1u) {
            let rr = r0 + m;
            if (rr < rows) {
                let row = rr * P.nx;
                let c = row + i;
                let s = back(j, P.ny, 2u) * P.nx + k * nxy + i;
                let t = fwd(j, P.ny, 3u) * P.nx + k * nxy + i;
                let uc = u0[c];
                let vc = v0[c];
                // The CPU's order of operations (grids::gray_scott, `Stencil`).
                var lu = u0[row + li] + u0[row + ri] + u0[s] + u0[t] - P.centre * uc;
                var lv = v0[row + li] + v0[row + ri] + v0[s] + v0[t] - P.centre * vc;
                if (P.three != 0u) {
                    let d = j * P.nx + back(k, P.nz, 4u) * nxy + i;
                    let up = j * P.nx + fwd(k, P.nz, 5u) * nxy + i;
                    lu = lu + (u0[d] + u0[up]);
                    lv = lv + (v0[d] + v0[up]);
                }
                let uvv = uc * vc * vc;
                let cu = P.f * (1.0 - uc) - uvv;
                let cv = uvv - P.fk * vc;
                u1[c] = uc + P.du * lu + P.dt * cu;
                v1[c] = vc + P.dv * lv + P.dt * cv;
                ru = ru + cu;
                rv = rv + cv;
            }
            j = j + 1u;
            if (j == P.ny) {
                j = 0u;
                k = k + 1u;
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
        let g = wid.x + P.gx * block_of(wid);
        made[2u * g] = made[2u * g] + P.dt * su[0];
        made[2u * g + 1u] = made[2u * g + 1u] + P.dt * sv[0];
    }
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
        if (rr < P.ny * P.nz && (bad(u0[c]) || bad(v0[c]))) {
            atomicMin(&flag[0], c);
        }
    }
}
