//! Dense evaluation: every point of the finest grid. The reference for exactness.

use super::Scratch;
use crate::field::{Evaluator, FieldError};
use crate::grid::Grid;

pub(crate) fn run(
    ev: &mut Evaluator,
    grid: &mut Grid,
    scratch: &mut Scratch,
) -> Result<(), FieldError> {
    let spec = grid.spec();
    let plane = spec.n() * spec.n();
    // One z-slab at a time keeps the index list small.
    for k in 0..spec.n() {
        scratch.list.clear();
        scratch
            .list
            .extend((k * plane..(k + 1) * plane).map(|l| l as u32));
        ev.eval_grid(grid, &scratch.list)?;
    }
    Ok(())
}
