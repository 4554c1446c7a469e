//! `volcap bench mlp`: the point MLP's throughput against the machine's matrix-product peak,
//! in one process: SGEMM on square matrices (`matrixmultiply`, one thread: the peak the MLP
//! could reach), the fused MLP (the engine's default for f32 CBN files) and the same file on
//! tract, on the same points. GFLOP/s = 2 x multiply-adds / time.

use crate::MlpArgs;
use anyhow::{anyhow, bail};
use std::fmt::Write as _;
use std::time::Instant;
use volcap_engine::model::{Precision, ShapeNets};

/// Median seconds of `runs` calls of `f` (after one untimed call).
pub(crate) fn timed(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

pub fn run(a: &MlpArgs) -> anyhow::Result<()> {
    if a.points == 0 || a.points > 1 << 22 {
        bail!("--points {} must be in 1..=4194304", a.points);
    }
    let nets = ShapeNets::load(&a.models_dir, &a.model, Precision::F32)
        .map_err(|e| anyhow!("model {} in {}: {e}", a.model, a.models_dir.display()))?;
    let Some(fused) = &nets.fused else {
        bail!(
            "shape-{}.mlp.onnx is not a CBN MLP (or disagrees with tract): nothing fused to measure",
            a.model
        );
    };
    let (c, zd, n) = (nets.channels, nets.z.dim(), a.points);
    let feat: Vec<f32> = (0..n * c)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect();
    let z: Vec<f32> = (0..n * zd).map(|i| (i * 13 % 97) as f32 / 96.0).collect();
    let mut out = vec![0.0f32; n];
    let flop = 2.0 * fused.macs_per_point() as f64 * n as f64;
    // The peak: square SGEMM, 512^3.
    let m = 512;
    let (x, y) = (vec![0.5f32; m * m], vec![0.25f32; m * m]);
    let mut p = vec![0.0f32; m * m];
    let t_peak = timed(a.runs, || {
        volcap_engine::model::mlp::sgemm(m, m, m, &x, &y, &mut p)
    });
    let peak = 2.0 * (m * m * m) as f64 / t_peak / 1e9;
    let t_fused = timed(a.runs, || fused.run(&feat, &z, &mut out));
    let t_tract = timed(a.runs, || {
        let _ = nets.mlp.run(&[(&[n, c], &feat), (&[n, zd], &z)]);
    });
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| what | ms | GFLOP/s | of peak |\n|---|---|---|---|\n| SGEMM 512^3 (matrixmultiply, 1 thread: the peak) | {:.1} | {peak:.1} | 100 % |",
        t_peak * 1e3
    );
    for (what, t) in [
        ("fused MLP (engine default)", t_fused),
        ("tract, same ONNX file", t_tract),
    ] {
        let g = flop / t / 1e9;
        let _ = writeln!(
            s,
            "| {what}, {n} points x {} MACs | {:.1} | {g:.1} | {:.0} % |",
            fused.macs_per_point(),
            t * 1e3,
            100.0 * g / peak
        );
    }
    print!("{s}");
    Ok(())
}
