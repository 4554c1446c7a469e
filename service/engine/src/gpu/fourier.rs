//! The Fourier field on the GPU: a frame's coefficient maps written to the adapter once,
//! then the occupancy of any batch of crop-NDC points in one dispatch (`fourier.wgsl`: taps,
//! basis recurrence, level offset, clamp), equal to [`FourierMaps::occupancy`] within float
//! rounding (tests/gpu.rs: 100k points per committed model within 1e-4).
//!
//! A frame's buffers (maps, points, occupancy, read-back, parameters and their bind group)
//! come from the adapter's pool ([`Gpu::field_pool`]) and go back to it when the frame's
//! field is dropped: a frame writes into them instead of creating them.

use super::kit::entry;
use super::{Gpu, groups};
use crate::model::fourier::{Basis, FourierMaps};
use glam::Vec3;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

const SOURCE: &str = concat!(include_str!("series.wgsl"), include_str!("fourier.wgsl"));

/// Point buffers sized for this many points at least (grown by doubling when a batch is
/// larger).
const MIN_POINTS: usize = 1 << 14;

/// Frames' buffers kept for reuse: the fields alive at once (the render stage's and the
/// field stage's) and one spare.
const POOL: usize = 3;

/// One frame's buffers on the adapter.
pub(crate) struct FieldBuffers {
    /// Floats the maps buffer holds, points the point buffers hold.
    maps_cap: usize,
    cap: usize,
    maps: wgpu::Buffer,
    pts: wgpu::Buffer,
    occ: wgpu::Buffer,
    staging: wgpu::Buffer,
    params: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// The points as the kernel reads them, reused from batch to batch.
    flat: Vec<f32>,
}

impl FieldBuffers {
    /// Buffers for `maps_cap` map floats (reusing `maps` when given) and `cap` points.
    fn new(
        gpu: &Gpu,
        pipeline: &wgpu::ComputePipeline,
        maps: Option<wgpu::Buffer>,
        maps_cap: usize,
        cap: usize,
    ) -> Self {
        use wgpu::BufferUsages as U;
        let buf = |label, bytes: usize, usage| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        let maps =
            maps.unwrap_or_else(|| buf("fourier maps", maps_cap * 4, U::STORAGE | U::COPY_DST));
        let pts = buf("points", cap * 12, U::STORAGE | U::COPY_DST);
        let occ = buf("occupancy", cap * 4, U::STORAGE | U::COPY_SRC);
        let staging = buf("occupancy read-back", cap * 4, U::MAP_READ | U::COPY_DST);
        let params = buf("fourier params", 24, U::STORAGE | U::COPY_DST);
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &params),
                entry(1, &maps),
                entry(2, &pts),
                entry(3, &occ),
            ],
        });
        FieldBuffers {
            maps_cap,
            cap,
            maps,
            pts,
            occ,
            staging,
            params,
            bind,
            flat: Vec::with_capacity(cap * 3),
        }
    }
}

/// The series' parameters as `series.wgsl` takes them: K, map size, basis (1: cosine), the
/// depth scale and the surface level's offset (the floats as bits).
pub(super) fn series_head(maps: &FourierMaps) -> [u32; 5] {
    series_words(
        maps.k(),
        maps.size(),
        maps.basis(),
        maps.zeta_scale(),
        maps.iso_level(),
    )
}

/// [`series_head`]'s words from the series' parts (`iso_level` as the maps give it back).
pub(super) fn series_words(
    k: usize,
    size: usize,
    basis: Basis,
    zeta_scale: f32,
    iso_level: f32,
) -> [u32; 5] {
    [
        k as u32,
        size as u32,
        (basis == Basis::Cosine) as u32,
        zeta_scale.to_bits(),
        (0.5 - iso_level).to_bits(),
    ]
}

/// One frame's maps on the adapter, written there by the first point query (a frame whose
/// every stage runs on the adapter never asks one, and its maps go up once, to the
/// localizer, not twice).
pub struct GpuFourier {
    gpu: Arc<Gpu>,
    pipeline: Arc<wgpu::ComputePipeline>,
    head: [u32; 5],
    len: usize,
    /// The maps' buffer when they are on the adapter already ([`Self::on_adapter`]): copied
    /// there, never written from the host.
    source: Option<wgpu::Buffer>,
    buffers: Mutex<Option<FieldBuffers>>,
}

impl GpuFourier {
    /// The field of `maps` (its coefficients, basis and surface level) on the adapter: checked
    /// against the adapter's limit now, written at the first [`Self::occupancy`].
    pub fn new(gpu: Arc<Gpu>, maps: &FourierMaps) -> Result<Self, String> {
        let pipeline = gpu.pipeline("fourier", SOURCE)?;
        let data = maps.coefficients();
        let bytes = std::mem::size_of_val(data);
        let limit = gpu.device.limits().max_storage_buffer_binding_size as usize;
        if bytes > limit {
            return Err(format!(
                "maps of {bytes} bytes exceed the adapter's {limit} per binding"
            ));
        }
        Ok(GpuFourier {
            gpu,
            pipeline,
            head: series_head(maps),
            len: data.len(),
            source: None,
            buffers: Mutex::new(None),
        })
    }

    /// The field of maps already on the adapter (the GPU backend's frames): the first query
    /// copies them into the field's buffers there.
    pub fn on_adapter(maps: &super::maps::GpuMaps) -> Result<Self, String> {
        let gpu = maps.gpu().clone();
        let pipeline = gpu.pipeline("fourier", SOURCE)?;
        let head = maps.head();
        Ok(GpuFourier {
            gpu,
            pipeline,
            head: head.series(),
            len: head.len(),
            source: Some(maps.buffer().clone()),
            buffers: Mutex::new(None),
        })
    }

    /// The maps' buffers, from the adapter's pool or new, with the maps written in (`maps`,
    /// or copied from the adapter's buffer for a field made [`Self::on_adapter`]).
    fn upload(&self, maps: Option<&FourierMaps>) -> FieldBuffers {
        let len = self.len;
        let pooled = {
            let mut pool = self
                .gpu
                .field_pool
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            let i = pool.iter().position(|b| b.maps_cap >= len);
            i.map(|i| pool.swap_remove(i))
        };
        let b = pooled
            .unwrap_or_else(|| FieldBuffers::new(&self.gpu, &self.pipeline, None, len, MIN_POINTS));
        match (&self.source, maps) {
            (Some(src), _) => {
                let mut enc = self
                    .gpu
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
                enc.copy_buffer_to_buffer(src, 0, &b.maps, 0, (len * 4) as u64);
                self.gpu.queue.submit([enc.finish()]);
            }
            (None, Some(maps)) => {
                let data = maps.coefficients();
                self.gpu
                    .queue
                    .write_buffer(&b.maps, 0, bytemuck::cast_slice(data));
                self.gpu
                    .count()
                    .bytes_up
                    .fetch_add(std::mem::size_of_val(data) as u64, Ordering::Relaxed);
            }
            (None, None) => {}
        }
        b
    }

    /// Occupancy in [0, 1] at crop-NDC `points` into `out` (as [`FourierMaps::occupancy`]);
    /// `maps` are the ones this field was made from (written to the adapter on first use).
    pub fn occupancy(
        &self,
        maps: &FourierMaps,
        points: &[Vec3],
        out: &mut [f32],
    ) -> Result<(), String> {
        if series_head(maps) != self.head || maps.coefficients().len() != self.len {
            return Err("the maps are not the ones this field was made from".into());
        }
        self.query(Some(maps), points, out)
    }

    /// [`Self::occupancy`] of a field made [`Self::on_adapter`] (its maps are there).
    pub fn occupancy_on_adapter(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), String> {
        if self.source.is_none() {
            return Err("the maps of this field are on the host".into());
        }
        self.query(None, points, out)
    }

    fn query(
        &self,
        maps: Option<&FourierMaps>,
        points: &[Vec3],
        out: &mut [f32],
    ) -> Result<(), String> {
        let n = points.len().min(out.len());
        if n == 0 {
            return Ok(());
        }
        let mut slot = self.buffers.lock().unwrap_or_else(|p| p.into_inner());
        let mut b = match slot.take() {
            Some(b) => b,
            None => self.upload(maps),
        };
        if b.cap < n {
            // A larger batch: new point buffers, the maps kept.
            let cap = n.next_power_of_two();
            b = FieldBuffers::new(&self.gpu, &self.pipeline, Some(b.maps), b.maps_cap, cap);
        }
        let result = self.dispatch(&mut b, &points[..n], &mut out[..n]);
        *slot = Some(b);
        result
    }

    fn dispatch(
        &self,
        b: &mut FieldBuffers,
        points: &[Vec3],
        out: &mut [f32],
    ) -> Result<(), String> {
        let n = points.len();
        let q = &self.gpu.queue;
        let mut params = [0u32; 6];
        params[0] = n as u32;
        params[1..].copy_from_slice(&self.head);
        q.write_buffer(&b.params, 0, bytemuck::cast_slice(&params));
        b.flat.clear();
        b.flat.extend(points.iter().flat_map(|p| [p.x, p.y, p.z]));
        q.write_buffer(&b.pts, 0, bytemuck::cast_slice(&b.flat));
        let c = self.gpu.count();
        c.bytes_up.fetch_add((n * 12) as u64, Ordering::Relaxed);
        let mut enc = self
            .gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &b.bind, &[]);
            let (x, y) = groups(n as u32);
            pass.dispatch_workgroups(x, y, 1);
        }
        c.dispatches.fetch_add(1, Ordering::Relaxed);
        c.field_runs.fetch_add(1, Ordering::Relaxed);
        self.gpu
            .submit_and_read_into(enc, &b.occ, &b.staging, out)
            .map(|_| ())
    }
}

impl Drop for GpuFourier {
    /// The frame's buffers back to the adapter's pool for the next frame.
    fn drop(&mut self) {
        let b = self
            .buffers
            .get_mut()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        if let Some(b) = b {
            let mut pool = self
                .gpu
                .field_pool
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            if pool.len() < POOL {
                pool.push(b);
            }
        }
    }
}
