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

/// A stream an algorithm names itself (e.g. `"vdpo/belief"`), for the streams of one
/// algorithm's file: the name's FNV-1a hash mixed into the seed by SplitMix64's finaliser,
/// so that different names give unrelated streams.
pub fn named(seed: u64, stream: &str) -> u64 {
    let hash = stream.bytes().fold(0xCBF2_9CE4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01B3)
    });
    let mut z = (seed ^ hash).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
