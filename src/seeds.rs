//! Every random stream of a run, derived from the run's seed in one place, so that each stream
//! is independent of the others and a run is reproduced by its seed alone.

/// The training copies' delay layer: warm-up actions (and random delays).
pub fn delay_layer(seed: u64) -> u64 {
    seed ^ 0xDE1A
}

/// Which replay transitions the updates draw.
pub fn replay_sampling(seed: u64) -> u64 {
    seed ^ 0x5A3B
}

/// The uniform random actions of the warm-up phase before learning starts.
pub fn warmup_phase(seed: u64) -> u64 {
    seed ^ 0x3A3
}

/// The copies (initial states and delay layer) of the `k`-th evaluation.
pub fn evaluation(seed: u64, k: u64) -> u64 {
    seed ^ 0xE7A1 ^ (k << 20)
}

/// A SAC learner's exploration and target-policy noise (networks use the seed itself).
pub fn learner_noise(seed: u64) -> u64 {
    seed ^ 0x5AC
}

/// The seed of D2HPG's delay-free learner: the same learner as a delay-free SAC seeded so.
pub fn delay_free_learner(seed: u64) -> u64 {
    seed ^ 0xA857_AC7
}

/// D2HPG's lifting-loss samples.
pub fn lifting_noise(seed: u64) -> u64 {
    seed ^ 0x11F7
}
