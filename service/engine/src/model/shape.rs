//! The shape model of a frame: which family a `shape-NAME` file set is, and the segmentation
//! passes it was trained on.

use super::{FourierNet, ModelError, Precision, Runtime, ShapeNets};
use std::path::Path;
use std::sync::Arc;

/// A shape model family: the paper's encoder + point MLP, or the Fourier head.
pub enum ShapeModel {
    Mlp(Arc<ShapeNets>),
    Fourier(Arc<FourierNet>),
}

impl ShapeModel {
    /// `shape-NAME.fourier.onnx` if it exists, else `shape-NAME.encoder.onnx` + `.mlp.onnx`.
    pub fn load(dir: &Path, name: &str, precision: Precision) -> Result<Self, ModelError> {
        Self::load_on(dir, name, precision, &Runtime::Tract)
    }

    /// [`ShapeModel::load`] on `rt`.
    pub fn load_on(
        dir: &Path,
        name: &str,
        precision: Precision,
        rt: &Runtime,
    ) -> Result<Self, ModelError> {
        if FourierNet::path(dir, name, precision).is_file() {
            Ok(Self::Fourier(Arc::new(FourierNet::load_on(
                dir, name, precision, rt,
            )?)))
        } else {
            Ok(Self::Mlp(Arc::new(ShapeNets::load_on(
                dir, name, precision, rt,
            )?)))
        }
    }

    /// "mlp" or "fourier".
    pub fn family(&self) -> &'static str {
        match self {
            Self::Mlp(_) => "mlp",
            Self::Fourier(_) => "fourier",
        }
    }

    /// The segmentation passes the model was trained on (a Fourier file's metadata
    /// `volcap.segment_passes`; 1 where absent and for the point-MLP family): what
    /// [`super::Models::segment_passes`] starts at, so a model is fed masks made as its training
    /// masks were unless the board or the tool says otherwise.
    pub fn trained_segment_passes(&self) -> u8 {
        match self {
            Self::Mlp(_) => 1,
            Self::Fourier(f) => f.segment_passes,
        }
    }
}

/// [`ShapeModel::trained_segment_passes`] of `shape-NAME` in `dir` at `precision` from its
/// file's metadata alone (no network is built): for the tools that set up a run per model
/// before loading it. 1 for the point-MLP family.
pub fn trained_segment_passes(
    dir: &Path,
    name: &str,
    precision: Precision,
) -> Result<u8, ModelError> {
    let path = FourierNet::path(dir, name, precision);
    if !path.is_file() {
        return Ok(1);
    }
    super::fourier::trained_segment_passes(&path, &super::meta_of(&path))
}
