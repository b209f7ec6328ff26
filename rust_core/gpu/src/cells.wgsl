// A cell list on the device (issue "GPU fluids, grains and batches": the neighbour search):
// particles binned into the cells of a box by a counting sort (u32 atomics for the counts, a
// prefix scan in three dispatches, an atomic scatter), then each cell's particles put in index order,
// so that the order (and every sum gathered over it) is the same on every run: the scatter's
// atomics decide only the order before that sort. The host prepends the precision header.

struct Params {
    // Particles, dimension, cells along x, y, z (z = 1 in 2D).
    n: u32,
    dim: u32,
    cx: u32,
    cy: u32,
    cz: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
    // The box's lower corner and the cell size (≥ the interaction radius), and that radius.
    lo_x: real,
    lo_y: real,
    lo_z: real,
    cell: real,
    radius: real,
};

const WG: u32 = 64u;
const RW: u32 = 256u;

@group(0) @binding(0) var<uniform> P: Params;
// Positions, `dim` per particle.
@group(0) @binding(1) var<storage, read> pos: array<real>;
// Each particle's cell.
@group(0) @binding(2) var<storage, read_write> cell_of: array<u32>;
// Per cell: its count (then its scatter cursor).
@group(0) @binding(3) var<storage, read_write> counts: array<atomic<u32>>;
// Per cell c: the first slot of its particles in `order` (start[cells] = n).
@group(0) @binding(4) var<storage, read_write> start: array<u32>;
// The particles by cell, each cell's in index order.
@group(0) @binding(5) var<storage, read_write> order: array<u32>;
// Per particle: its neighbours within the radius (itself left out): the gather's check.
@group(0) @binding(6) var<storage, read_write> found: array<u32>;
// The scan's block totals, then their exclusive prefix sums (one per BLOCK cells).
@group(0) @binding(7) var<storage, read_write> blocks_sum: array<u32>;

fn cells() -> u32 {
    return P.cx * P.cy * P.cz;
}

// The cell coordinate along an axis of `m` cells, clamped into the box.
fn axis(x: real, lo: real, m: u32) -> u32 {
    let f = (x - lo) / P.cell;
    if (!(f > 0.0)) {
        return 0u;
    }
    return min(u32(f), m - 1u);
}

fn coords(i: u32) -> vec3<u32> {
    let d = P.dim;
    let x = axis(pos[d * i], P.lo_x, P.cx);
    let y = axis(pos[d * i + 1u], P.lo_y, P.cy);
    var z = 0u;
    if (d == 3u) {
        z = axis(pos[d * i + 2u], P.lo_z, P.cz);
    }
    return vec3<u32>(x, y, z);
}

fn flat(c: vec3<u32>) -> u32 {
    return c.x + P.cx * (c.y + P.cy * c.z);
}

fn index(g: vec3<u32>) -> u32 {
    return g.x + 65535u * WG * g.y;
}

@compute @workgroup_size(WG)
fn clear(@builtin(global_invocation_id) g: vec3<u32>) {
    let c = index(g);
    if (c < cells()) {
        atomicStore(&counts[c], 0u);
    }
}

@compute @workgroup_size(WG)
fn bin(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = index(g);
    if (i < P.n) {
        let c = flat(coords(i));
        cell_of[i] = c;
        atomicAdd(&counts[c], 1u);
    }
}

var<workgroup> sums: array<u32, RW>;

// The prefix scan of the counts in three dispatches (reduce, scan of the block totals, apply),
// all in u32 (exact, so the same whatever the order): block b holds the BLOCK cells from
// b·BLOCK, thread t of its workgroup the CHUNK cells from b·BLOCK + t·CHUNK. One workgroup
// scanning every cell alone (as before) left 256 threads to walk millions of cells: 8.4 of the
// 11.7 ms of a 4M-particle WCSPH step on an H200 (2.5M cells; docs/guide/gpu.md).
const CHUNK: u32 = 4u;
const BLOCK: u32 = RW * CHUNK;

fn blocks() -> u32 {
    return (cells() + BLOCK - 1u) / BLOCK;
}

// A block's index from its workgroup id, folded into y past 65,535 blocks (`cells::scan_groups`).
fn block_of(w: vec3<u32>) -> u32 {
    return w.x + 65535u * w.y;
}

// Thread t's cells of block b: [a, e), clamped to the grid.
fn chunk_of(b: u32, t: u32) -> vec2<u32> {
    let m = cells();
    let a = min(b * BLOCK + t * CHUNK, m);
    return vec2<u32>(a, min(a + CHUNK, m));
}

// The counts of cells [r.x, r.y).
fn chunk_total(r: vec2<u32>) -> u32 {
    var s = 0u;
    for (var c = r.x; c < r.y; c = c + 1u) {
        s = s + atomicLoad(&counts[c]);
    }
    return s;
}

// sums[t] becomes the inclusive prefix sum over the workgroup (Hillis–Steele); every thread
// takes part (the barriers are in uniform control flow).
fn scan_sums(t: u32) {
    for (var w = 1u; w < RW; w = w * 2u) {
        var v = 0u;
        if (t >= w) {
            v = sums[t - w];
        }
        workgroupBarrier();
        sums[t] = sums[t] + v;
        workgroupBarrier();
    }
}

// 1. Each block's total into `blocks_sum[b]` (the last of its threads' prefix sums).
@compute @workgroup_size(RW)
fn scan_blocks(@builtin(local_invocation_id) l: vec3<u32>, @builtin(workgroup_id) w: vec3<u32>) {
    let b = block_of(w);
    if (b >= blocks()) {
        return;
    }
    sums[l.x] = chunk_total(chunk_of(b, l.x));
    workgroupBarrier();
    scan_sums(l.x);
    if (l.x == RW - 1u) {
        blocks_sum[b] = sums[RW - 1u];
    }
}

// 2. One workgroup: the block totals become their exclusive prefix sums (thread t a contiguous
// run of them), and start[cells] the particle count.
@compute @workgroup_size(RW)
fn scan_tops(@builtin(local_invocation_id) l: vec3<u32>) {
    let nb = blocks();
    let run_len = (nb + RW - 1u) / RW;
    let a = min(l.x * run_len, nb);
    let b = min(a + run_len, nb);
    var s = 0u;
    for (var k = a; k < b; k = k + 1u) {
        s = s + blocks_sum[k];
    }
    sums[l.x] = s;
    workgroupBarrier();
    scan_sums(l.x);
    var run = sums[l.x] - s;
    for (var k = a; k < b; k = k + 1u) {
        let v = blocks_sum[k];
        blocks_sum[k] = run;
        run = run + v;
    }
    if (l.x == RW - 1u) {
        start[cells()] = sums[RW - 1u];
    }
}

// 3. Each cell's start (its block's offset plus the prefix within the block), and each count
// becomes its cell's scatter cursor (its start).
@compute @workgroup_size(RW)
fn scan_apply(@builtin(local_invocation_id) l: vec3<u32>, @builtin(workgroup_id) w: vec3<u32>) {
    let b = block_of(w);
    if (b >= blocks()) {
        return;
    }
    let r = chunk_of(b, l.x);
    let s = chunk_total(r);
    sums[l.x] = s;
    workgroupBarrier();
    scan_sums(l.x);
    var run = blocks_sum[b] + sums[l.x] - s;
    for (var c = r.x; c < r.y; c = c + 1u) {
        let k = atomicLoad(&counts[c]);
        start[c] = run;
        atomicStore(&counts[c], run);
        run = run + k;
    }
}

@compute @workgroup_size(WG)
fn scatter(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = index(g);
    if (i < P.n) {
        order[atomicAdd(&counts[cell_of[i]], 1u)] = i;
    }
}

// Each cell's particles in index order (insertion sort: a cell holds a few).
@compute @workgroup_size(WG)
fn sort_cells(@builtin(global_invocation_id) g: vec3<u32>) {
    let c = index(g);
    if (c >= cells()) {
        return;
    }
    let a = start[c];
    let b = start[c + 1u];
    for (var k = a + 1u; k < b; k = k + 1u) {
        let v = order[k];
        var j = k;
        while (j > a && order[j - 1u] > v) {
            order[j] = order[j - 1u];
            j = j - 1u;
        }
        order[j] = v;
    }
}

// Particle i's neighbours within the radius, gathered over the 3^d cells around its own in a
// fixed order (z, y, x, then each cell's particles by index; a row's three cells along x are
// consecutive in `order`: one run of slots).
@compute @workgroup_size(WG)
fn neighbours(@builtin(global_invocation_id) g: vec3<u32>) {
    let i = index(g);
    if (i >= P.n) {
        return;
    }
    let d = P.dim;
    let c = coords(i);
    let r2 = P.radius * P.radius;
    var k = 0u;
    var z0 = 0u;
    var z1 = 0u;
    if (d == 3u) {
        z0 = max(c.z, 1u) - 1u;
        z1 = min(c.z + 1u, P.cz - 1u);
    }
    for (var z = z0; z <= z1; z = z + 1u) {
        for (var y = max(c.y, 1u) - 1u; y <= min(c.y + 1u, P.cy - 1u); y = y + 1u) {
            let row = flat(vec3<u32>(0u, y, z));
            for (var s = start[row + max(c.x, 1u) - 1u]; s < start[row + min(c.x + 1u, P.cx - 1u) + 1u]; s = s + 1u) {
                let j = order[s];
                var q: real = 0.0;
                for (var a = 0u; a < d; a = a + 1u) {
                    let e = pos[d * j + a] - pos[d * i + a];
                    q = q + e * e;
                }
                if (j != i && q < r2) {
                    k = k + 1u;
                }
            }
        }
    }
    found[i] = k;
}
