//! Sparse probability vectors: sorted `(index, value)` lists, the accumulator that builds them, and
//! the distances used by the belief partitions (total variation, paper A.5) and the checks.

use std::cmp::Ordering;

/// A probability vector stored as `(index, probability)` pairs sorted by index; missing indices
/// have probability zero. Beliefs `b_Δ(·|x)` use this form.
pub type SparseDistribution = Vec<(usize, f64)>;

/// Builds sparse vectors by summing contributions into a dense scratch array and remembering which
/// entries were touched, so that building one vector costs time proportional to its support.
#[derive(Clone, Debug)]
pub(crate) struct SparseAccumulator {
    dense: Vec<f64>,
    seen: Vec<bool>,
    touched: Vec<usize>,
}

impl SparseAccumulator {
    /// An empty accumulator for indices `0..dimension`.
    pub(crate) fn new(dimension: usize) -> Self {
        Self {
            dense: vec![0.0; dimension],
            seen: vec![false; dimension],
            touched: Vec::new(),
        }
    }

    /// Adds `value` to entry `index`.
    pub(crate) fn add(&mut self, index: usize, value: f64) {
        if !self.seen[index] {
            self.seen[index] = true;
            self.touched.push(index);
        }
        self.dense[index] += value;
    }

    /// Returns the accumulated vector sorted by index and resets the accumulator.
    pub(crate) fn drain_sorted(&mut self) -> SparseDistribution {
        self.touched.sort_unstable();
        let out: SparseDistribution = self.touched.iter().map(|&i| (i, self.dense[i])).collect();
        for &i in &self.touched {
            self.dense[i] = 0.0;
            self.seen[i] = false;
        }
        self.touched.clear();
        out
    }
}

/// Walks the union of the supports of two sorted sparse vectors, calling `visit(index, a, b)` with
/// `None` where a vector has no entry.
pub(crate) fn merge_union<A: Copy, B: Copy>(
    a: &[(usize, A)],
    b: &[(usize, B)],
    mut visit: impl FnMut(usize, Option<A>, Option<B>),
) {
    let (mut i, mut j) = (0, 0);
    loop {
        match (a.get(i), b.get(j)) {
            (Some(&(ka, va)), Some(&(kb, vb))) => match ka.cmp(&kb) {
                Ordering::Less => {
                    visit(ka, Some(va), None);
                    i += 1;
                }
                Ordering::Greater => {
                    visit(kb, None, Some(vb));
                    j += 1;
                }
                Ordering::Equal => {
                    visit(ka, Some(va), Some(vb));
                    i += 1;
                    j += 1;
                }
            },
            (Some(&(ka, va)), None) => {
                visit(ka, Some(va), None);
                i += 1;
            }
            (None, Some(&(kb, vb))) => {
                visit(kb, None, Some(vb));
                j += 1;
            }
            (None, None) => break,
        }
    }
}

/// `Σ_i |a_i − b_i|` for two sorted sparse vectors.
pub(crate) fn l1_distance(a: &[(usize, f64)], b: &[(usize, f64)]) -> f64 {
    let mut total = 0.0;
    merge_union(a, b, |_, x, y| {
        total += (x.unwrap_or(0.0) - y.unwrap_or(0.0)).abs()
    });
    total
}

/// `max_i |a_i − b_i|` for two sorted sparse vectors.
pub(crate) fn max_abs_difference(a: &[(usize, f64)], b: &[(usize, f64)]) -> f64 {
    let mut largest = 0.0f64;
    merge_union(a, b, |_, x, y| {
        largest = largest.max((x.unwrap_or(0.0) - y.unwrap_or(0.0)).abs())
    });
    largest
}

/// Total-variation distance `‖a − b‖_TV = ½ Σ_s |a(s) − b(s)|` between two sparse distributions
/// sorted by index (the distance of the ε-abstract partition, paper section 3.2 and A.5).
pub fn total_variation(a: &[(usize, f64)], b: &[(usize, f64)]) -> f64 {
    0.5 * l1_distance(a, b)
}
