// What the passes over the cell list share (appended to sph.wgsl, dfsph.wgsl and dem.wgsl,
// whose parameter blocks hold the cells along x and y, `cx`, `cy`, and which define `WG`).

// The thread's item of a dispatch spread over x and y (`cells::spread`).
fn index(g: vec3<u32>) -> u32 {
    return g.x + 65535u * WG * g.y;
}

// The cell coordinates of a flat cell index (cells.wgsl's `flat`, inverted).
fn coords(c: u32) -> vec3<u32> {
    return vec3<u32>(c % P.cx, (c / P.cx) % P.cy, c / (P.cx * P.cy));
}

fn flat(c: vec3<u32>) -> u32 {
    return c.x + P.cx * (c.y + P.cy * c.z);
}

// The range of cells around coordinate c along an axis of m cells.
fn lo_of(c: u32) -> u32 {
    return max(c, 1u) - 1u;
}

fn hi_of(c: u32, m: u32) -> u32 {
    return min(c + 1u, m - 1u);
}
