//! The paper's CBN point MLP as fused dense layers on `matrixmultiply`'s SGEMM, its weights
//! read from the same ONNX file that tract would run (the one source).
//!
//! Per batch of N points with features `F` [N, f] and depth codes `Z` [N, zdim]:
//! 1. every block's CBN scale and shift in one product: `C = F W_c + b_c` [N, 2 B H]
//!    (`gamma_k`, `beta_k` side by side);
//! 2. block 0: `h = relu(gamma_0 * (Z W_0' + b_0') + beta_0)`, blocks k > 0 alike from `h`,
//!    where each linear layer has its batch norm (running statistics) folded in:
//!    `W' = W / sqrt(var + eps)`, `b' = (b - mean) / sqrt(var + eps)`;
//! 3. `occ = sigmoid(h w_out + b_out)`.
//!
//! It replaces tract only when the file has exactly this structure (f32, names as
//! `volcap_train.nets.CbnMlp` exports them) and agrees with tract on a probe batch at load;
//! anything else (int8, the plain MLP) stays on tract.

use super::Net;
use std::collections::HashMap;
use std::path::Path;
use tract_onnx::pb::TensorProto;
use tract_onnx::prelude::Framework;

/// Points per pass through the layers: small enough that a chunk's CBN products and
/// activations stay in the per-core L2 cache (256 x 2 B H floats, 512 KiB for the compact
/// model's 4 x 64) between the product and its epilogue. Measured with `volcap bench mlp`
/// (compact, 65,536 points): 4,096 -> 59 % of the SGEMM peak, 512 -> 71-74 %, 256 -> 74-76 %.
const CHUNK: usize = 256;

/// The fused MLP (see the module text).
pub struct FusedCbnMlp {
    zdim: usize,
    hidden: usize,
    cond: usize,
    /// Per block: the folded weights stored [in, H] (row-major, so `x W` reads them in order)
    /// and the folded bias [H].
    layers: Vec<(Vec<f32>, Vec<f32>)>,
    /// [f, 2 B H]: gamma_0 | beta_0 | gamma_1 | beta_1 | ...
    cond_w: Vec<f32>,
    cond_b: Vec<f32>,
    out_w: Vec<f32>,
    out_b: f32,
}

fn floats(t: &TensorProto) -> Option<Vec<f32>> {
    // TensorProto.DataType FLOAT = 1.
    if t.data_type != 1 {
        return None;
    }
    if !t.float_data.is_empty() {
        return Some(t.float_data.clone());
    }
    if !t.raw_data.len().is_multiple_of(4) {
        return None;
    }
    Some(
        t.raw_data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
    )
}

/// `C[m, n] = A[m, k] B[k, n]`, all row-major and contiguous (the product the fused MLP is
/// built on; `volcap bench mlp` measures its peak with it).
pub fn sgemm(m: usize, k: usize, n: usize, a: &[f32], b: &[f32], c: &mut [f32]) {
    gemm(m, k, n, a, b, c, false);
}

/// `C[m, n] = A[m, k] B[k, n]` (+ `C` when `acc`), all row-major and contiguous.
fn gemm(m: usize, k: usize, n: usize, a: &[f32], b: &[f32], c: &mut [f32], acc: bool) {
    assert!(a.len() >= m * k && b.len() >= k * n && c.len() >= m * n);
    // SAFETY: the asserts above bound every index the kernel touches (row-major strides
    // k/1, n/1, n/1 over m x k, k x n and m x n elements); `c` does not alias `a` or `b`
    // (a mutable borrow).
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            k as isize,
            1,
            b.as_ptr(),
            n as isize,
            1,
            if acc { 1.0 } else { 0.0 },
            c.as_mut_ptr(),
            n as isize,
            1,
        );
    }
}

impl FusedCbnMlp {
    /// Read the weights of a CBN MLP file; `None` when the file is not exactly that (f32
    /// initializers named `m.inp.*`, `m.lin.K.*`, `m.cbn.K.{bn.running_*, gamma.*, beta.*}`,
    /// `m.out.*` with consistent shapes).
    pub fn from_onnx(path: &Path) -> Option<Self> {
        let proto = tract_onnx::onnx().proto_model_for_path(path).ok()?;
        let graph = proto.graph.as_ref()?;
        let mut w: HashMap<&str, (Vec<usize>, Vec<f32>)> = HashMap::new();
        for t in &graph.initializer {
            let dims: Vec<usize> = t.dims.iter().map(|&d| d as usize).collect();
            w.insert(t.name.as_str(), (dims, floats(t)?));
        }
        let eps = graph
            .node
            .iter()
            .find(|n| n.op_type == "BatchNormalization")?
            .attribute
            .iter()
            .find(|a| a.name == "epsilon")
            .map(|a| a.f)
            .unwrap_or(1e-5);
        let get = |name: &str, shape: &[usize]| -> Option<&Vec<f32>> {
            let (d, v) = w.get(name)?;
            (d.as_slice() == shape && v.len() == shape.iter().product::<usize>()).then_some(v)
        };
        let (d_inp, _) = w.get("m.inp.weight")?;
        let (hidden, zdim) = (*d_inp.first()?, *d_inp.get(1)?);
        let (d_g, _) = w.get("m.cbn.0.gamma.weight")?;
        let cond = *d_g.get(1)?;
        let blocks = (0..)
            .take_while(|k| w.contains_key(format!("m.cbn.{k}.gamma.weight").as_str()))
            .count();
        if blocks == 0 || hidden == 0 {
            return None;
        }
        let mut layers = Vec::with_capacity(blocks);
        let mut cond_w = vec![0.0f32; cond * 2 * blocks * hidden];
        let mut cond_b = vec![0.0f32; 2 * blocks * hidden];
        let row = 2 * blocks * hidden;
        for k in 0..blocks {
            let (lw, lb, fan_in) = if k == 0 {
                (
                    get("m.inp.weight", &[hidden, zdim])?,
                    get("m.inp.bias", &[hidden])?,
                    zdim,
                )
            } else {
                let p = format!("m.lin.{}", k - 1);
                (
                    get(&format!("{p}.weight"), &[hidden, hidden])?,
                    get(&format!("{p}.bias"), &[hidden])?,
                    hidden,
                )
            };
            let p = format!("m.cbn.{k}");
            let mean = get(&format!("{p}.bn.running_mean"), &[hidden])?;
            let var = get(&format!("{p}.bn.running_var"), &[hidden])?;
            let mut wt = vec![0.0f32; fan_in * hidden];
            let mut bias = vec![0.0f32; hidden];
            for o in 0..hidden {
                let s = 1.0 / (var[o] + eps).sqrt();
                for i in 0..fan_in {
                    wt[i * hidden + o] = lw[o * fan_in + i] * s;
                }
                bias[o] = (lb[o] - mean[o]) * s;
            }
            layers.push((wt, bias));
            for (j, part) in ["gamma", "beta"].iter().enumerate() {
                let gw = get(&format!("{p}.{part}.weight"), &[hidden, cond])?;
                let gb = get(&format!("{p}.{part}.bias"), &[hidden])?;
                let col = (2 * k + j) * hidden;
                for o in 0..hidden {
                    for i in 0..cond {
                        cond_w[i * row + col + o] = gw[o * cond + i];
                    }
                    cond_b[col + o] = gb[o];
                }
            }
        }
        let out_w = get("m.out.weight", &[1, hidden])?.clone();
        let out_b = *get("m.out.bias", &[1])?.first()?;
        let all_finite = layers
            .iter()
            .all(|(a, b)| a.iter().chain(b).all(|v| v.is_finite()))
            && cond_w
                .iter()
                .chain(&cond_b)
                .chain(&out_w)
                .all(|v| v.is_finite())
            && out_b.is_finite();
        all_finite.then_some(Self {
            zdim,
            hidden,
            cond,
            layers,
            cond_w,
            cond_b,
            out_w,
            out_b,
        })
    }

    /// Feature channels and depth-code width the MLP takes.
    pub fn dims(&self) -> (usize, usize) {
        (self.cond, self.zdim)
    }

    /// Multiply-adds per point.
    pub fn macs_per_point(&self) -> usize {
        let b = self.layers.len();
        self.cond * 2 * b * self.hidden
            + self.zdim * self.hidden
            + (b - 1) * self.hidden * self.hidden
            + self.hidden
    }

    /// Occupancy of `n` points: `feat` [n, f], `z` [n, zdim] -> `out` [n], in chunks of [`CHUNK`].
    pub fn run(&self, feat: &[f32], z: &[f32], out: &mut [f32]) {
        let h = self.hidden;
        let n = out.len();
        let row = 2 * self.layers.len() * h;
        // Scratch kept per thread (evaluation threads call this at once), grown once.
        thread_local! {
            static SCRATCH: std::cell::RefCell<[Vec<f32>; 3]> = Default::default();
        }
        SCRATCH.with_borrow_mut(|[c, x, y]| {
            for (v, len) in [(&mut *c, row), (&mut *x, h), (&mut *y, h)] {
                if v.len() < CHUNK.min(n) * len {
                    v.resize(CHUNK.min(n) * len, 0.0);
                }
            }
            self.run_chunks(feat, z, out, c, x, y)
        });
    }

    fn run_chunks(
        &self,
        feat: &[f32],
        z: &[f32],
        out: &mut [f32],
        c: &mut [f32],
        x: &mut Vec<f32>,
        y: &mut Vec<f32>,
    ) {
        let (f, zd, h) = (self.cond, self.zdim, self.hidden);
        let n = out.len();
        let row = 2 * self.layers.len() * h;
        for s in (0..n).step_by(CHUNK) {
            let m = CHUNK.min(n - s);
            let c = &mut c[..m * row];
            for r in c.chunks_exact_mut(row) {
                r.copy_from_slice(&self.cond_b);
            }
            gemm(m, f, row, &feat[s * f..(s + m) * f], &self.cond_w, c, true);
            for (k, (wt, b)) in self.layers.iter().enumerate() {
                let (input, fan_in): (&[f32], usize) = if k == 0 {
                    (&z[s * zd..(s + m) * zd], zd)
                } else {
                    (&x[..m * h], h)
                };
                let ys = &mut y[..m * h];
                for r in ys.chunks_exact_mut(h) {
                    r.copy_from_slice(b);
                }
                gemm(m, fan_in, h, input, wt, ys, true);
                for (p, yr) in ys.chunks_exact_mut(h).enumerate() {
                    let cr = &c[p * row + 2 * k * h..p * row + (2 * k + 2) * h];
                    let (g, be) = cr.split_at(h);
                    for ((v, g), be) in yr.iter_mut().zip(g).zip(be) {
                        *v = (*g * *v + *be).max(0.0);
                    }
                }
                std::mem::swap(x, y);
            }
            for (p, o) in out[s..s + m].iter_mut().enumerate() {
                let hr = &x[p * h..(p + 1) * h];
                let logit: f32 =
                    hr.iter().zip(&self.out_w).map(|(a, b)| a * b).sum::<f32>() + self.out_b;
                // Sigmoid without overflow for any finite logit.
                *o = if logit >= 0.0 {
                    1.0 / (1.0 + (-logit).exp())
                } else {
                    let e = logit.exp();
                    e / (1.0 + e)
                };
            }
        }
    }
}

/// The fused MLP and tract agree (max |difference| <= 1e-4) on a probe batch of 257 points
/// with pseudo-random features in [-2, 2] and depth codes in [0, 1].
pub(crate) fn agrees(f: &FusedCbnMlp, net: &Net, c: usize, zd: usize) -> bool {
    let n = 257;
    let mut state = 0x9e37_79b9u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state as f32 / u32::MAX as f32
    };
    let feat: Vec<f32> = (0..n * c).map(|_| 4.0 * next() - 2.0).collect();
    let z: Vec<f32> = (0..n * zd).map(|_| next()).collect();
    let Ok(want) = net.run(&[(&[n, c], &feat), (&[n, zd], &z)]) else {
        return false;
    };
    let mut got = vec![0.0f32; n];
    f.run(&feat, &z, &mut got);
    want.len() == n && want.iter().zip(&got).all(|(a, b)| (a - b).abs() <= 1e-4)
}
