// What the stable fluid's two modules share (`fluid.wgsl`, `poisson.wgsl`): the parameter block,
// the books' scalars, the workgroups' partial sums and their fixed-order reduction. The host
// prepends the precision header (`real`, `bad`).
//
// One parameter block per dispatch (bound at a dynamic offset): the fluid grid's size, a region
// (`lw` a row's length, `lnx` × `lny` its nodes), up to eight offsets or slabs (`o0`..`o7`, each
// kernel says what they are), flags, the workgroups along x of the dispatch (`gx`: a workgroup's
// partial sum goes to slot wid.x + gx·wid.y), an id (a stage, a solver) and eight reals.
struct Params {
    nx: u32,
    ny: u32,
    lw: u32,
    lnx: u32,
    lny: u32,
    o0: u32,
    o1: u32,
    o2: u32,
    o3: u32,
    o4: u32,
    o5: u32,
    o6: u32,
    o7: u32,
    flags: u32,
    gx: u32,
    id: u32,
    r0: real,
    r1: real,
    r2: real,
    r3: real,
    r4: real,
    r5: real,
    r6: real,
    r7: real,
};

const WG: u32 = 64u;
// The one-workgroup reductions' threads.
const RW: u32 = 256u;

@group(0) @binding(0) var<uniform> P: Params;
// The books and the solvers' scalars (slots: `fluid.rs`, `Slot`).
@group(0) @binding(1) var<storage, read_write> sc: array<real>;
// One partial sum per workgroup of the dispatch before a reduction.
@group(0) @binding(2) var<storage, read_write> part: array<real>;

var<workgroup> red: array<real, RW>;

// The sum of v over a workgroup of `n` threads (a power of two, at most RW), in a fixed tree
// order; every thread gets it. Called in uniform control flow.
fn wg_sum(v: real, lid: u32, n: u32) -> real {
    red[lid] = v;
    workgroupBarrier();
    for (var w = n / 2u; w > 0u; w = w / 2u) {
        if (lid < w) {
            red[lid] = red[lid] + red[lid + w];
        }
        workgroupBarrier();
    }
    let s = red[0];
    workgroupBarrier();
    return s;
}

// Σ part[first .. first + count) by one workgroup of RW threads: thread t adds slots t, t + RW, …
// in order, then the tree. Every thread gets the sum.
fn sum_parts(first: u32, count: u32, lid: u32) -> real {
    var s: real = 0.0;
    for (var k = lid; k < count; k = k + RW) {
        s = s + part[first + k];
    }
    return wg_sum(s, lid, RW);
}

// The slot of this workgroup's partial sum.
fn slot(wid: vec3<u32>) -> u32 {
    return wid.x + P.gx * wid.y;
}

// part[at] = the sum of s over the workgroup (of WG threads). Called in uniform control flow.
fn put_part(at: u32, s: real, lid: u32) {
    let t = wg_sum(s, lid, WG);
    if (lid == 0u) {
        part[at] = t;
    }
}
