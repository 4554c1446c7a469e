//! volcap's scene simulator: synthetic performances with exact ground truth.
//!
//! * [`makehuman`]: readers for the full MakeHuman CC0 data (used to build the pack and
//!   datasets).
//! * [`assets`]: the in-memory human assets and the compact runtime pack (embedded).
//! * [`subject`]: shape (macro model), skeleton, linear blend skinning, garment fitting.
//! * [`pose`]: static poses and the seeded procedural pose generator with joint limits.
//! * [`camera`], [`raster`]: weak-perspective/pinhole cameras and the CPU rasterizer.
//! * [`scene`]: declarative scene files; [`effects`]: the stages built from their `effect`
//!   list (only declared effects run).
//! * [`oracle`]: occupancy and colour ground truth for arbitrary points, usable as engine
//!   fields; [`rays`]: per-pixel inside intervals along camera rays (Fourier supervision).
//! * [`sim`]: the [`Simulator`] tying them together; [`dataset`]: training shards.

pub mod assets;
pub mod camera;
pub mod dataset;
pub mod effects;
pub mod files;
pub mod hands;
pub mod makehuman;
pub mod oracle;
pub mod parts;
pub mod pose;
pub mod raster;
pub mod rays;
pub mod scene;
pub mod shards;
pub mod sim;
pub mod subject;

pub use assets::HumanAssets;
pub use scene::Scene;
pub use sim::{SimError, SimFrame, Simulator};
