//! How the grid's values lie over storage bindings ([`Tiling`]), and the localizer's other
//! limits: the grid's size against the adapter's storage buffers, the index lists' growth
//! within one binding.

use super::{GpuLocalizer, grid_bytes};
use crate::gpu::kit::entry;
use crate::grid::GridSpec;

const MIB: f64 = (1u64 << 20) as f64;

/// The binding of the values' second tile (the first is binding 1), then one each.
const TILE_BINDING: u32 = 16;

/// Storage bindings per stage that the localization's kernels take besides the values'
/// (the lists, bits and counts, and the field's maps and mask in the evaluation kernels).
const OTHER_STORAGE: u32 = 7;

/// How a grid's values are laid over storage bindings: `tiles` buffers of `1 << shift`
/// floats (the last one shorter), point `q` at `q & ((1 << shift) - 1)` of tile
/// `q >> shift`. One tile is the whole grid in one binding, as before tiling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tiling {
    pub shift: u32,
    pub tiles: u32,
}

impl Tiling {
    /// The whole grid in one binding.
    pub const ONE: Tiling = Tiling {
        shift: 31,
        tiles: 1,
    };

    /// Tiles for `len` floats where a binding holds `max_floats` at most: one tile if it
    /// fits, else tiles of the largest power of two floats within the limit.
    pub fn new(len: usize, max_floats: u64) -> Tiling {
        if len as u64 <= max_floats {
            return Tiling::ONE;
        }
        let shift = 63 - max_floats.max(1).leading_zeros();
        Tiling {
            shift,
            tiles: (len as u64).div_ceil(1 << shift) as u32,
        }
    }

    /// Floats in tile `t` of a grid of `len`.
    pub(super) fn tile_len(&self, t: u32, len: usize) -> usize {
        if self.tiles == 1 {
            return len;
        }
        let per = 1usize << self.shift;
        len.saturating_sub(t as usize * per).min(per)
    }

    fn binding(t: u32) -> u32 {
        if t == 0 { 1 } else { TILE_BINDING + t - 1 }
    }

    /// The layout entries of the tiles (binding 1, then [`TILE_BINDING`] on).
    pub(in crate::gpu) fn layout_entries(
        &self,
        read_only: bool,
    ) -> Vec<wgpu::BindGroupLayoutEntry> {
        (0..self.tiles)
            .map(|t| crate::gpu::kit::storage(Self::binding(t), read_only))
            .collect()
    }

    /// Bind group entries of `tiles` (one buffer per tile).
    pub(in crate::gpu) fn entries<'b>(
        &self,
        tiles: &'b [wgpu::Buffer],
    ) -> Vec<wgpu::BindGroupEntry<'b>> {
        tiles
            .iter()
            .enumerate()
            .map(|(t, b)| entry(Self::binding(t as u32), b))
            .collect()
    }

    /// WGSL ahead of a kernel source: the tiles' bindings, `vget(q)` and (`writable`)
    /// `vset(q, v)`.
    pub(in crate::gpu) fn wgsl(&self, writable: bool) -> String {
        use std::fmt::Write;
        let access = if writable { "read_write" } else { "read" };
        let name = |t: u32| {
            if t == 0 {
                "values".to_string()
            } else {
                format!("values_{t}")
            }
        };
        let mut w = String::new();
        for t in 0..self.tiles {
            let _ = writeln!(
                w,
                "@group(0) @binding({}) var<storage, {access}> {}: array<f32>;",
                Self::binding(t),
                name(t)
            );
        }
        if self.tiles == 1 {
            w.push_str("fn vget(q: u32) -> f32 { return values[q]; }\n");
            if writable {
                w.push_str("fn vset(q: u32, v: f32) { values[q] = v; }\n");
            }
            return w;
        }
        let (shift, mask) = (self.shift, (1u64 << self.shift) - 1);
        let cases = |body: &dyn Fn(&str) -> String| {
            let mut c = String::new();
            for t in 1..self.tiles {
                let _ = writeln!(c, "        case {t}u: {{ {} }}", body(&name(t)));
            }
            let _ = writeln!(c, "        default: {{ {} }}", body("values"));
            c
        };
        let _ = write!(
            w,
            "fn vget(q: u32) -> f32 {{\n    let o = q & {mask}u;\n    switch q >> {shift}u {{\n{}    }}\n}}\n",
            cases(&|v| format!("return {v}[o];"))
        );
        if writable {
            let _ = write!(
                w,
                "fn vset(q: u32, x: f32) {{\n    let o = q & {mask}u;\n    switch q >> {shift}u {{\n{}    }}\n}}\n",
                cases(&|v| format!("{v}[o] = x;"))
            );
        }
        w
    }
}

impl GpuLocalizer {
    /// The most bytes one storage binding holds here (a buffer's size bounds it too).
    pub(super) fn binding_bytes(&self) -> u64 {
        let limits = self.gpu.device.limits();
        limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
    }

    /// Tiles of the values of at most `n` floats (a power of two at most; the adapter's
    /// binding limit bounds them anyway): the tests tile small grids with it, so that the
    /// tiled kernels run where a binding would hold the whole grid.
    pub fn with_tile_floats(mut self, n: usize) -> Self {
        self.tile_floats = Some(n.max(1) as u64);
        self.bufs = None;
        self
    }

    /// How a grid of `spec` lays its values over storage bindings here.
    pub fn tiling(&self, spec: GridSpec) -> Tiling {
        let floats = (self.binding_bytes() / 4).min(self.tile_floats.unwrap_or(u64::MAX));
        Tiling::new(spec.len(), floats)
    }

    /// Lists of at most `n` entries (one storage binding bounds them anyway; the tests make
    /// the bound small to reach it).
    pub fn with_max_list_entries(mut self, n: usize) -> Self {
        self.max_list = Some(n.max(1));
        self.bufs = None;
        self
    }

    /// Whether a grid of `spec` fits the adapter's limits: its values in as many storage
    /// bindings as the adapter's binding size needs ([`Self::tiling`]), with the kernels'
    /// other storage buffers, within the adapter's storage buffers per stage. The error
    /// names the sizes.
    pub fn check_size(&self, spec: GridSpec) -> Result<(), String> {
        let t = self.tiling(spec);
        let limits = self.gpu.device.limits();
        let per_stage = limits.max_storage_buffers_per_shader_stage;
        // Bindings are numbered below the group's limit too (tile t > 0 at 15 + t).
        let max_tiles = per_stage.saturating_sub(OTHER_STORAGE).min(
            limits
                .max_bindings_per_bind_group
                .saturating_sub(TILE_BINDING - 1),
        );
        if t.tiles > max_tiles {
            let n = spec.n();
            return Err(format!(
                "a {n}^3 grid needs {:.1} MiB of values in {} storage bindings of at most \
                 {:.1} MiB, more than the {max_tiles} that the adapter's {per_stage} storage \
                 buffers per stage leave beside the localization's other {OTHER_STORAGE} \
                 (localize it on the CPU)",
                grid_bytes(spec) as f64 / MIB,
                t.tiles,
                (4u64 << t.shift).min(grid_bytes(spec)) as f64 / MIB,
            ));
        }
        Ok(())
    }

    /// After a list overflowed: lists four times larger (up to the grid's size).
    pub(in crate::gpu) fn grow(&mut self, spec: GridSpec) -> Result<(), String> {
        if self.cap >= spec.len() {
            return Err("the index lists overflowed at the grid's size".into());
        }
        let next = (self.cap * 4).min(spec.len()).min(self.list_bound());
        if next <= self.cap {
            // Not a wgpu validation error (a panic) on a buffer over the binding limit.
            return Err(format!(
                "this {}^3 frame needs index lists of more than {} entries, the most one \
                 storage binding holds here (localize it on the CPU)",
                spec.n(),
                self.cap
            ));
        }
        self.cap = next;
        Ok(())
    }

    /// Entries an index list may hold: the largest buffer per entry (the renderer's lists,
    /// three pairs of words an entry, else a list's pair) within one storage binding, or
    /// [`Self::with_max_list_entries`].
    pub(super) fn list_bound(&self) -> usize {
        let per_entry = if self.render { 24 } else { 8 };
        usize::try_from(self.binding_bytes() / per_entry)
            .unwrap_or(usize::MAX)
            .min(self.max_list.unwrap_or(usize::MAX))
            .max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::Tiling;

    #[test]
    fn tiles_are_the_largest_power_of_two_within_the_binding_and_cover_the_grid() {
        let len = 513usize * 513 * 513;
        // A 128 MiB binding (lavapipe's): five tiles of 2^25 floats, the last one short.
        let t = Tiling::new(len, (128 << 20) / 4);
        assert_eq!(
            t,
            Tiling {
                shift: 25,
                tiles: 5
            }
        );
        let lens: Vec<usize> = (0..t.tiles).map(|i| t.tile_len(i, len)).collect();
        assert_eq!(lens.iter().sum::<usize>(), len);
        assert!(lens[..4].iter().all(|&l| l == 1 << 25));
        assert_eq!(lens[4], len - 4 * (1 << 25));
        // A limit that is not a power of two: tiles of the power of two below it.
        assert_eq!(
            Tiling::new(1000, 100),
            Tiling {
                shift: 6,
                tiles: 16
            }
        );
        assert_eq!(Tiling::new(1000, 100).tile_len(15, 1000), 1000 - 15 * 64);
        // A grid that fits: one tile, the whole grid.
        assert_eq!(Tiling::new(len, len as u64), Tiling::ONE);
        assert_eq!(Tiling::ONE.tile_len(0, len), len);
    }

    #[test]
    fn the_tiles_wgsl_declares_each_binding_and_routes_by_the_high_bits() {
        let one = Tiling::ONE.wgsl(true);
        assert!(one.contains("@binding(1) var<storage, read_write> values: array<f32>;"));
        assert!(one.contains("fn vset"));
        assert!(!Tiling::ONE.wgsl(false).contains("fn vset"));
        let t = Tiling {
            shift: 16,
            tiles: 3,
        };
        let w = t.wgsl(false);
        assert!(
            w.contains("@binding(1) var<storage, read> values: array<f32>;"),
            "{w}"
        );
        assert!(
            w.contains("@binding(16) var<storage, read> values_1"),
            "{w}"
        );
        assert!(
            w.contains("@binding(17) var<storage, read> values_2"),
            "{w}"
        );
        assert!(w.contains("q & 65535u") && w.contains("q >> 16u"), "{w}");
        assert!(w.contains("case 2u: { return values_2[o]; }"), "{w}");
        assert!(!w.contains("fn vset"), "{w}");
        // (Compiled with the kernels by the adapter in tests/gpu.rs.)
    }
}
