//! Recording a frame's localization: compute passes on one encoder, the levels of the
//! hierarchical method, the conflict rounds one submission each (the first with its level's
//! passes; in batches with `GpuLocalizer::with_rounds_per_wait`), the counters read back
//! after each; or, with a plan (`plan.rs`), every level's predicted rounds in the one
//! submission the frame's first read-back ends.

use super::plan::{LEVEL_KEYS, level_key};
use super::{Bufs, COUNTS, FieldBufs, LEVEL_ROUNDS, LIST, MISS, OVERFLOW, Pipes};
use crate::gpu::{Gpu, groups};
use crate::grid::GridSpec;
use crate::localize::HierarchicalMode;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Records a frame's work: compute passes on one encoder, submitted where the host must read
/// a count (the conflict loop's rounds, the frame's end).
pub(in crate::gpu) struct Rec<'a> {
    pub(in crate::gpu) gpu: &'a Arc<Gpu>,
    pub(in crate::gpu) b: &'a Bufs,
    pub(super) f: &'a FieldBufs,
    pub(in crate::gpu) p: &'a Pipes,
    pub(super) eval: &'a wgpu::ComputePipeline,
    pub(in crate::gpu) spec: GridSpec,
    pub(super) enc: Option<wgpu::CommandEncoder>,
    /// Whether a pass of `enc` began the submission's span on the adapter's clock.
    pub(super) timed: bool,
    pub(in crate::gpu) dispatches: u64,
    /// Conflict rounds per submission at most (`GpuLocalizer::with_rounds_per_wait`).
    pub(super) rounds_per_wait: usize,
    /// Loop iterations to record per level key, read back once (`plan.rs`); `None`: read
    /// after each round.
    pub(super) plan: Option<[u32; LEVEL_KEYS]>,
    /// The counters last read, while nothing was recorded since.
    pub(super) last: Option<[u32; COUNTS]>,
}

/// Why a frame is run again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::gpu) enum Retry {
    /// A list overflowed: larger lists.
    Overflow,
    /// A level's predicted rounds fell short: the rounds each level ran (a level's up to
    /// the one that fell short are exact, that one's a lower bound).
    Missed([u32; LEVEL_KEYS]),
}

impl Retry {
    /// What counters read back say of the frame so far.
    pub(in crate::gpu) fn of(counts: &[u32; COUNTS]) -> Option<Retry> {
        if counts[OVERFLOW] != 0 {
            Some(Retry::Overflow)
        } else if counts[MISS] != 0 {
            let mut seen = [0; LEVEL_KEYS];
            seen.copy_from_slice(&counts[LEVEL_ROUNDS..LEVEL_ROUNDS + LEVEL_KEYS]);
            Some(Retry::Missed(seen))
        } else {
            None
        }
    }
}

impl<'a> Rec<'a> {
    /// Record one compute pass of `steps` (pipeline, level, orientation, how).
    pub(in crate::gpu) fn pass(
        &mut self,
        steps: &[(&wgpu::ComputePipeline, u32, usize, Dispatch<'_>)],
    ) {
        let enc = self
            .enc
            .get_or_insert_with(|| self.gpu.device.create_command_encoder(&Default::default()));
        // The submission's first pass starts its span on the adapter's clock.
        let begin = self.b.timer.as_ref().filter(|_| !self.timed);
        self.timed |= begin.is_some();
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: begin.map(|t| t.begin()),
        });
        for (pipe, l, o, how) in steps {
            pass.set_pipeline(pipe);
            pass.set_bind_group(0, &self.b.binds[*l as usize][*o], &[]);
            match how {
                Dispatch::One => pass.dispatch_workgroups(1, 1, 1),
                Dispatch::Prep => {
                    pass.set_bind_group(1, &self.b.args_bind, &[]);
                    pass.dispatch_workgroups(1, 1, 1)
                }
                Dispatch::Points(count) => {
                    let (x, y) = groups(*count);
                    pass.dispatch_workgroups(x, y, 1)
                }
                Dispatch::Indirect => pass.dispatch_workgroups_indirect(&self.b.args, 0),
                Dispatch::Eval => {
                    pass.set_bind_group(1, &self.f.bind, &[]);
                    pass.dispatch_workgroups_indirect(&self.b.args, 0)
                }
                Dispatch::With(g, count) => {
                    pass.set_bind_group(1, *g, &[]);
                    match count {
                        Some(c) => {
                            let (x, y) = groups(*c);
                            pass.dispatch_workgroups(x, y, 1)
                        }
                        None => pass.dispatch_workgroups_indirect(&self.b.args, 0),
                    }
                }
            }
            self.dispatches += 1;
        }
    }

    /// The field's seeds at level `l` into the list orientation `o` writes (after the
    /// level's dilation, as the CPU's `queue_seeds`), when the frame has any.
    pub(in crate::gpu) fn seeds(&mut self, l: u32, o: usize) {
        let (f, p) = (self.f, self.p);
        if let Some((g, n)) = f.seeds() {
            self.pass(&[(&p.seeds, l, o, Dispatch::With(g, Some(n)))]);
        }
    }

    /// The evaluation kernel of the field uploaded.
    pub(in crate::gpu) fn eval_pipe(&self) -> &'a wgpu::ComputePipeline {
        self.eval
    }

    /// Points of level `l` (all, not only the new ones).
    pub(in crate::gpu) fn level_points(&self, l: u32) -> u32 {
        let n = self.spec.n() as u32;
        let nl = (n - 1) / self.spec.stride(l) as u32 + 1;
        nl * nl * nl
    }

    /// Submit what was recorded with a copy of the counters and read them (no read-back when
    /// nothing was recorded since the last).
    pub(in crate::gpu) fn counts(&mut self) -> Result<[u32; COUNTS], String> {
        if let (None, Some(last)) = (&self.enc, self.last) {
            return Ok(last);
        }
        self.read(None)
    }

    /// [`Self::counts`], and the first `out.len()` bytes of `src` copied after what was
    /// recorded (through `staging`) into `out`: one wait for both.
    pub(in crate::gpu) fn counts_and_read(
        &mut self,
        src: &wgpu::Buffer,
        staging: &wgpu::Buffer,
        out: &mut [u8],
    ) -> Result<[u32; COUNTS], String> {
        let enc = self
            .enc
            .get_or_insert_with(|| self.gpu.device.create_command_encoder(&Default::default()));
        enc.copy_buffer_to_buffer(src, 0, staging, 0, out.len() as u64);
        self.read(Some((staging, out)))
    }

    fn read(&mut self, also: Option<(&wgpu::Buffer, &mut [u8])>) -> Result<[u32; COUNTS], String> {
        let mut enc = self
            .enc
            .take()
            .unwrap_or_else(|| self.gpu.device.create_command_encoder(&Default::default()));
        let b = self.b;
        enc.copy_buffer_to_buffer(&b.counts, 0, &b.counts_staging, 0, (COUNTS * 4) as u64);
        let timer = b.timer.as_ref().filter(|_| self.timed);
        self.timed = false;
        if let Some(t) = timer {
            t.end_into(&mut enc, &b.counts_staging, (COUNTS * 4) as u64);
        }
        let mut raw = [0u8; COUNTS * 4 + 16];
        let len = COUNTS * 4 + if timer.is_some() { 16 } else { 0 };
        match also {
            Some((staging, out)) => self.gpu.submit_and_read_many(
                enc,
                &mut [(&b.counts_staging, &mut raw[..len]), (staging, out)],
            )?,
            None => self
                .gpu
                .submit_and_read_bytes(enc, &b.counts_staging, &mut raw[..len])?,
        };
        if timer.is_some() {
            let c = &self.gpu.count().localize_gpu_ns;
            self.gpu.add_span(c, &raw[COUNTS * 4..]);
        }
        let mut out = [0u32; COUNTS];
        for (o, w) in out.iter_mut().zip(raw.chunks_exact(4)) {
            *o = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
        }
        self.last = Some(out);
        Ok(out)
    }

    /// Record levels `coarse..=last` (the coarsest evaluated whole). Waiting per round, a
    /// submission per round (per batch of rounds) and `Some` when a read showed a list
    /// overflowed; with a plan, the levels' predicted rounds and no read (the next one tells
    /// whether a list overflowed or a plan fell short: [`Retry::of`]).
    pub(in crate::gpu) fn levels(
        &mut self,
        coarse: u32,
        last: u32,
        mode: HierarchicalMode,
    ) -> Result<Option<Retry>, String> {
        let p = self.p;
        let ev = self.eval;
        let pts = self.level_points(coarse);
        self.pass(&[
            (&p.zero, coarse, 1, Dispatch::One),
            (&p.seed, coarse, 1, Dispatch::Points(pts)),
            (&p.prep_eval, coarse, 0, Dispatch::Prep),
            (ev, coarse, 0, Dispatch::Eval),
        ]);
        for l in coarse + 1..=last {
            let pts = self.level_points(l);
            self.pass(&[
                (&p.zero, l, 1, Dispatch::One),
                (&p.upsample, l, 1, Dispatch::Points(pts)),
                (&p.prep_cand, l, 1, Dispatch::Prep),
                (&p.dilate, l, 1, Dispatch::Indirect),
            ]);
            self.seeds(l, 1);
            self.pass(&[
                (&p.prep_eval, l, 0, Dispatch::Prep),
                (ev, l, 0, Dispatch::Eval),
            ]);
            if mode == HierarchicalMode::NoConflict {
                continue;
            }
            self.pass(&[
                (&p.zero, l, 0, Dispatch::One),
                (&p.prep_src, l, 0, Dispatch::Prep),
                (&p.conflict, l, 0, Dispatch::Indirect),
            ]);
            // The conflict loop: the list just written (o = 1 reads list 1) is evaluated and
            // scanned until a round lists nothing. Rounds are recorded `per` at a time (one,
            // unless `with_rounds_per_wait` allows batches) and the counters read after each
            // batch: the rounds after the last one that listed something run over empty lists
            // and change nothing; `prep_round` counts only the rounds that evaluated.
            // The first batch goes with the level's own passes, in the same submission.
            // With a plan, the level's predicted rounds, then the check of the last one's list.
            let mut o = 1usize;
            if let Some(plan) = self.plan {
                for _ in 0..plan[level_key(self.spec, l)].max(1) {
                    self.round(l, o);
                    o = 1 - o;
                }
                self.pass(&[(&p.check_round, l, o, Dispatch::One)]);
                continue;
            }
            let mut per = 1usize;
            loop {
                for _ in 0..per {
                    self.round(l, o);
                    o = 1 - o;
                }
                let counts = self.counts()?;
                if counts[OVERFLOW] != 0 {
                    return Ok(Some(Retry::Overflow));
                }
                if counts[LIST[o]] == 0 {
                    break;
                }
                per = (per * 2).min(self.rounds_per_wait);
            }
        }
        let c = self.gpu.count();
        c.dispatches
            .fetch_add(std::mem::take(&mut self.dispatches), Ordering::Relaxed);
        c.localize_runs.fetch_add(1, Ordering::Relaxed);
        Ok(None)
    }

    /// One conflict round at level `l`: list `o` evaluated, then scanned into the other.
    fn round(&mut self, l: u32, o: usize) {
        let p = self.p;
        self.pass(&[
            (&p.prep_round, l, o, Dispatch::Prep),
            (self.eval, l, o, Dispatch::Eval),
            (&p.zero, l, o, Dispatch::One),
            (&p.prep_src, l, o, Dispatch::Prep),
            (&p.conflict, l, o, Dispatch::Indirect),
        ]);
    }
}

/// How a step dispatches.
#[derive(Clone, Copy)]
pub(in crate::gpu) enum Dispatch<'g> {
    /// One invocation.
    One,
    /// One invocation writing the indirect arguments.
    Prep,
    /// One invocation per point of a count known to the host.
    Points(u32),
    /// The indirect arguments.
    Indirect,
    /// The field's evaluation, over the indirect arguments.
    Eval,
    /// With a second bind group: over a count, or the indirect arguments.
    With(&'g wgpu::BindGroup, Option<u32>),
}
