//! The maps' smoothing across pixels on the adapter (`smooth_region.wgsl`, `smooth.wgsl` and
//! `smooth_keep.wgsl`, the rule of `model/fourier/smooth.rs`): after the interleave, the
//! maps copied aside, the region to smooth (two dispatches: erode, then dilate),
//! `MapsHead::smooth` passes ping-pong between the frame's maps and a buffer of the same size
//! kept with them, then the pixels that lost one of their own inside runs take their own
//! coefficients back (one dispatch), in the network's own submission, before the temporal
//! filter.

use super::super::kit::entry;
use super::super::{Gpu, groups};
use super::{FrameBufs, MapsHead};
use crate::model::fourier::{Basis, sample_basis};

const SMOOTH: &str = include_str!("smooth.wgsl");
const REGION: &str = include_str!("smooth_region.wgsl");
const KEEP: &str = include_str!("smooth_keep.wgsl");

/// The smoothing's other buffer, the maps as they came (`own`), its region's flags (eroded,
/// then the region) and bind groups (the region's two steps; the maps into the other
/// buffer, it into the maps; the kept runs, for the basis and level in `made_for`).
pub(super) struct SmoothBufs {
    tmp: wgpu::Buffer,
    own: wgpu::Buffer,
    region: [wgpu::BindGroup; 2],
    binds: [wgpu::BindGroup; 2],
    keep: wgpu::BindGroup,
    made_for: (Basis, u32),
}

impl SmoothBufs {
    fn new(
        gpu: &Gpu,
        fb: &FrameBufs,
        head: MapsHead,
        [region, smooth, keep]: [&wgpu::ComputePipeline; 3],
    ) -> Self {
        use wgpu::BufferUsages as U;
        let d = &gpu.device;
        let tmp = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("smoothed maps"),
            size: (fb.cap.max(1) * 4) as u64,
            usage: U::STORAGE | U::COPY_SRC,
            mapped_at_creation: false,
        });
        let own = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("maps before smoothing"),
            size: (fb.cap.max(1) * 4) as u64,
            usage: U::STORAGE | U::COPY_DST,
            mapped_at_creation: false,
        });
        // The buffers hold square maps of `channels` values a pixel (`MapsHead::len`).
        let size = (fb.cap / fb.channels.max(1)).isqrt();
        let flags = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("smoothed region"),
            size: (2 * size * size).max(1) as u64 * 4,
            usage: U::STORAGE,
            mapped_at_creation: false,
        });
        let params = |mode: u32| {
            wgpu::util::DeviceExt::create_buffer_init(
                d,
                &wgpu::util::BufferInitDescriptor {
                    label: Some("smooth params"),
                    contents: bytemuck::cast_slice(&[
                        fb.cap as u32,
                        fb.channels as u32,
                        size as u32,
                        crate::model::fourier::SMOOTH_INSIDE.to_bits(),
                        crate::model::fourier::SMOOTH_THIN as u32,
                        mode,
                    ]),
                    usage: U::STORAGE,
                },
            )
        };
        let (erode, open) = (params(0), params(1));
        let layout = region.get_bind_group_layout(0);
        let step = |params: &wgpu::Buffer| {
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &layout,
                entries: &[entry(0, params), entry(1, &fb.maps), entry(2, &flags)],
            })
        };
        let region = [step(&erode), step(&open)];
        let layout = smooth.get_bind_group_layout(0);
        let pass = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
            d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &layout,
                entries: &[
                    entry(0, &erode),
                    entry(1, src),
                    entry(2, dst),
                    entry(3, &flags),
                ],
            })
        };
        let binds = [pass(&fb.maps, &tmp), pass(&tmp, &fb.maps)];
        let init = |label: &str, contents: &[u8]| {
            wgpu::util::DeviceExt::create_buffer_init(
                d,
                &wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage: U::STORAGE,
                },
            )
        };
        let made_for = (head.basis, head.iso_level.to_bits());
        let keep_params = init(
            "smooth keep params",
            bytemuck::cast_slice(&[fb.channels as u32, size as u32, made_for.1]),
        );
        let table = init(
            "smooth keep depths",
            bytemuck::cast_slice(&sample_basis(head.basis, head.k)),
        );
        let keep = d.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &keep.get_bind_group_layout(0),
            entries: &[
                entry(0, &keep_params),
                entry(1, &own),
                entry(2, &fb.maps),
                entry(3, &flags),
                entry(4, &table),
            ],
        });
        SmoothBufs {
            tmp,
            own,
            region,
            binds,
            keep,
            made_for,
        }
    }
}

/// Record the region and `head.smooth` passes over `fb`'s maps into `enc` (the buffers made
/// at the first frame that smooths); the dispatches recorded.
pub(super) fn record(
    gpu: &Gpu,
    enc: &mut wgpu::CommandEncoder,
    fb: &mut FrameBufs,
    head: MapsHead,
) -> Result<u64, String> {
    if head.smooth == 0 {
        return Ok(0);
    }
    let region = gpu.pipeline("maps smooth region", REGION)?;
    let pipeline = gpu.pipeline("maps smooth", SMOOTH)?;
    let keep = gpu.pipeline("maps smooth keep", KEEP)?;
    let made_for = (head.basis, head.iso_level.to_bits());
    if fb.smooth.as_ref().is_none_or(|sb| sb.made_for != made_for) {
        fb.smooth = Some(SmoothBufs::new(gpu, fb, head, [&region, &pipeline, &keep]));
    }
    let sb = fb.smooth.as_ref().ok_or("no smoothing buffers")?;
    let len = head.len();
    enc.copy_buffer_to_buffer(&fb.maps, 0, &sb.own, 0, (len * 4) as u64);
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&region);
        let (x, y) = groups(head.pixels() as u32);
        for step in &sb.region {
            pass.set_bind_group(0, step, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        pass.set_pipeline(&pipeline);
        let (x, y) = groups(len as u32);
        for i in 0..head.smooth {
            pass.set_bind_group(0, &sb.binds[usize::from(i % 2)], &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
    // An odd count ends in the other buffer.
    if head.smooth % 2 == 1 {
        enc.copy_buffer_to_buffer(&sb.tmp, 0, &fb.maps, 0, (len * 4) as u64);
    }
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&keep);
        pass.set_bind_group(0, &sb.keep, &[]);
        let (x, y) = groups(head.pixels() as u32);
        pass.dispatch_workgroups(x, y, 1);
    }
    Ok(3 + u64::from(head.smooth))
}
