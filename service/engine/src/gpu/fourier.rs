//! The Fourier field on the GPU: a frame's coefficient maps uploaded once, then the
//! occupancy of any batch of crop-NDC points in one dispatch (`fourier.wgsl`: taps, basis
//! recurrence, level offset, clamp), equal to [`FourierMaps::occupancy`] within float
//! rounding (tests/gpu.rs: 100k points per committed model within 1e-4).

use super::{Gpu, groups};
use crate::model::fourier::{Basis, FourierMaps};
use glam::Vec3;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

const SOURCE: &str = include_str!("fourier.wgsl");

/// Point buffers sized for this many points at least (grown by doubling when a batch is
/// larger).
const MIN_POINTS: usize = 1 << 14;

struct Buffers {
    cap: usize,
    pts: wgpu::Buffer,
    occ: wgpu::Buffer,
    staging: wgpu::Buffer,
    params: wgpu::Buffer,
    bind: wgpu::BindGroup,
}

/// One frame's maps on the adapter.
pub struct GpuFourier {
    gpu: Arc<Gpu>,
    pipeline: Arc<wgpu::ComputePipeline>,
    maps: wgpu::Buffer,
    head: [u32; 5],
    buffers: Mutex<Option<Buffers>>,
}

impl GpuFourier {
    /// Upload `maps` (its coefficients, basis and surface level).
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
        let buf = gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("fourier maps"),
                contents: bytemuck::cast_slice(data),
                usage: wgpu::BufferUsages::STORAGE,
            });
        gpu.count()
            .bytes_up
            .fetch_add(bytes as u64, Ordering::Relaxed);
        let head = [
            maps.k() as u32,
            maps.size() as u32,
            (maps.basis() == Basis::Cosine) as u32,
            maps.zeta_scale().to_bits(),
            (0.5 - maps.iso_level()).to_bits(),
        ];
        Ok(GpuFourier {
            gpu,
            pipeline,
            maps: buf,
            head,
            buffers: Mutex::new(None),
        })
    }

    fn buffers(&self, n: usize) -> Buffers {
        let cap = n.max(MIN_POINTS).next_power_of_two();
        let dev = &self.gpu.device;
        let storage = |label, bytes: usize, usage| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let pts = storage("points", cap * 12, U::STORAGE | U::COPY_DST);
        let occ = storage("occupancy", cap * 4, U::STORAGE | U::COPY_SRC);
        let staging = storage("occupancy read-back", cap * 4, U::MAP_READ | U::COPY_DST);
        let params = storage("fourier params", 24, U::STORAGE | U::COPY_DST);
        let bind = dev.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: self.maps.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: pts.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: occ.as_entire_binding(),
                },
            ],
        });
        Buffers {
            cap,
            pts,
            occ,
            staging,
            params,
            bind,
        }
    }

    /// Occupancy in [0, 1] at crop-NDC `points` into `out` (as [`FourierMaps::occupancy`]).
    pub fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), String> {
        let n = points.len().min(out.len());
        if n == 0 {
            return Ok(());
        }
        let mut slot = self.buffers.lock().unwrap_or_else(|p| p.into_inner());
        if slot.as_ref().is_none_or(|b| b.cap < n) {
            *slot = Some(self.buffers(n));
        }
        let b = slot.as_ref().ok_or("no buffers")?;
        let q = &self.gpu.queue;
        let mut params = vec![n as u32];
        params.extend(self.head);
        q.write_buffer(&b.params, 0, bytemuck::cast_slice(&params));
        let flat: Vec<f32> = points[..n].iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        q.write_buffer(&b.pts, 0, bytemuck::cast_slice(&flat));
        self.gpu
            .count()
            .bytes_up
            .fetch_add((n * 12) as u64, Ordering::Relaxed);
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
        self.gpu.count().dispatches.fetch_add(1, Ordering::Relaxed);
        self.gpu.count().field_runs.fetch_add(1, Ordering::Relaxed);
        let v = self.gpu.submit_and_read(enc, &b.occ, &b.staging, n)?;
        out[..n].copy_from_slice(&v);
        Ok(())
    }
}
