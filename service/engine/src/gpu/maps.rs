//! A frame's Fourier coefficient maps kept on the adapter, from the shape network to the
//! localizer, the renderer and the point queries, with the temporal filter of the maps run
//! there ([`GpuTemporal`]): the network's planar output is interleaved into a frame buffer
//! (`maps.wgsl`, which flags a value that is not finite) and, in a live stream, blended with
//! the last frame's maps (`maps_temporal.wgsl`, the rule of `model/temporal.rs`), in the
//! network's own submission; the host waits once, for the flag (4 bytes) and, when the colour
//! features are blended too, the per-pixel weights (`4 n` bytes). Before this, the maps came
//! down (2 MB at K = 15 and 128 px), were filtered on the host and went up again to the
//! localizer and to the point queries.
//!
//! The host has the maps only when something asks for them ([`GpuMaps::host`], read back
//! once: the mesh of a frame, a CPU fallback); the frame's buffer goes back to the adapter's
//! pool when the frame's field is dropped.

use super::kit::{bind_layout, entry, module, pipeline, pipeline_layout, storage};
use super::{Gpu, groups};
use crate::model::fourier::{Basis, FourierMaps};
use crate::model::preprocess::Crop;
use std::sync::atomic::Ordering;
use std::sync::{Arc, OnceLock};

mod smooth;

const INTERLEAVE: &str = include_str!("maps.wgsl");
const TEMPORAL: &str = include_str!("maps_temporal.wgsl");

/// Frames' map buffers kept for reuse: the frames alive at once (the field stage's, the
/// render stage's, a mesh request's) and one spare.
const POOL: usize = 4;

/// Where a frame's read-back holds its timestamps (after the flag); the filter's weights
/// follow them.
const STAMPS_AT: u64 = 4;
/// Then the shape network's own two timestamps (`fourier_frame`).
const NET_STAMPS_AT: u64 = STAMPS_AT + 16;
const WEIGHTS_AT: u64 = NET_STAMPS_AT + 16;

/// What a frame's maps hold, as the series reads them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapsHead {
    /// Series order K (2K + 1 channels).
    pub k: usize,
    /// Side of the maps.
    pub size: usize,
    pub basis: Basis,
    pub zeta_scale: f32,
    /// The series level read as the surface (`FourierMaps::with_iso_level`).
    pub iso_level: f32,
    /// Passes of the smoothing across pixels the frame's maps get after the interleave
    /// (`maps/smooth.wgsl`, `FourierMaps::smoothed`), before the temporal filter.
    pub smooth: u8,
}

impl MapsHead {
    pub fn channels(&self) -> usize {
        2 * self.k + 1
    }

    /// Pixels of a map.
    pub fn pixels(&self) -> usize {
        self.size * self.size
    }

    /// Floats of the maps.
    pub fn len(&self) -> usize {
        self.channels() * self.pixels()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The series' parameters as `series.wgsl` takes them: the bits
    /// [`super::fourier::series_head`] gives for host maps of this head.
    pub(crate) fn series(&self) -> [u32; 5] {
        // The level as `FourierMaps::with_iso_level` stores it and `iso_level()` gives it back.
        let iso = 0.5 - (0.5 - self.iso_level);
        super::fourier::series_words(self.k, self.size, self.basis, self.zeta_scale, iso)
    }
}

/// A frame's map buffer (the maps, then the not-finite flag), its flag's read-back and the
/// interleave's parameters and bind group (kept with the buffer from frame to frame).
pub(crate) struct FrameBufs {
    /// Floats the maps part holds, and its channels.
    cap: usize,
    channels: usize,
    maps: wgpu::Buffer,
    /// The flag, then the frame's two timestamps.
    flag_staging: wgpu::Buffer,
    /// The frame's passes on the adapter's clock, where it has timestamps.
    timer: Option<super::Timer>,
    /// `maps.wgsl`'s parameters for these maps.
    params: wgpu::Buffer,
    /// The interleave's bind group and the network output it reads (remade when another).
    bind: Option<(wgpu::Buffer, wgpu::BindGroup)>,
    /// The smoothing's other buffer and bind groups (maps into it, it into the maps), made
    /// at the first frame that smooths.
    smooth: Option<smooth::SmoothBufs>,
}

impl FrameBufs {
    fn new(gpu: &Gpu, head: MapsHead) -> Self {
        use wgpu::BufferUsages as U;
        let cap = head.len();
        let maps = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame maps"),
            size: ((cap + 1) * 4) as u64,
            usage: U::STORAGE | U::COPY_SRC | U::COPY_DST,
            mapped_at_creation: false,
        });
        let params = wgpu::util::DeviceExt::create_buffer_init(
            &gpu.device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("interleave params"),
                contents: bytemuck::cast_slice(&[
                    cap as u32,
                    head.channels() as u32,
                    head.pixels() as u32,
                ]),
                usage: U::STORAGE,
            },
        );
        let flag_staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("maps flag read-back"),
            size: WEIGHTS_AT,
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        FrameBufs {
            cap,
            channels: head.channels(),
            maps,
            flag_staging,
            timer: gpu.timer(),
            params,
            bind: None,
            smooth: None,
        }
    }

    /// The interleave's bind group reading `src` into these maps.
    fn bind(
        &mut self,
        gpu: &Gpu,
        pipeline: &wgpu::ComputePipeline,
        src: &wgpu::Buffer,
    ) -> &wgpu::BindGroup {
        if self.bind.as_ref().is_none_or(|(b, _)| b != src) {
            let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[entry(0, &self.params), entry(1, src), entry(2, &self.maps)],
            });
            self.bind = Some((src.clone(), group));
        }
        &self.bind.as_ref().expect("set above").1
    }
}

/// One frame's coefficient maps on the adapter.
pub struct GpuMaps {
    gpu: Arc<Gpu>,
    head: MapsHead,
    /// `Some` until dropped (then back to the pool).
    bufs: Option<FrameBufs>,
    host: OnceLock<FourierMaps>,
}

impl std::fmt::Debug for GpuMaps {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuMaps({:?})", self.head)
    }
}

impl GpuMaps {
    fn new(gpu: Arc<Gpu>, head: MapsHead) -> Self {
        let (len, channels) = (head.len(), head.channels());
        let pooled = {
            let mut pool = gpu.maps_pool.lock().unwrap_or_else(|p| p.into_inner());
            let i = pool
                .iter()
                .position(|b| b.cap == len && b.channels == channels);
            i.map(|i| pool.swap_remove(i))
        };
        let bufs = pooled.unwrap_or_else(|| FrameBufs::new(&gpu, head));
        GpuMaps {
            gpu,
            head,
            bufs: Some(bufs),
            host: OnceLock::new(),
        }
    }

    pub fn head(&self) -> MapsHead {
        self.head
    }

    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    /// The maps' buffer on the adapter (`head().len()` floats, pixel-interleaved, then the
    /// flag).
    pub fn buffer(&self) -> &wgpu::Buffer {
        // Set in `new`, taken only by `drop`.
        &self
            .bufs
            .as_ref()
            .expect("frame buffers until dropped")
            .maps
    }

    /// The maps on the host, read back from the adapter at the first call (the head's surface
    /// level and basis set, as `FourierNet::maps` makes them).
    pub fn host(&self) -> Result<&FourierMaps, String> {
        if let Some(m) = self.host.get() {
            return Ok(m);
        }
        let h = self.head;
        let bytes = (h.len() * 4) as u64;
        let staging = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("maps read-back"),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        let mut data = vec![0.0f32; h.len()];
        self.gpu
            .submit_and_read_into(enc, self.buffer(), &staging, &mut data)?;
        let maps = FourierMaps::from_interleaved(data, h.k, h.size, h.zeta_scale)
            .ok_or("the maps on the adapter are not finite")?
            .with_iso_level(h.iso_level)
            .with_basis(h.basis);
        Ok(self.host.get_or_init(|| maps))
    }
}

impl Drop for GpuMaps {
    fn drop(&mut self) {
        if let Some(b) = self.bufs.take() {
            let mut pool = self.gpu.maps_pool.lock().unwrap_or_else(|p| p.into_inner());
            if pool.len() < POOL {
                pool.push(b);
            }
        }
    }
}

/// One frame's step of the temporal filter, worked out by `model::temporal::Temporal` (its
/// host state: the time step, the crop filter's weight, the settings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemporalStep {
    /// The crop moved since the last frame (the last maps are resampled into this one's).
    pub moved: bool,
    /// The rates' low-pass weight.
    pub a: f32,
    pub min_cutoff_hz: f32,
    pub beta: f32,
    pub dt: f32,
    /// The weight's floor (the crop filter's own).
    pub floor: f32,
    pub from: Crop,
    pub to: Crop,
}

/// Where the temporal filter's parameters hold the motion's pixels, one bit each (word 16:
/// their least weight, 0 when none moved).
const MOTION_BITS_AT: usize = 17;

struct TemporalPipes {
    layout: wgpu::BindGroupLayout,
    rates: wgpu::ComputePipeline,
    reduce: wgpu::ComputePipeline,
    blend: wgpu::ComputePipeline,
    prime: wgpu::ComputePipeline,
}

/// The temporal filter's state of the maps on the adapter: the last frame's maps and rates
/// (two pairs of buffers, read one, write the other, swapped after each frame that went
/// through), per-pixel scratch and the weights' read-back.
pub struct GpuTemporal {
    gpu: Arc<Gpu>,
    pipes: TemporalPipes,
    head: MapsHead,
    last: [wgpu::Buffer; 2],
    rate: [wgpu::Buffer; 2],
    /// speed [n], magnitude [n], weight [n], norm.
    scratch: wgpu::Buffer,
    params: wgpu::Buffer,
    /// The flag, the frame's timestamps, then the weights.
    staging: wgpu::Buffer,
    /// Which of the pairs holds the last frame's.
    cur: usize,
    /// Bind groups made, by frame buffer and `cur` (the pool's few buffers, both ways).
    binds: Vec<(wgpu::Buffer, usize, wgpu::BindGroup)>,
}

/// Bind groups [`GpuTemporal`] keeps: the maps pool's buffers with either pair read.
const BINDS: usize = 2 * POOL;

impl std::fmt::Debug for GpuTemporal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuTemporal({:?})", self.head)
    }
}

impl GpuTemporal {
    /// State for maps of `head` on `gpu`.
    pub fn new(gpu: Arc<Gpu>, head: MapsHead) -> Result<Self, String> {
        let d = &gpu.device;
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let layout = bind_layout(
            d,
            "maps temporal",
            &[
                storage(0, true),
                storage(1, false),
                storage(2, true),
                storage(3, false),
                storage(4, true),
                storage(5, false),
                storage(6, false),
            ],
        );
        let m = module(d, "maps temporal", TEMPORAL);
        let pl = pipeline_layout(d, &[&layout]);
        let pipes = TemporalPipes {
            rates: pipeline(d, &m, &pl, "rates"),
            reduce: pipeline(d, &m, &pl, "reduce"),
            blend: pipeline(d, &m, &pl, "blend"),
            prime: pipeline(d, &m, &pl, "prime"),
            layout,
        };
        use wgpu::BufferUsages as U;
        let (len, n) = (head.len(), head.pixels());
        let buf = |label, bytes: usize, usage| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(4) as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        let state = |label| buf(label, len * 4, U::STORAGE);
        let last = [state("last maps"), state("last maps")];
        let rate = [state("map rates"), state("map rates")];
        let scratch = buf(
            "temporal scratch",
            (3 * n + 1) * 4,
            U::STORAGE | U::COPY_SRC,
        );
        let params = buf(
            "temporal params",
            (MOTION_BITS_AT + n.div_ceil(32)) * 4,
            U::STORAGE | U::COPY_DST,
        );
        let staging = buf(
            "temporal read-back",
            WEIGHTS_AT as usize + n * 4,
            U::MAP_READ | U::COPY_DST,
        );
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(format!("the maps' temporal filter: {e}"));
        }
        Ok(GpuTemporal {
            gpu,
            pipes,
            head,
            last,
            rate,
            scratch,
            params,
            staging,
            cur: 0,
            binds: Vec::new(),
        })
    }

    pub fn head(&self) -> MapsHead {
        self.head
    }

    /// Record the filter of `maps` (this frame's, in place): `step` continues from the last
    /// frame's maps, `None` starts from this frame's (after a reset); `motion`: the least
    /// weight of the new maps and the pixels it holds at (`FrameFilter::motion`).
    fn record(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        maps: &wgpu::Buffer,
        step: Option<&TemporalStep>,
        motion: Option<&(f32, Vec<bool>)>,
    ) -> u64 {
        let h = self.head;
        let (n, c) = (h.pixels() as u32, h.channels() as u32);
        let mut p = vec![0u32; MOTION_BITS_AT];
        p[0] = n;
        p[1] = c;
        p[2] = h.size as u32;
        if let Some(s) = step {
            p[3] = s.moved as u32;
            let f = [
                s.a,
                // As the host's filter divides (its `1 / dt`, not the adapter's division).
                1.0 / s.dt,
                s.min_cutoff_hz,
                s.beta,
                s.dt,
                s.floor,
                s.from.tx,
                s.from.ty,
                s.from.s,
                s.to.tx,
                s.to.ty,
                s.to.s,
            ];
            for (o, v) in p[4..].iter_mut().zip(f) {
                *o = v.to_bits();
            }
            // The motion's bits (2 KB at 128 x 128) go up with the parameters, which, as
            // every kernel's parameter block, the byte counters leave out.
            if let Some((least, pixels)) = motion.filter(|m| m.1.len() == n as usize) {
                p[16] = least.to_bits();
                let mut bits = vec![0u32; pixels.len().div_ceil(32)];
                for (q, _) in pixels.iter().enumerate().filter(|(_, m)| **m) {
                    bits[q / 32] |= 1 << (q % 32);
                }
                p.extend(bits);
            }
        }
        self.gpu
            .queue
            .write_buffer(&self.params, 0, bytemuck::cast_slice(&p));
        let (r, w) = (self.cur, 1 - self.cur);
        let known = self.binds.iter().position(|(b, c, _)| b == maps && *c == r);
        let i = match known {
            Some(i) => i,
            None => {
                let group = self
                    .gpu
                    .device
                    .create_bind_group(&wgpu::BindGroupDescriptor {
                        label: None,
                        layout: &self.pipes.layout,
                        entries: &[
                            entry(0, &self.params),
                            entry(1, maps),
                            entry(2, &self.last[r]),
                            entry(3, &self.last[w]),
                            entry(4, &self.rate[r]),
                            entry(5, &self.rate[w]),
                            entry(6, &self.scratch),
                        ],
                    });
                if self.binds.len() == BINDS {
                    self.binds.remove(0);
                }
                self.binds.push((maps.clone(), r, group));
                self.binds.len() - 1
            }
        };
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_bind_group(0, &self.binds[i].2, &[]);
        let mut dispatch = |pipe: &wgpu::ComputePipeline, (x, y): (u32, u32)| {
            pass.set_pipeline(pipe);
            pass.dispatch_workgroups(x, y, 1);
        };
        if step.is_some() {
            dispatch(&self.pipes.rates, groups(n));
            dispatch(&self.pipes.reduce, (1, 1));
            dispatch(&self.pipes.blend, groups(n));
            3
        } else {
            dispatch(&self.pipes.prime, groups(n * c));
            1
        }
    }
}

/// The temporal filter's part in [`fourier_frame`].
pub struct FrameFilter<'a> {
    pub state: &'a mut GpuTemporal,
    /// `None`: the first frame after a reset.
    pub step: Option<TemporalStep>,
    /// Where the mask moved: the least weight of the new maps there and, per map pixel,
    /// whether it is there (`Temporal::motion_pixels`; `None`: nowhere).
    pub motion: Option<(f32, Vec<bool>)>,
    /// Bring the per-pixel weights back (the colour features are blended on the host with
    /// them).
    pub weights: bool,
}

/// Why [`fourier_frame`] gave no maps.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameError {
    /// The network's output holds a value that is not finite (nothing was filtered).
    NotFinite,
    Backend(String),
}

/// Run the shape network `net` on `input` and keep its maps on the adapter: interleaved into
/// a frame buffer (`head` says what they hold), filtered by `filter` when given, in one
/// submission with one wait. Returns the maps and, when asked, the filter's weights per
/// map pixel. A frame whose output is not finite changes no filter state.
pub fn fourier_frame(
    net: &super::net::GpuNet,
    input: (&[usize], &[f32]),
    head: MapsHead,
    filter: Option<FrameFilter<'_>>,
) -> Result<(GpuMaps, Option<Vec<f32>>), FrameError> {
    let gpu = net.gpu().clone();
    let mut out = None;
    net.run_then(&[input], |enc, src, shape, net_timer| {
        let got: usize = shape.iter().product();
        if got != head.len() {
            return Err(format!(
                "the network's output {shape:?} is not maps of {head:?}"
            ));
        }
        out = Some(frame_from(&gpu, enc, src, head, filter, net_timer)?);
        Ok(())
    })
    .map_err(FrameError::Backend)?;
    finish(out.ok_or(FrameError::Backend("no frame".into()))?)
}

/// [`fourier_frame`] from planar maps `[2K + 1, size, size]` given by the host instead of a
/// network's output (written to the adapter first): the same interleave and filter, for
/// tests and for maps made elsewhere.
pub fn maps_frame(
    gpu: &Arc<Gpu>,
    planar: &[f32],
    head: MapsHead,
    filter: Option<FrameFilter<'_>>,
) -> Result<(GpuMaps, Option<Vec<f32>>), FrameError> {
    if planar.len() != head.len() {
        return Err(FrameError::Backend(format!(
            "{} values are not maps of {head:?}",
            planar.len()
        )));
    }
    let src = wgpu::util::DeviceExt::create_buffer_init(
        &gpu.device,
        &wgpu::util::BufferInitDescriptor {
            label: Some("planar maps"),
            contents: bytemuck::cast_slice(planar),
            usage: wgpu::BufferUsages::STORAGE,
        },
    );
    gpu.count()
        .bytes_up
        .fetch_add(std::mem::size_of_val(planar) as u64, Ordering::Relaxed);
    let enc = gpu
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    finish(frame_from(gpu, enc, &src, head, filter, None).map_err(FrameError::Backend)?)
}

/// What a frame's submission gave: its maps, the flag's word, the weights, and the filter
/// to advance when the maps are finite.
type Frame<'a> = (GpuMaps, [u8; 4], Option<Vec<f32>>, Option<FrameFilter<'a>>);

/// Record the interleave of `src` (planar maps on the adapter) into a new frame buffer and
/// the filter's passes after `enc`'s work, submit, and read the flag (and the weights, and
/// the timestamps of these passes and of the network before them, `net_timer`).
fn frame_from<'a>(
    gpu: &Arc<Gpu>,
    mut enc: wgpu::CommandEncoder,
    src: &wgpu::Buffer,
    head: MapsHead,
    mut filter: Option<FrameFilter<'a>>,
    net_timer: Option<&super::Timer>,
) -> Result<Frame<'a>, String> {
    let interleave = gpu.pipeline("maps interleave", INTERLEAVE)?;
    if let Some(f) = &filter
        && f.state.head != head
    {
        return Err(format!(
            "the filter holds maps of {:?}, the frame {head:?}",
            f.state.head
        ));
    }
    let mut maps = GpuMaps::new(gpu.clone(), head);
    let len = head.len();
    let flag_at = (len * 4) as u64;
    let fb = maps.bufs.as_mut().ok_or("no frame buffers")?;
    enc.clear_buffer(&fb.maps, flag_at, Some(4));
    let timer = fb.timer.as_ref();
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes: timer.map(|t| t.begin()),
        });
        pass.set_pipeline(&interleave);
        let (x, y) = groups(len as u32);
        pass.set_bind_group(0, fb.bind(gpu, &interleave, src), &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
    let mut dispatches = 1 + smooth::record(gpu, &mut enc, fb, head)?;
    let fb = maps.bufs.as_ref().ok_or("no frame buffers")?;
    let timer = fb.timer.as_ref();
    // The filter's passes; the read-back (the flag, the timestamps where timed, 16 bytes for
    // these passes' span and 16 for the network's, the weights where asked) into the
    // filter's staging, which has room for the weights, or the frame's.
    let n = head.pixels();
    let mut want_weights = false;
    if let Some(f) = filter.as_mut() {
        dispatches += f
            .state
            .record(&mut enc, &fb.maps, f.step.as_ref(), f.motion.as_ref());
        want_weights = f.weights && f.step.is_some();
    }
    let (staging, scratch) = match filter.as_ref() {
        Some(f) => (&f.state.staging, Some(&f.state.scratch)),
        None => (&fb.flag_staging, None),
    };
    enc.copy_buffer_to_buffer(&fb.maps, flag_at, staging, 0, 4);
    let mut stamps = 0;
    if let Some(timer) = timer {
        timer.end_into(&mut enc, staging, STAMPS_AT);
        stamps = 16;
        if let Some(nt) = net_timer {
            nt.copy_into(&mut enc, staging, NET_STAMPS_AT);
            stamps = 32;
        }
    }
    let mut out = vec![0u8; STAMPS_AT as usize + stamps];
    if let (true, Some(scratch)) = (want_weights, scratch) {
        let at = (2 * n * 4) as u64;
        enc.copy_buffer_to_buffer(scratch, at, staging, WEIGHTS_AT, (n * 4) as u64);
        out.resize(WEIGHTS_AT as usize + 4 * n, 0);
    }
    gpu.submit_and_read_bytes(enc, staging, &mut out)?;
    let weights =
        want_weights.then(|| bytemuck::pod_collect_to_vec::<u8, f32>(&out[WEIGHTS_AT as usize..]));
    let mut flag = [0u8; 4];
    flag.copy_from_slice(&out[..4]);
    if stamps > 0 {
        let c = gpu.count();
        gpu.add_span(&c.maps_gpu_ns, &out[STAMPS_AT as usize..]);
        if net_timer.is_some() {
            gpu.add_span(&c.gpu_ns, &out[NET_STAMPS_AT as usize..]);
        }
    }
    gpu.count()
        .dispatches
        .fetch_add(dispatches, Ordering::Relaxed);
    Ok((maps, flag, weights, filter))
}

/// The frame's maps once its flag says they are finite; the filter's state advanced then.
fn finish(
    (maps, flag, weights, filter): Frame<'_>,
) -> Result<(GpuMaps, Option<Vec<f32>>), FrameError> {
    if u32::from_le_bytes(flag) != 0 {
        return Err(FrameError::NotFinite);
    }
    if let Some(f) = filter {
        // This frame's maps are the next one's last.
        f.state.cur = 1 - f.state.cur;
    }
    Ok((maps, weights))
}
