//! Finite-domain DHRL (paper section 3 and appendix A): delayed MDPs, their augmented MDPs, the
//! belief-equivalence abstraction and the paper's guarantees, checked exactly on finite MDPs.
//!
//! * [`FiniteMdp`]: a validated finite MDP `(S, A, P, R, γ)`, read from JSON ([`MdpFile`]) or
//!   generated ([`random_mdp`]).
//! * [`AugmentedMdp`]: the regular MDP `M_Δ` over `X = S × A^Δ` with `P_Δ`, the belief
//!   `b_Δ(·|x)` and `R_Δ(x, a) = E_{b_Δ(·|x)}[R(s, a)]`; refuses `|X|` above [`SizeLimits`].
//! * [`belief_partition`] (Definition 3.2) and [`approximate_belief_partition`] (ε under total
//!   variation, appendix A.5) give a [`Partition`], i.e. the state map `f: X → X̄`.
//! * [`QuotientMdp`]: the abstract MDP of a partition (appendix A.5 weights, uniform by default),
//!   with `f`, the identity action map `g` and policy lifting.
//! * [`check_homomorphism`] (reward-respecting and SSP, Prop. 3.3), [`Partition::compression_ratio`]
//!   (Prop. 3.5), [`evaluate_abstraction`] (Cor. 3.4) and [`value_loss_bound`] (Lemma 3.7).
//! * [`value_iteration`], [`evaluate_policy`] and [`q_learning`] run on any [`TabularModel`];
//!   [`DelayedEnv`] simulates the delayed process for Q-learning; [`run_bench`] is the
//!   sample-complexity experiment of `dhrl tabular-bench` (Cor. 3.6).
//!
//! The exact belief partition identifies beliefs after rounding every probability to a multiple of
//! `2^-40`; see [`belief_partition`].

mod analysis;
mod augmented;
mod bench;
mod bound;
mod checks;
mod cli;
mod environment;
mod error;
mod generate;
mod mdp;
mod model;
mod partition;
mod plot;
mod qlearning;
mod quotient;
mod solve;
mod sparse;

pub use analysis::{
    AbstractionQuality, AnalysisOptions, ApproximateReport, TabularReport, analyze,
    evaluate_abstraction,
};
pub use augmented::{AugmentedMdp, DEFAULT_MAX_AUGMENTED_STATES, SizeLimits};
pub use bench::{BenchConfig, BenchReport, BenchRow, SampleStats, run_bench};
pub use bound::{ValueLossBound, value_loss_bound};
pub use checks::{CHECK_TOLERANCE, HomomorphismCheck, check_homomorphism};
pub use cli::{TabularArgs, TabularBenchArgs, run_tabular, run_tabular_bench};
pub use environment::{DelayedEnv, Environment, ModelEnv};
pub use error::TabularError;
pub use generate::{RandomMdpSpec, random_mdp};
pub use mdp::{FiniteMdp, MdpFile, ROW_SUM_TOLERANCE};
pub use model::TabularModel;
pub use partition::{Partition, approximate_belief_partition, belief_partition};
pub use plot::write_bench_plot;
pub use qlearning::{QLearningConfig, QLearningRun, QTable, q_learning};
pub use quotient::QuotientMdp;
pub use solve::{SolveOptions, ValueSolution, evaluate_policy, value_iteration};
pub use sparse::{SparseDistribution, total_variation};
