// A frame's Fourier coefficient maps out of the shape network (model/fourier.rs
// `FourierMaps::from_planar`): the network's planar output [C, n] written pixel-interleaved
// [n, C] into the frame's maps buffer, one invocation per value. A value that is not finite
// sets the flag after the maps (the buffer's float `len`, cleared before this pass): the host
// reads it and refuses the frame, and the temporal filter's passes skip a flagged frame.
// p: [len, c, n]
@group(0) @binding(0) var<storage, read> p: array<u32>;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> maps: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>) {
    let j = (wg.y * nwg.x + wg.x) * 64u + lid.x;
    let len = p[0];
    if j >= len { return; }
    let c = p[1];
    let n = p[2];
    let q = j / c;
    let v = src[(j - q * c) * n + q];
    let bits = bitcast<u32>(v);
    maps[j] = bits;
    if (bits & 0x7f800000u) == 0x7f800000u {
        maps[len] = 1u;
    }
}
