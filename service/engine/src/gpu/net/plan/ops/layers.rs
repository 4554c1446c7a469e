//! The layers with weights or windows: convolution (batch-norm folded in), pooling, Gemm /
//! MatMul, resize; and batch-norm's per-channel affine.

use super::{Act, broadcast, input};
use crate::gpu::net::plan::{Attrs, ConvKernels, Kernel, Planner, Val, numel};
use tract_onnx::pb::NodeProto;

/// Batch-norm's per-channel (scale, shift): y = x scale + shift.
pub(super) fn bn_affine(pl: &Planner, n: &NodeProto) -> Result<(Vec<f32>, Vec<f32>), String> {
    let eps = Attrs(&n.attribute).float("epsilon", 1e-5);
    let get = |i: usize| -> Result<Vec<f32>, String> {
        Ok(pl
            .konst(n.input.get(i).map(|s| s.as_str()).unwrap_or(""))?
            .1
            .floats())
    };
    let (g, b, m, v) = (get(1)?, get(2)?, get(3)?, get(4)?);
    let scale: Vec<f32> = g
        .iter()
        .zip(&v)
        .map(|(g, v)| g / (v + eps).sqrt())
        .collect();
    let shift: Vec<f32> = b
        .iter()
        .zip(&m)
        .zip(&scale)
        .map(|((b, m), s)| b - m * s)
        .collect();
    Ok((scale, shift))
}

/// (pad_top, pad_left) and the output side for one spatial axis.
fn conv_pads(
    a: &Attrs,
    shape_in: [usize; 2],
    k: [usize; 2],
    s: [usize; 2],
    d: [usize; 2],
    transpose: bool,
) -> Result<([usize; 2], [usize; 2]), String> {
    let auto = a.string("auto_pad", "NOTSET");
    let pads = a.ints("pads").unwrap_or_else(|| vec![0; 4]);
    if pads.len() != 4 || pads.iter().any(|&p| p < 0) {
        return Err(format!("pads {pads:?}"));
    }
    if !matches!(auto.as_str(), "NOTSET" | "VALID")
        || (auto == "VALID" && pads.iter().any(|&p| p != 0))
    {
        return Err(format!("auto_pad {auto:?} (NOTSET or VALID)"));
    }
    let outp = a.ints("output_padding").unwrap_or_else(|| vec![0, 0]);
    if transpose && a.get("output_shape").is_some() {
        return Err("ConvTranspose with output_shape (give pads)".into());
    }
    let mut o = [0usize; 2];
    for i in 0..2 {
        let span = d[i] * (k[i] - 1) + 1;
        let (b, e) = (pads[i] as usize, pads[i + 2] as usize);
        o[i] = if transpose {
            ((shape_in[i] - 1) * s[i] + span + *outp.get(i).unwrap_or(&0) as usize)
                .checked_sub(b + e)
                .ok_or("negative output")?
        } else {
            let full = shape_in[i] + b + e;
            if full < span {
                return Err(format!("kernel {k:?} larger than the padded input"));
            }
            (full - span) / s[i] + 1
        };
    }
    Ok(([pads[0] as usize, pads[1] as usize], o))
}

pub(super) fn conv(
    pl: &mut Planner,
    n: &NodeProto,
    out: &str,
    act: Act,
    bn: Option<&NodeProto>,
) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let transpose = n.op_type == "ConvTranspose";
    let x = n.input.first().map(|s| s.as_str()).unwrap_or("");
    let (b, shape) = pl.dev(x)?;
    let (wshape, w) = pl.konst(n.input.get(1).map(|s| s.as_str()).unwrap_or(""))?;
    if shape.len() != 4 || wshape.len() != 4 {
        return Err(pl.err(format!(
            "{} of input {shape:?}, weights {wshape:?} (2-D, NCHW)",
            n.op_type
        )));
    }
    let group = a.int("group", 1).max(1) as usize;
    let (nb, c, h, wd) = (shape[0], shape[1], shape[2], shape[3]);
    let m = if transpose {
        wshape[1] * group
    } else {
        wshape[0]
    };
    let cin_w = if transpose {
        wshape[0]
    } else {
        wshape[1] * group
    };
    if cin_w != c || c % group != 0 || m % group != 0 {
        return Err(pl.err(format!(
            "weights {wshape:?} for {c} input channels in {group} groups"
        )));
    }
    let two = |name: &str| -> [usize; 2] {
        let v = a.ints(name).unwrap_or_else(|| vec![1, 1]);
        [
            v.first().copied().unwrap_or(1).max(1) as usize,
            v.get(1).copied().unwrap_or(1).max(1) as usize,
        ]
    };
    let (s, d) = (two("strides"), two("dilations"));
    let k = [wshape[2], wshape[3]];
    let (pt, o) = conv_pads(&a, [h, wd], k, s, d, transpose).map_err(|e| pl.err(e))?;
    let mut w = w.floats();
    let mut bias = match n.input.get(2).filter(|s| !s.is_empty()) {
        Some(name) => pl.konst(name)?.1.floats(),
        None => vec![0.0; m],
    };
    if let Some(bn) = bn {
        // Folded at load: W' = W scale[m], b' = b scale[m] + shift[m].
        let (scale, shift) = bn_affine(pl, bn)?;
        let per = w.len() / m;
        for (i, v) in w.iter_mut().enumerate() {
            *v *= scale[i / per];
        }
        for (j, v) in bias.iter_mut().enumerate() {
            *v = *v * scale[j] + shift[j];
        }
    }
    // Ungrouped with at least 4 outputs: four channels per invocation (a count that is not
    // a multiple of 4 padded with zero channels, which the kernel computes and does not
    // write: 31 Fourier coefficients cost 32 channels' work, against reading every input
    // once per channel in `conv`). Under 4 outputs (a mask's 1 or 2) `conv`, which computes
    // no padding.
    let blocked = !transpose && group == 1 && m >= 4;
    if blocked && m % 4 != 0 {
        let padded = m.div_ceil(4) * 4;
        w.resize(padded * (w.len() / m), 0.0);
        bias.resize(padded, 0.0);
    }
    // Rows of at least 8 columns: four channels by four columns per invocation
    // (`conv_row.wgsl`). Layers with few blocks of work and long sums: a workgroup per block
    // of four channels at a pixel (`conv_split.wgsl`). Both take the weights regrouped so that
    // each tap's four channels are one vector.
    let row_blocks = nb * m.div_ceil(4) * o[0] * o[1].div_ceil(4);
    let pixel_blocks = nb * m.div_ceil(4) * o[0] * o[1];
    let rows = o[1] >= ROW_MIN_COLUMNS;
    let kernel = match pl.conv_kernels {
        _ if transpose => Kernel::ConvTranspose,
        _ if !blocked => Kernel::Conv,
        ConvKernels::Conv4 => Kernel::Conv4,
        ConvKernels::Split
            if (if rows { row_blocks } else { pixel_blocks }) < SPLIT_BELOW_BLOCKS
                && c * k[0] * k[1] >= SPLIT_MIN_TERMS =>
        {
            Kernel::ConvSplit
        }
        _ if rows => Kernel::ConvRow,
        _ => Kernel::Conv4,
    };
    if matches!(kernel, Kernel::ConvRow | Kernel::ConvSplit) {
        w = block_weights(&w, m.div_ceil(4) * 4);
    }
    let wb = pl.upload(w);
    let bb = pl.upload(bias);
    let oshape = vec![nb, m, o[0], o[1]];
    let ob = pl.alloc(numel(&oshape));
    let dims = [
        nb, c, h, wd, m, o[0], o[1], k[0], k[1], s[0], s[1], pt[0], pt[1], d[0], d[1], group,
    ];
    let count = match kernel {
        Kernel::ConvRow => row_blocks,
        Kernel::ConvSplit => pixel_blocks * 64,
        Kernel::Conv4 => pixel_blocks,
        _ => numel(&oshape),
    };
    let mut p = vec![count as u32];
    p.extend(dims.iter().map(|&v| v as u32));
    p.extend([act.0, act.1.to_bits(), act.2.to_bits()]);
    pl.step(kernel, p, vec![b, wb, bb, ob]);
    pl.define_dev(out, ob, oshape);
    Ok(())
}

/// Output columns from which an ungrouped convolution runs four columns per invocation
/// (`conv_row.wgsl`); narrower planes (the squeeze-excitation's 1 x 1) keep `conv4`.
const ROW_MIN_COLUMNS: usize = 8;

/// Blocks (invocations of `conv_row` or `conv4`) under which a convolution whose sums have
/// [`SPLIT_MIN_TERMS`] terms or more splits each block's sum over a workgroup
/// (`conv_split.wgsl`): 4,096 invocations are 64 workgroups, half the multiprocessors of a
/// large GPU (an H200 has 132), each invocation adding its terms one after another.
const SPLIT_BELOW_BLOCKS: usize = 4096;
/// Terms of a block's sum (input channels x taps) from which the split pays: a workgroup's
/// 64 invocations each one term or more.
const SPLIT_MIN_TERMS: usize = 64;

/// Weights `[M4, C, KH, KW]` (M4 a multiple of 4) regrouped as `[M4 / 4, C, KH, KW, 4]`:
/// a block's four output channels side by side at each input channel and tap.
fn block_weights(w: &[f32], m4: usize) -> Vec<f32> {
    let per = w.len() / m4;
    let mut out = vec![0.0; w.len()];
    for (i, &v) in w.iter().enumerate() {
        let (m, t) = (i / per, i % per);
        out[((m / 4) * per + t) * 4 + m % 4] = v;
    }
    out
}

pub(super) fn pool(pl: &mut Planner, n: &NodeProto, out: &str) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let x = n.input.first().map(|s| s.as_str()).unwrap_or("");
    let (b, shape) = pl.dev(x)?;
    if shape.len() != 4 {
        return Err(pl.err(format!("{} of {shape:?} (2-D, NCHW)", n.op_type)));
    }
    let (h, w) = (shape[2], shape[3]);
    let global = n.op_type.starts_with("Global");
    let max = n.op_type.ends_with("MaxPool");
    let (k, s, pads) = if global {
        ([h, w], [1, 1], vec![0; 4])
    } else {
        let ks = a
            .ints("kernel_shape")
            .ok_or_else(|| pl.err("pool without kernel_shape"))?;
        let st = a.ints("strides").unwrap_or_else(|| vec![1, 1]);
        if ks.len() != 2 || st.len() != 2 {
            return Err(pl.err("pooling over other than 2 axes"));
        }
        if a.ints("dilations")
            .is_some_and(|d| d.iter().any(|&v| v != 1))
            || a.string("auto_pad", "NOTSET") != "NOTSET"
        {
            return Err(pl.err("dilated or auto-padded pooling"));
        }
        (
            [ks[0] as usize, ks[1] as usize],
            [st[0].max(1) as usize, st[1].max(1) as usize],
            a.ints("pads").unwrap_or_else(|| vec![0; 4]),
        )
    };
    let ceil = a.int("ceil_mode", 0) == 1;
    let mut o = [0usize; 2];
    for i in 0..2 {
        let full = [h, w][i] + (pads[i] + pads[i + 2]).max(0) as usize;
        if full < k[i] {
            return Err(pl.err(format!("window {k:?} larger than the padded input")));
        }
        let q = full - k[i];
        o[i] = if ceil { q.div_ceil(s[i]) } else { q / s[i] } + 1;
    }
    let oshape = vec![shape[0], shape[1], o[0], o[1]];
    let ob = pl.alloc(numel(&oshape));
    if o == [1, 1] && k == [h, w] && pads.iter().all(|&v| v == 0) {
        // The window is the plane: one workgroup per plane (pool_plane.wgsl).
        let planes = shape[0] * shape[1];
        pl.step(
            Kernel::PoolPlane,
            [planes * 64, planes, h * w, max as usize]
                .iter()
                .map(|&v| v as u32)
                .collect(),
            vec![b, ob],
        );
        pl.define_dev(out, ob, oshape);
        return Ok(());
    }
    let p = [
        numel(&oshape),
        shape[0] * shape[1],
        h,
        w,
        o[0],
        o[1],
        k[0],
        k[1],
        s[0],
        s[1],
        pads[0] as usize,
        pads[1] as usize,
        max as usize,
        a.int("count_include_pad", 0) as usize,
    ];
    pl.step(
        Kernel::Pool,
        p.iter().map(|&v| v as u32).collect(),
        vec![b, ob],
    );
    pl.define_dev(out, ob, oshape);
    Ok(())
}

pub(super) fn gemm(pl: &mut Planner, n: &NodeProto, out: &str, act: Act) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let inp = |i: usize| input(n, i);
    let (ba, sa) = pl.dev(inp(0).unwrap_or(""))?;
    // B's buffer only for the general kernel (gemm4 uploads its own layout of a constant).
    let sb = pl.get(inp(1).unwrap_or(""))?.shape().to_vec();
    let gemm = n.op_type == "Gemm";
    let (ta, tb) = if gemm {
        (a.int("transA", 0) == 1, a.int("transB", 0) == 1)
    } else {
        (false, false)
    };
    if sa.len() != 2 || sb.len() != 2 {
        return Err(pl.err(format!("{} of {sa:?} and {sb:?} (2-D only)", n.op_type)));
    }
    let (m, k) = if ta { (sa[1], sa[0]) } else { (sa[0], sa[1]) };
    let (k2, nn) = if tb { (sb[1], sb[0]) } else { (sb[0], sb[1]) };
    if k != k2 {
        return Err(pl.err(format!("inner sizes {k} and {k2} differ")));
    }
    let (alpha, beta) = if gemm {
        (a.float("alpha", 1.0), a.float("beta", 1.0))
    } else {
        (1.0, 0.0)
    };
    // A constant weight (every MLP layer): transposed and padded at plan time for the
    // four-outputs-a-row kernel, alpha and beta folded, when C is absent or a constant bias
    // row.
    if !ta
        && nn >= 4
        && let Some(w4) = weights4(pl, inp(1), tb, k, nn, alpha)?
        && let Some(bias) = bias4(pl, inp(2).filter(|_| gemm), nn, beta)?
    {
        let wb = pl.upload(w4);
        let biasb = pl.upload(bias);
        let ob = pl.alloc(m * nn);
        let p = vec![
            (m * nn.div_ceil(4)) as u32,
            m as u32,
            nn as u32,
            k as u32,
            act.0,
            act.1.to_bits(),
            act.2.to_bits(),
        ];
        pl.step(Kernel::Gemm4, p, vec![ba, wb, biasb, ob]);
        pl.define_dev(out, ob, vec![m, nn]);
        return Ok(());
    }
    let (bb, _) = pl.dev(inp(1).unwrap_or(""))?;
    let (cb, crs, ccs, has_c) = match inp(2).filter(|_| gemm) {
        Some(c) => {
            let (cb, sc) = pl.dev(c)?;
            // C's strides in the [M, N] output (0 on a broadcast axis).
            let st = broadcast(&[m, nn], &sc)
                .filter(|(o, _, _)| o[..] == [m, nn])
                .map(|(_, _, s)| s)
                .ok_or_else(|| pl.err(format!("C {sc:?} for [{m}, {nn}]")))?;
            (cb, st[0] as u32, st[1] as u32, 1)
        }
        None => (ba, 0, 0, 0),
    };
    let ob = pl.alloc(m * nn);
    let p = vec![
        (m * nn) as u32,
        m as u32,
        nn as u32,
        k as u32,
        ta as u32,
        tb as u32,
        alpha.to_bits(),
        beta.to_bits(),
        crs,
        ccs,
        has_c,
        act.0,
        act.1.to_bits(),
        act.2.to_bits(),
    ];
    pl.step(Kernel::Gemm, p, vec![ba, bb, cb, ob]);
    pl.define_dev(out, ob, vec![m, nn]);
    Ok(())
}

/// A constant Gemm/MatMul weight as the `gemm4` kernel reads it: `[K, N4]` (column `j` of
/// the output at inner index `k` at `k N4 + j`), times `alpha`, the columns from N to
/// N4 = 4 ceil(N / 4) zero; `None` when the weight is computed on the device.
fn weights4(
    pl: &Planner,
    name: Option<&str>,
    tb: bool,
    k: usize,
    nn: usize,
    alpha: f32,
) -> Result<Option<Vec<f32>>, String> {
    let Some(name) = name else { return Ok(None) };
    let Some(Val::Const { data, .. }) = pl.vals.get(name) else {
        return Ok(None);
    };
    let w = data.floats();
    if w.len() != k * nn {
        return Err(pl.err(format!("weight of {} values for [{k}, {nn}]", w.len())));
    }
    let n4 = nn.div_ceil(4) * 4;
    let mut out = vec![0.0f32; k * n4];
    for kk in 0..k {
        for j in 0..nn {
            let v = if tb { w[j * k + kk] } else { w[kk * nn + j] };
            out[kk * n4 + j] = alpha * v;
        }
    }
    Ok(Some(out))
}

/// A Gemm's C as `gemm4`'s bias (`beta C`, padded like the weight's columns): absent, a
/// constant `[N]` or `[1, N]` row, or a scalar; `None` for a C that varies per row or is
/// computed on the device (the general kernel takes those).
fn bias4(
    pl: &Planner,
    name: Option<&str>,
    nn: usize,
    beta: f32,
) -> Result<Option<Vec<f32>>, String> {
    let n4 = nn.div_ceil(4) * 4;
    let Some(name) = name else {
        return Ok(Some(vec![0.0; n4]));
    };
    let Some(Val::Const { shape, data }) = pl.vals.get(name) else {
        return Ok(None);
    };
    let c = data.floats();
    let row: Vec<f32> = match (shape.as_slice(), c.len()) {
        ([], 1) | ([1], 1) | ([1, 1], 1) => vec![c[0]; nn],
        ([n], _) | ([1, n], _) if *n == nn => c,
        _ => return Ok(None),
    };
    let mut out = vec![0.0f32; n4];
    for (o, v) in out.iter_mut().zip(row) {
        *o = beta * v;
    }
    Ok(Some(out))
}

pub(super) fn resize(pl: &mut Planner, n: &NodeProto, out: &str) -> Result<(), String> {
    let a = Attrs(&n.attribute);
    let inp = |i: usize| input(n, i);
    let (b, shape) = pl.dev(inp(0).unwrap_or(""))?;
    if shape.len() != 4 {
        return Err(pl.err(format!("Resize of {shape:?} (NCHW)")));
    }
    let scales = match inp(2) {
        Some(s) => pl.konst(s)?.1.floats(),
        None => vec![],
    };
    let sizes = match inp(3) {
        Some(s) => pl.konst(s)?.1.ints(),
        None => vec![],
    };
    let (oh, ow, sh, sw) = if sizes.len() == 4 {
        let (oh, ow) = (sizes[2] as usize, sizes[3] as usize);
        if sizes[0] as usize != shape[0] || sizes[1] as usize != shape[1] {
            return Err(pl.err("Resize of N or C"));
        }
        (
            oh,
            ow,
            oh as f32 / shape[2] as f32,
            ow as f32 / shape[3] as f32,
        )
    } else if scales.len() == 4 {
        if scales[0] != 1.0 || scales[1] != 1.0 {
            return Err(pl.err("Resize of N or C"));
        }
        (
            (shape[2] as f32 * scales[2]).floor() as usize,
            (shape[3] as f32 * scales[3]).floor() as usize,
            scales[2],
            scales[3],
        )
    } else {
        return Err(pl.err("Resize without 4 scales or sizes"));
    };
    let mode = match a.string("mode", "nearest").as_str() {
        "nearest" => 0,
        "linear" => 1,
        other => return Err(pl.err(format!("Resize mode {other:?}"))),
    };
    let ctm = match a
        .string("coordinate_transformation_mode", "half_pixel")
        .as_str()
    {
        "half_pixel" => 0,
        "align_corners" => 1,
        "asymmetric" => 2,
        "pytorch_half_pixel" => 3,
        other => return Err(pl.err(format!("Resize coordinate_transformation_mode {other:?}"))),
    };
    let near = match a.string("nearest_mode", "round_prefer_floor").as_str() {
        "round_prefer_floor" => 0,
        "round_prefer_ceil" => 1,
        "floor" => 2,
        "ceil" => 3,
        other => return Err(pl.err(format!("Resize nearest_mode {other:?}"))),
    };
    resize_step(pl, b, &shape, [oh, ow], [mode, ctm, near], [sh, sw], out);
    Ok(())
}

/// The `Resize` kernel's step: `shape` [N, C, H, W] in buffer `b` to [N, C, OH, OW].
fn resize_step(
    pl: &mut Planner,
    b: usize,
    shape: &[usize],
    [oh, ow]: [usize; 2],
    [mode, ctm, near]: [u32; 3],
    [sh, sw]: [f32; 2],
    out: &str,
) {
    let oshape = vec![shape[0], shape[1], oh, ow];
    let ob = pl.alloc(numel(&oshape));
    let p = vec![
        numel(&oshape) as u32,
        (shape[0] * shape[1]) as u32,
        shape[2] as u32,
        shape[3] as u32,
        oh as u32,
        ow as u32,
        mode,
        ctm,
        near,
        sh.to_bits(),
        sw.to_bits(),
    ];
    pl.step(Kernel::Resize, p, vec![b, ob]);
    pl.define_dev(out, ob, oshape);
}

/// Bilinear x2 upsampling with half-pixel centres (what export's shifted sums compute,
/// `plan::shifts`) of the 4-D value `x` into `out`.
pub(in crate::gpu::net::plan) fn bilinear_x2(
    pl: &mut Planner,
    x: &str,
    out: &str,
) -> Result<(), String> {
    let (b, shape) = pl.dev(x)?;
    if shape.len() != 4 {
        return Err(pl.err(format!("upsampling of {shape:?} (NCHW)")));
    }
    let o = [shape[2] * 2, shape[3] * 2];
    resize_step(pl, b, &shape, o, [1, 0, 0], [2.0, 2.0], out);
    Ok(())
}
