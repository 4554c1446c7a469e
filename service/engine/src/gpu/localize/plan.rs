//! How the host waits for the conflict loop's rounds: after each round (the lists' lengths
//! read back: exact, a read-back per round), or once a frame with each level's rounds
//! predicted from the last frame's ([`RoundWaits::PerFrame`], `localize/waits.rs`).
//!
//! Predicted, a level is recorded with the rounds the same level took last frame plus
//! [`SPARE_ROUNDS`] (a round over an empty list lists, evaluates and counts nothing:
//! `prep_round`), then `check_round` raises the miss flag if the last of them still listed
//! points, i.e. the loop had more to do. The whole frame then goes to the adapter in one
//! submission. A frame whose flag is up is run again (its values would differ from the
//! CPU's): first with each level's rounds at least those it ran and [`MISS_SPARE_ROUNDS`]
//! more, and if that falls short too, waiting per round; the completed run's rounds are
//! the next frame's prediction. Frames
//! of one scene change little from one to the next, so most frames wait once where they
//! waited once per round and level (13 times at 257^3 from level 3; each wait a round trip
//! that on a GPU shared with the networks cost about 0.5 ms: docs/bench/pipeline-gpu.md).

use super::{COUNTS, LEVEL_ROUNDS};
use crate::grid::GridSpec;
use crate::localize::{HierarchicalMode, RoundWaits};

/// Rounds recorded beyond the last frame's at each level when predicting.
pub const SPARE_ROUNDS: u32 = 1;

/// Rounds recorded beyond those a frame ran when it is run again after a miss.
pub const MISS_SPARE_ROUNDS: u32 = 3;

/// Levels the per-level round counters tell apart (by the level's stride exponent: 0 is the
/// finest; a 2^16 + 1 grid would need 17).
pub const LEVEL_KEYS: usize = 16;

/// The slot of level `l`'s round counter in a grid of `spec`.
pub(super) fn level_key(spec: GridSpec, l: u32) -> usize {
    (spec.level().saturating_sub(l) as usize).min(LEVEL_KEYS - 1)
}

/// The last frame's rounds per level, for the next frame's plan.
#[derive(Debug, Default)]
pub(in crate::gpu) struct Predictor {
    pub(super) waits: RoundWaits,
    /// The grid, coarse level and mode the rounds were counted on.
    seen: Option<(GridSpec, u32, HierarchicalMode)>,
    rounds: [u32; LEVEL_KEYS],
    /// Plans of this frame that fell short: after one, a plan with more spare rounds; after
    /// two, waiting per round.
    misses: u8,
}

impl Predictor {
    pub(super) fn new(waits: RoundWaits) -> Self {
        Predictor {
            waits,
            ..Default::default()
        }
    }

    /// Loop iterations to record per level key, or `None`: wait per round (the first frame
    /// of a grid, coarse level or mode, and a frame run again after two misses).
    pub(super) fn plan(
        &self,
        spec: GridSpec,
        coarse: u32,
        mode: HierarchicalMode,
    ) -> Option<[u32; LEVEL_KEYS]> {
        if self.waits != RoundWaits::PerFrame || self.seen != Some((spec, coarse, mode)) {
            return None;
        }
        let spare = match self.misses {
            0 => SPARE_ROUNDS,
            1 => SPARE_ROUNDS + MISS_SPARE_ROUNDS,
            _ => return None,
        };
        // A level whose loop found nothing still scans once (the first conflict's list).
        Some(self.rounds.map(|r| r.max(1) + spare))
    }

    /// A frame completed with these counters: its rounds are the next plan.
    pub(in crate::gpu) fn learn(
        &mut self,
        spec: GridSpec,
        coarse: u32,
        mode: HierarchicalMode,
        counts: &[u32; COUNTS],
    ) {
        self.seen = Some((spec, coarse, mode));
        self.rounds
            .copy_from_slice(&counts[LEVEL_ROUNDS..LEVEL_ROUNDS + LEVEL_KEYS]);
        self.misses = 0;
    }

    /// The plan fell short, the levels having run `seen` rounds: the frame is run again
    /// with at least those and more spare, or after a second miss waiting per round.
    pub(super) fn missed(&mut self, seen: &[u32; LEVEL_KEYS]) {
        for (r, s) in self.rounds.iter_mut().zip(seen) {
            *r = (*r).max(*s);
        }
        self.misses = self.misses.saturating_add(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_needs_a_frame_of_the_same_grid_and_is_dropped_after_a_miss() {
        let spec = GridSpec::from_resolution(65).unwrap();
        let mode = HierarchicalMode::Paper;
        let mut p = Predictor::new(RoundWaits::PerFrame);
        assert_eq!(p.plan(spec, 3, mode), None, "no frame seen");
        let mut counts = [0u32; COUNTS];
        counts[LEVEL_ROUNDS + level_key(spec, 5)] = 3;
        counts[LEVEL_ROUNDS + level_key(spec, 6)] = 0;
        p.learn(spec, 3, mode, &counts);
        let plan = p.plan(spec, 3, mode).unwrap();
        assert_eq!(plan[level_key(spec, 5)], 3 + SPARE_ROUNDS);
        assert_eq!(plan[level_key(spec, 6)], 1 + SPARE_ROUNDS);
        assert_eq!(p.plan(spec, 2, mode), None, "another coarse level");
        assert_eq!(
            p.plan(spec, 3, HierarchicalMode::Tight),
            None,
            "another mode"
        );
        let other = GridSpec::from_resolution(33).unwrap();
        assert_eq!(p.plan(other, 3, mode), None, "another grid");
        let mut seen = [0; LEVEL_KEYS];
        seen[level_key(spec, 5)] = 6;
        p.missed(&seen);
        let again = p.plan(spec, 3, mode).unwrap();
        let boost = SPARE_ROUNDS + MISS_SPARE_ROUNDS;
        assert_eq!(
            again[level_key(spec, 5)],
            6 + boost,
            "at least the rounds run"
        );
        assert_eq!(again[level_key(spec, 6)], 1 + boost);
        p.missed(&seen);
        assert_eq!(p.plan(spec, 3, mode), None, "after a second miss");
        p.learn(spec, 3, mode, &counts);
        assert_eq!(
            p.plan(spec, 3, mode),
            Some(plan),
            "a completed frame's rounds"
        );
        assert!(p.plan(spec, 3, mode).is_some());
        p.waits = RoundWaits::PerRound;
        assert_eq!(p.plan(spec, 3, mode), None, "waiting per round");
    }

    #[test]
    fn level_keys_are_stride_exponents() {
        let spec = GridSpec::from_resolution(257).unwrap();
        assert_eq!(level_key(spec, spec.level()), 0);
        assert_eq!(level_key(spec, 3), spec.level() as usize - 3);
    }
}
