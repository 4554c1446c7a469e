//! Pieces apart from the body in the adapter's render ([`crate::render::RenderOptions`]'s
//! `drop_apart`, `render.rs` step 1b): after the levels up to `L - 1`, the level's inside
//! points come back as bits (`pieces.wgsl` `pack`: a bit a point, some 330 KB at 257^3), the
//! host finds the pieces on them ([`Pieces::drop_apart_bits`], the CPU renderer's rule on the
//! same lattice), and the dropped points go up as a list (`drop_apart`: each set outside, it
//! and its 26 level-`L` neighbours marked handled, so that the final level lists none of
//! them). The frame then goes on as without the pass: a dropped piece has no candidates, no
//! hit, and culls nothing behind it.

use super::super::kit::{bind_layout, entry, module, pipeline, pipeline_layout, storage};
use super::super::localize::{Dispatch, Rec, Retry, Tiling};
use crate::grid::GridSpec;
use crate::pieces::{Pieces, gap_points, lattice_words};

const PIECES: &str = concat!(
    include_str!("../localize.wgsl"),
    include_str!("../pieces.wgsl")
);

/// The two kernels, made for the localizer's tiling of the values.
pub(super) struct ApartPipes {
    layout: wgpu::BindGroupLayout,
    pack: wgpu::ComputePipeline,
    drop: wgpu::ComputePipeline,
}

impl ApartPipes {
    /// Within the caller's error scope (a validation error is its to report).
    pub(super) fn new(d: &wgpu::Device, layout0: &wgpu::BindGroupLayout, tiling: Tiling) -> Self {
        let layout = bind_layout(d, "pieces", &[storage(0, false)]);
        let m = module(d, "pieces", &format!("{}{PIECES}", tiling.wgsl(true)));
        let pl = pipeline_layout(d, &[layout0, &layout]);
        ApartPipes {
            pack: pipeline(d, &m, &pl, "pack"),
            drop: pipeline(d, &m, &pl, "drop_apart"),
            layout,
        }
    }
}

struct ApartBufs {
    /// Words the buffer holds.
    words: usize,
    buf: wgpu::Buffer,
    staging: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

/// The pass's buffers and the host's scratch, kept from frame to frame.
#[derive(Default)]
pub(super) struct Apart {
    bufs: Option<ApartBufs>,
    host: Pieces,
    bits: Vec<u32>,
    list: Vec<u32>,
}

impl Apart {
    /// A buffer of at least `words` words (the bits, then the list), grown by half again.
    fn ensure(&mut self, d: &wgpu::Device, pipes: &ApartPipes, words: usize) -> Result<(), String> {
        if self.bufs.as_ref().is_some_and(|b| b.words >= words) {
            return Ok(());
        }
        let words = words + words / 2;
        let bytes = (words * 4) as u64;
        let limits = d.limits();
        let most = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes > most {
            return Err(format!(
                "the pieces apart from the body need {bytes} bytes in one storage binding, \
                 more than the adapter's {most} (render.drop_apart = 0 turns the pass off)"
            ));
        }
        use wgpu::BufferUsages as U;
        let buf = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pieces"),
            size: bytes,
            usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
            mapped_at_creation: false,
        });
        let staging = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pieces read-back"),
            size: bytes,
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipes.layout,
            entries: &[entry(0, &buf)],
        });
        self.bufs = Some(ApartBufs {
            words,
            buf,
            staging,
            bind,
        });
        Ok(())
    }

    /// The pass on the frame `rec` records, its levels up to `fine` (`L - 1`) localized:
    /// the points dropped (the CPU's `RenderStats::dropped_apart`), or why the frame must run
    /// again (its read-back is the counters' too: [`Retry::of`]). `frac` is the gap, a
    /// fraction of the grid's side ([`gap_points`] on level `L - 1`, as `render.rs`).
    pub(super) fn run(
        &mut self,
        rec: &mut Rec<'_>,
        pipes: &ApartPipes,
        spec: GridSpec,
        fine: u32,
        frac: f32,
    ) -> Result<Result<u64, Retry>, String> {
        let gpu = rec.gpu;
        let d = &gpu.device;
        let words = lattice_words(spec, 2);
        self.ensure(d, pipes, words)?;
        let b = self.bufs.as_ref().ok_or("no pieces buffer")?;
        rec.pass(&[(
            &pipes.pack,
            fine,
            0,
            Dispatch::With(&b.bind, Some(words as u32)),
        )]);
        self.bits.resize(words, 0);
        let counts =
            rec.counts_and_read(&b.buf, &b.staging, bytemuck::cast_slice_mut(&mut self.bits))?;
        if let Some(r) = Retry::of(&counts) {
            return Ok(Err(r));
        }
        let coarser = spec.coarser().ok_or("a grid too small for pieces")?;
        let gap = gap_points(coarser, frac);
        let st = self.host.drop_apart_bits(spec, 2, &self.bits, [gap; 3])?;
        let dropped = self.host.dropped();
        if dropped.is_empty() {
            return Ok(Ok(0));
        }
        let count = dropped.len() as u32;
        self.list.clear();
        self.list.push(count);
        self.list.extend_from_slice(dropped);
        self.ensure(d, pipes, self.list.len())?;
        let b = self.bufs.as_ref().ok_or("no pieces buffer")?;
        gpu.queue
            .write_buffer(&b.buf, 0, bytemuck::cast_slice(&self.list));
        gpu.count().bytes_up.fetch_add(
            (self.list.len() * 4) as u64,
            std::sync::atomic::Ordering::Relaxed,
        );
        rec.pass(&[(&pipes.drop, fine, 0, Dispatch::With(&b.bind, Some(count)))]);
        Ok(Ok(st.dropped_points as u64))
    }
}
