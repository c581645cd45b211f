//! What an update reports. Each statistic stays on the learner's device as one value per run of
//! the stack (or several, logged as their mean) until the training loop writes a log row; then
//! every statistic of every update since the last row comes back in one download. On a GPU that
//! is one transfer and one synchronisation per `log_every` updates instead of several per update.
use burn::prelude::Tensor;

use crate::learn::to_vec;

/// One update's statistics for the runs of a stack, a subset of the agent's
/// [`super::Agent::stat_names`] (the runs of a stack report the same ones): each as `[n, S]`,
/// n values per run that are logged as their mean (n = 1 but for statistics of several steps).
#[derive(Debug, Clone, Default)]
pub struct Stats {
    entries: Vec<(&'static str, Tensor<2>)>,
}

/// One run's statistics of one update, downloaded: `(name, value)`.
pub type RunStats = Vec<(&'static str, f64)>;

impl Stats {
    pub fn new() -> Stats {
        Stats::default()
    }

    /// `values`: `[S]`, one per run (taken off any autodiff graph).
    pub fn push(&mut self, name: &'static str, values: Tensor<1>) {
        self.entries.push((name, values.inner().unsqueeze_dim(0)));
    }

    /// `steps`: n tensors `[S]`, one per step, logged as their mean per run.
    pub fn push_mean(&mut self, name: &'static str, steps: Vec<Tensor<1>>) {
        let steps: Vec<Tensor<1>> = steps.into_iter().map(Tensor::inner).collect();
        self.entries.push((name, Tensor::stack(steps, 0)));
    }

    /// The statistics' names, in the order they were pushed.
    pub fn names(&self) -> Vec<&'static str> {
        self.entries.iter().map(|(name, _)| *name).collect()
    }

    /// The statistics of consecutive groups of runs (the passes of a stack), as one stack's.
    pub fn concat_runs(parts: Vec<Stats>) -> Stats {
        let names = parts[0].names();
        assert!(
            parts.iter().all(|part| part.names() == names),
            "the passes of a stack report the same statistics"
        );
        let mut columns: Vec<Vec<Tensor<2>>> = vec![Vec::new(); names.len()];
        for part in parts {
            for (column, (_, values)) in columns.iter_mut().zip(part.entries) {
                column.push(values);
            }
        }
        Stats {
            entries: names
                .into_iter()
                .zip(columns)
                .map(|(name, column)| (name, Tensor::cat(column, 1)))
                .collect(),
        }
    }

    /// Every run's values of each of `updates`, `[update][run]`, in one download.
    pub fn download(updates: &[Stats]) -> Vec<Vec<RunStats>> {
        let shapes: Vec<Vec<(&'static str, [usize; 2])>> = updates
            .iter()
            .map(|stats| {
                let shape = |(name, values): &(&'static str, Tensor<2>)| (*name, values.dims());
                stats.entries.iter().map(shape).collect()
            })
            .collect();
        let flat: Vec<Tensor<1>> = updates
            .iter()
            .flat_map(|stats| &stats.entries)
            .map(|(_, values)| values.clone().reshape([-1]))
            .collect();
        let values = match flat.is_empty() {
            true => Vec::new(),
            false => to_vec(Tensor::cat(flat, 0)),
        };
        let mut offset = 0;
        shapes
            .into_iter()
            .map(|entries| {
                let runs = entries.first().map_or(0, |(_, [_, runs])| *runs);
                let mut per_run: Vec<RunStats> = vec![Vec::new(); runs];
                for (name, [steps, runs]) in entries {
                    let block = &values[offset..offset + steps * runs];
                    offset += steps * runs;
                    for (run, stats) in per_run.iter_mut().enumerate() {
                        let mut sum = 0.0f64;
                        for step in 0..steps {
                            sum += f64::from(block[step * runs + run]);
                        }
                        stats.push((name, sum / steps as f64));
                    }
                }
                per_run
            })
            .collect()
    }

    /// Every run's values of this update, in one download.
    pub fn values(&self) -> Vec<RunStats> {
        Stats::download(std::slice::from_ref(self)).remove(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::matrix;

    fn runs(values: &[f32], device: &burn::prelude::Device) -> Tensor<1> {
        matrix(values.to_vec(), 1, values.len(), device).reshape([-1])
    }

    #[test]
    fn updates_come_back_per_run_with_means_of_several_steps() {
        let device = crate::learn::Devices::new(crate::learn::LearnDevice::Cpu)
            .unwrap()
            .plain;
        let mut first = Stats::new();
        first.push("loss", runs(&[1.0, 2.0], &device));
        first.push_mean(
            "kl",
            vec![runs(&[1.0, 10.0], &device), runs(&[2.0, 20.0], &device)],
        );
        let mut second = Stats::new();
        second.push("loss", runs(&[3.0], &device));
        let mut other_pass = Stats::new();
        other_pass.push("loss", runs(&[4.0], &device));
        let second = Stats::concat_runs(vec![second, other_pass]);
        let values = Stats::download(&[first, second]);
        assert_eq!(
            values,
            vec![
                vec![
                    vec![("loss", 1.0), ("kl", 1.5)],
                    vec![("loss", 2.0), ("kl", 15.0)]
                ],
                vec![vec![("loss", 3.0)], vec![("loss", 4.0)]],
            ]
        );
        assert!(Stats::download(&[]).is_empty());
    }
}
