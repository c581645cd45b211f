//! rliable's aggregate statistics (Agarwal et al., "Deep RL at the Edge of the Statistical
//! Precipice", NeurIPS 2021): the interquartile mean of normalised scores, the probability of
//! improvement, and stratified-bootstrap confidence intervals for both (runs resampled with
//! replacement within each task).
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Scores of one algorithm, one list of runs per task (the strata).
pub type Strata = Vec<Vec<f64>>;

/// The mean of the middle half: a quarter of the scores (rounded down) cut from each end, as
/// rliable's `scipy.stats.trim_mean(scores, 0.25)` does.
pub fn iqm(scores: &[f64]) -> f64 {
    let mut sorted = scores.to_vec();
    sorted.sort_by(f64::total_cmp);
    let cut = sorted.len() / 4;
    let middle = &sorted[cut..sorted.len() - cut];
    middle.iter().sum::<f64>() / middle.len() as f64
}

/// The IQM over every run of every task.
pub fn iqm_of_strata(strata: &Strata) -> f64 {
    iqm(&strata.iter().flatten().copied().collect::<Vec<_>>())
}

/// `P(X > Y)`: for each task the share of run pairs (x from X, y from Y) with x > y, ties
/// counting half, averaged over the tasks (rliable's `probability_of_improvement`).
pub fn probability_of_improvement(x: &Strata, y: &Strata) -> f64 {
    let per_task: Vec<f64> = x
        .iter()
        .zip(y)
        .map(|(xs, ys)| {
            let wins: f64 = xs
                .iter()
                .flat_map(|a| ys.iter().map(move |b| (a, b)))
                .map(|(a, b)| {
                    if a > b {
                        1.0
                    } else if a == b {
                        0.5
                    } else {
                        0.0
                    }
                })
                .sum();
            wins / (xs.len() * ys.len()) as f64
        })
        .collect();
    per_task.iter().sum::<f64>() / per_task.len() as f64
}

/// The strata resampled: each task's runs drawn with replacement, as many as it has.
fn resample(strata: &Strata, rng: &mut ChaCha8Rng) -> Strata {
    strata
        .iter()
        .map(|runs| {
            (0..runs.len())
                .map(|_| runs[rng.random_range(0..runs.len())])
                .collect()
        })
        .collect()
}

/// The 2.5 and 97.5 percentiles of `statistic` over `reps` stratified-bootstrap resamples of
/// `groups` (each resampled on its own), from a fixed seed so that a report is reproducible.
pub fn bootstrap_interval(
    groups: &[&Strata],
    reps: usize,
    seed: u64,
    statistic: impl Fn(&[Strata]) -> f64,
) -> (f64, f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut values: Vec<f64> = (0..reps)
        .map(|_| {
            let drawn: Vec<Strata> = groups.iter().map(|g| resample(g, &mut rng)).collect();
            statistic(&drawn)
        })
        .collect();
    values.sort_by(f64::total_cmp);
    (percentile(&values, 2.5), percentile(&values, 97.5))
}

/// Linear-interpolated percentile of sorted values (numpy's default).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let position = q / 100.0 * (sorted.len() - 1) as f64;
    let (low, high) = (position.floor() as usize, position.ceil() as usize);
    sorted[low] + (sorted[high] - sorted[low]) * (position - low as f64)
}

/// Mean and population standard deviation, as Table 1 reports over seeds.
pub fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Resampling stays within each task: two tasks whose runs all score 0.2 and 0.8 give
    /// every resample the same IQM, 0.5, so the interval is exactly (0.5, 0.5); runs pooled
    /// across tasks would spread it.
    #[test]
    fn the_bootstrap_resamples_within_each_task() {
        let strata: Strata = vec![vec![0.2; 4], vec![0.8; 4]];
        let (low, high) = bootstrap_interval(&[&strata], 2000, 1, |s| iqm_of_strata(&s[0]));
        assert_eq!((low, high), (0.5, 0.5));
    }

    /// The interval is the 2.5 and 97.5 percentiles of the resampled statistic: checked
    /// against the same distribution drawn here independently (the mean of 10 draws from
    /// 0..=9: its 2.5 and 5 percentiles are ~2.7 and ~3.0, so a 5/95 interval fails).
    #[test]
    fn the_interval_is_the_central_95_percent() {
        let runs: Vec<f64> = (0..10).map(f64::from).collect();
        let strata: Strata = vec![runs.clone()];
        let mean = |s: &[Strata]| s[0][0].iter().sum::<f64>() / s[0][0].len() as f64;
        let (low, high) = bootstrap_interval(&[&strata], 50_000, 3, mean);
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let mut independent: Vec<f64> = (0..200_000)
            .map(|_| (0..10).map(|_| runs[rng.random_range(0..10)]).sum::<f64>() / 10.0)
            .collect();
        independent.sort_by(f64::total_cmp);
        let (expected_low, expected_high) = (
            percentile(&independent, 2.5),
            percentile(&independent, 97.5),
        );
        assert!((low - expected_low).abs() < 0.06, "{low} vs {expected_low}");
        assert!(
            (high - expected_high).abs() < 0.06,
            "{high} vs {expected_high}"
        );
        assert!(
            expected_low < 2.85 && expected_high > 6.15,
            "{expected_low} {expected_high}"
        );
    }
}
