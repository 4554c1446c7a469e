//! When the host reads the hierarchical method's conflict loop on the GPU backend
//! (`gpu/localize/plan.rs`; volcapd's `compute.round_waits`). Here, outside the `wgpu`
//! feature, so that a configuration names it on any build.

/// When the host reads the conflict loop's progress (the frames are the same either way).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RoundWaits {
    /// After each round (batches with `GpuLocalizer::with_rounds_per_wait`): a read-back per
    /// round and level (some ten a frame at 257^3). The default until a GPU measures the
    /// other (docs/bench/pipeline-gpu.md).
    #[default]
    PerRound,
    /// Once for the levels: each level's rounds predicted from the last frame's (plus a
    /// spare one over an empty list); a frame the prediction fell short of runs again
    /// (counted: `adapter_work.reruns` in `/state`). `volcap bench pipeline --round-waits
    /// per-round,per-frame` measures what it buys.
    PerFrame,
}

impl RoundWaits {
    pub const ALL: [RoundWaits; 2] = [RoundWaits::PerRound, RoundWaits::PerFrame];

    /// The config value (`volcap bench pipeline / localize --round-waits` take the same).
    pub fn name(&self) -> &'static str {
        match self {
            RoundWaits::PerRound => "per-round",
            RoundWaits::PerFrame => "per-frame",
        }
    }

    /// The value named `name` (as [`Self::name`] writes it).
    pub fn by_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|w| w.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::RoundWaits;

    #[test]
    fn names_round_trip() {
        for w in RoundWaits::ALL {
            assert_eq!(RoundWaits::by_name(w.name()), Some(w));
        }
        assert_eq!(RoundWaits::by_name("sometimes"), None);
    }
}
