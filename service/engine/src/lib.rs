//! volcap's engine: pure compute, no async, no sockets, no devices.
//!
//! * [`grid`]: the coordinate convention, integer-indexed grids and bitsets.
//! * [`field`]: occupancy/colour field traits and the counted, checked evaluation path.
//! * [`analytic`]: analytic scenes with exact ground truth.
//! * [`localize`]: dense, MISE, PIFu threshold octree, the paper's hierarchical method and
//!   our variants.
//! * [`render`]: mesh-free rendering with shadow-node culling.
//! * [`sides`]: grid values held across frames (the surface's dead band).
//! * [`mesh`]: marching cubes, binary PLY and glTF (.glb) export.
//! * [`metrics`]: IoU, connected components, band bound, Chamfer and point-to-surface.
//! * [`softz`]: the SoftZ depth encoding.
//! * [`model`]: the trained networks (ONNX via tract) as occupancy and colour fields.
//! * [`gpu`] (feature `wgpu`): the GPU backend, WGSL compute kernels on one adapter.

pub mod analytic;
pub mod field;
#[cfg(feature = "wgpu")]
pub mod gpu;
pub mod grid;
pub mod localize;
mod mc_tables;
pub mod mesh;
pub mod metrics;
pub mod model;
pub mod pieces;
pub mod render;
pub mod sides;
pub mod softz;

pub use field::{ColorField, FieldError, OccupancyField};
pub use grid::{Grid, GridSpec, ISO, is_inside};
pub use localize::{LocalizeStats, Localizer, Method};
