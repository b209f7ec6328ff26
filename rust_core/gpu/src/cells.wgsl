// A cell list on the device (issue "GPU fluids, grains and batches": the neighbour search):
// particles binned into the cells of a box by a counting sort (u32 atomics for the counts, a
// one-workgroup prefix scan, an atomic scatter), then each cell's particles put in index order,
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

// One workgroup: start = the exclusive prefix sums of the counts (thread t takes a contiguous
// chunk; the chunks' totals are scanned in the workgroup), and each count becomes its cell's
// scatter cursor (its start).
@compute @workgroup_size(RW)
fn scan(@builtin(local_invocation_id) l: vec3<u32>) {
    let m = cells();
    let chunk = (m + RW - 1u) / RW;
    let a = min(l.x * chunk, m);
    let b = min(a + chunk, m);
    var s = 0u;
    for (var c = a; c < b; c = c + 1u) {
        s = s + atomicLoad(&counts[c]);
    }
    sums[l.x] = s;
    workgroupBarrier();
    // Hillis–Steele, inclusive.
    for (var w = 1u; w < RW; w = w * 2u) {
        var v = 0u;
        if (l.x >= w) {
            v = sums[l.x - w];
        }
        workgroupBarrier();
        sums[l.x] = sums[l.x] + v;
        workgroupBarrier();
    }
    var run = sums[l.x] - s;
    for (var c = a; c < b; c = c + 1u) {
        let k = atomicLoad(&counts[c]);
        start[c] = run;
        atomicStore(&counts[c], run);
        run = run + k;
    }
    if (l.x == RW - 1u) {
        start[m] = sums[RW - 1u];
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
// fixed order (z, y, x, then each cell's particles by index).
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
            for (var x = max(c.x, 1u) - 1u; x <= min(c.x + 1u, P.cx - 1u); x = x + 1u) {
                let cc = flat(vec3<u32>(x, y, z));
                for (var s = start[cc]; s < start[cc + 1u]; s = s + 1u) {
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
    }
    found[i] = k;
}
