//! The field the localizer evaluates on the adapter ([`GpuField`]: a host table, or the
//! Fourier head with its maps on the host or already on the adapter) and its upload.

use super::{GpuLocalizer, hold};
use crate::gpu::kit::entry;
use crate::grid::GridSpec;
use crate::model::fourier::FourierMaps;
use glam::Mat3;
use std::sync::atomic::Ordering;

/// A field the localizer evaluates on the adapter.
pub enum GpuField<'a> {
    /// One value per point of the run's grid (linear index order), evaluated by the host.
    Table(&'a [f32]),
    /// A table with seeds, points known inside in render NDC (as a CPU field's
    /// `OccupancyField::seeds`): the tests' way to reach the seeds' steps with a field the
    /// host tabulated.
    SeededTable(&'a [f32], Vec<glam::Vec3>),
    /// The Fourier head over the render view: `to_crop` maps render NDC to crop NDC, points
    /// outside the crop or where the `mask_size` x `mask_size` mask is below 0.5 are 0, the
    /// rest the series (`model/field.rs` `ModelField::occupancy`).
    Fourier {
        maps: MapsRef<'a>,
        mask: &'a [f32],
        mask_size: usize,
        to_crop: Mat3,
        /// Points known inside, in render NDC (`OccupancyField::seeds`: `ModelField`'s);
        /// evaluated at every level as the CPU's localizer does.
        seeds: Vec<glam::Vec3>,
    },
}

impl GpuField<'_> {
    /// The field's seeds (none for a plain table).
    pub fn seeds(&self) -> &[glam::Vec3] {
        match self {
            GpuField::Table(_) => &[],
            GpuField::SeededTable(_, seeds) => seeds,
            GpuField::Fourier { seeds, .. } => seeds,
        }
    }
}

/// Where a frame's Fourier maps are: on the host (written to the adapter with the field), or
/// already on the adapter (the GPU backend's frames: copied there, nothing goes up).
#[derive(Clone, Copy)]
pub enum MapsRef<'a> {
    Host(&'a FourierMaps),
    Adapter(&'a crate::gpu::maps::GpuMaps),
}

impl MapsRef<'_> {
    fn series_head(&self) -> [u32; 5] {
        match self {
            MapsRef::Host(m) => crate::gpu::fourier::series_head(m),
            MapsRef::Adapter(m) => m.head().series(),
        }
    }
}

/// The field's data as `upload_field` writes it.
enum FieldData<'a> {
    Host(&'a [f32]),
    /// A buffer on the adapter and the floats to copy from its start.
    Adapter(&'a wgpu::Buffer, usize),
}

impl FieldData<'_> {
    fn len(&self) -> usize {
        match self {
            FieldData::Host(d) => d.len(),
            FieldData::Adapter(_, n) => *n,
        }
    }
}

/// The field's buffers (grown, never shrunk).
pub(in crate::gpu) struct FieldBufs {
    pub(in crate::gpu) params: wgpu::Buffer,
    pub(in crate::gpu) maps: wgpu::Buffer,
    /// The grid's coordinates, then the mask.
    pub(in crate::gpu) aux: wgpu::Buffer,
    pub(in crate::gpu) maps_cap: usize,
    pub(in crate::gpu) aux_cap: usize,
    /// Points per axis of the grid whose coordinates `aux` holds (0: none yet).
    pub(in crate::gpu) coords_n: usize,
    pub(in crate::gpu) bind: wgpu::BindGroup,
    /// The seeds as the finest grid's linear indices after their count (`localize.wgsl`
    /// `seeds`), their capacity and bind group, and how many this frame has.
    seeds: Option<(wgpu::Buffer, usize, wgpu::BindGroup)>,
    pub(in crate::gpu) n_seeds: u32,
}

impl FieldBufs {
    /// The seeds' bind group and count, when the frame has any.
    pub(in crate::gpu) fn seeds(&self) -> Option<(&wgpu::BindGroup, u32)> {
        self.seeds
            .as_ref()
            .filter(|_| self.n_seeds > 0)
            .map(|(_, _, g)| (g, self.n_seeds))
    }
}

impl GpuLocalizer {
    /// Write the field's data (grown buffers where needed) and its bind group.
    pub(super) fn upload_field(
        &mut self,
        field: &GpuField<'_>,
        spec: GridSpec,
    ) -> Result<(), String> {
        self.pending_copy = None;
        let (data, mask, head, to_crop): (FieldData<'_>, &[f32], [u32; 6], Mat3) = match field {
            GpuField::Table(t) | GpuField::SeededTable(t, _) => {
                if t.len() != spec.len() {
                    return Err(format!(
                        "the table holds {} values for a grid of {}",
                        t.len(),
                        spec.len()
                    ));
                }
                (FieldData::Host(t), &[0.0][..], [0; 6], Mat3::IDENTITY)
            }
            GpuField::Fourier {
                maps,
                mask,
                mask_size,
                to_crop,
                ..
            } => {
                if mask.len() != mask_size * mask_size || *mask_size < 2 {
                    return Err(format!(
                        "the mask holds {} values, not {mask_size}^2",
                        mask.len()
                    ));
                }
                let s = maps.series_head();
                let head = [s[0], s[1], s[2], s[3], s[4], *mask_size as u32];
                let data = match maps {
                    MapsRef::Host(m) => FieldData::Host(m.coefficients()),
                    MapsRef::Adapter(m) => FieldData::Adapter(m.buffer(), m.head().len()),
                };
                (data, *mask, head, *to_crop)
            }
        };
        let limit = self.gpu.device.limits().max_storage_buffer_binding_size as usize;
        if data.len() * 4 > limit {
            return Err(format!(
                "the field's data of {} bytes exceed the adapter's {limit} per binding",
                data.len() * 4
            ));
        }
        let n = spec.n();
        let aux_len = n + mask.len();
        let fits = self
            .field
            .as_ref()
            .is_some_and(|f| f.maps_cap >= data.len() && f.aux_cap >= aux_len);
        if !fits {
            let old = self.field.take();
            let maps_cap = old.as_ref().map_or(0, |f| f.maps_cap).max(data.len());
            let aux_cap = old.as_ref().map_or(0, |f| f.aux_cap).max(aux_len);
            use wgpu::BufferUsages as U;
            let d = &self.gpu.device;
            let buf = |label, floats: usize, usage| {
                d.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: (floats.max(1) * 4) as u64,
                    usage: usage | U::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let params = buf("field params", hold::PARAM_WORDS, U::UNIFORM);
            // The dead band's table of quantized values, once.
            self.gpu.queue.write_buffer(
                &params,
                (hold::TABLE_AT * 4) as u64,
                bytemuck::cast_slice(&hold::table()),
            );
            self.gpu
                .count()
                .bytes_up
                .fetch_add(256 * 4, Ordering::Relaxed);
            let maps_b = buf("field data", maps_cap, U::STORAGE);
            let aux_b = buf("grid coords and mask", aux_cap, U::STORAGE);
            let bind = d.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &self.pipes.layout_field,
                entries: &[entry(0, &params), entry(1, &maps_b), entry(2, &aux_b)],
            });
            self.field = Some(FieldBufs {
                params,
                maps: maps_b,
                aux: aux_b,
                maps_cap,
                aux_cap,
                coords_n: 0,
                bind,
                seeds: old.and_then(|o| o.seeds),
                n_seeds: 0,
            });
        }
        let f = self.field.as_mut().expect("made above");
        // The seeds, as the CPU's localizer snaps them (`localize::seed_nodes`).
        let nodes: Vec<u32> = crate::localize::seed_nodes(spec, field.seeds())
            .into_iter()
            .map(|q| spec.linear(q.map(|v| v as usize)) as u32)
            .collect();
        f.n_seeds = nodes.len() as u32;
        if !nodes.is_empty() {
            if f.seeds
                .as_ref()
                .is_none_or(|(_, cap, _)| *cap < nodes.len())
            {
                let cap = nodes.len().next_power_of_two();
                let d = &self.gpu.device;
                let b = d.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("localize seeds"),
                    size: (cap as u64 + 1) * 4,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                });
                let g = d.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: None,
                    layout: &self.pipes.layout_seeds,
                    entries: &[entry(1, &b)],
                });
                f.seeds = Some((b, cap, g));
            }
            if let Some((b, _, _)) = &f.seeds {
                let mut up = vec![f.n_seeds];
                up.extend(&nodes);
                self.gpu.queue.write_buffer(b, 0, bytemuck::cast_slice(&up));
                self.gpu
                    .count()
                    .bytes_up
                    .fetch_add(up.len() as u64 * 4, Ordering::Relaxed);
            }
        }
        let mut params = [0u32; hold::TABLE_AT];
        params[..6].copy_from_slice(&head);
        for (i, v) in to_crop.to_cols_array().iter().enumerate() {
            params[8 + i] = v.to_bits();
        }
        params[hold::BAND_AT] = self.hold.band.to_bits();
        params[hold::STAMP_AT] = self.hold.frame_stamp;
        params[hold::MEMORY_AT] = Self::bit_words(spec) as u32;
        let q = &self.gpu.queue;
        q.write_buffer(&f.params, 0, bytemuck::cast_slice(&params));
        let mut up = std::mem::size_of_val(mask) + 80;
        match data {
            FieldData::Host(d) => {
                q.write_buffer(&f.maps, 0, bytemuck::cast_slice(d));
                up += std::mem::size_of_val(d);
            }
            // On the adapter already: copied there at the start of the localization's first
            // submission ([`Self::recorder`]).
            FieldData::Adapter(b, n) => self.pending_copy = Some((b.clone(), (n * 4) as u64)),
        }
        if f.coords_n != n {
            // The coordinates from the host (GridSpec::coord: the same floats as the CPU's
            // points, whatever the adapter's division), when the grid's size changes.
            let coords: Vec<f32> = (0..n).map(|i| spec.coord(i)).collect();
            q.write_buffer(&f.aux, 0, bytemuck::cast_slice(&coords));
            f.coords_n = n;
            up += n * 4;
        }
        // The mask after them.
        q.write_buffer(&f.aux, (n * 4) as u64, bytemuck::cast_slice(mask));
        self.gpu
            .count()
            .bytes_up
            .fetch_add(up as u64, Ordering::Relaxed);
        Ok(())
    }
}
