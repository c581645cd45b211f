//! One call that checks the paper's section-3 guarantees on a given MDP and delay: the exact
//! belief abstraction (Prop. 3.3, Prop. 3.5, Cor. 3.4) and, optionally, an ε-abstraction with
//! the Lemma 3.7 bound. This is what `dhrl tabular` prints.

use serde::Serialize;

use crate::augmented::{AugmentedMdp, SizeLimits};
use crate::bound::value_loss_bound;
use crate::checks::{CHECK_TOLERANCE, check_homomorphism};
use crate::error::TabularError;
use crate::mdp::FiniteMdp;
use crate::model::TabularModel;
use crate::partition::{approximate_belief_partition, belief_partition, validate_epsilon};
use crate::quotient::QuotientMdp;
use crate::solve::{SolveOptions, evaluate_policy, value_iteration};

/// How well an abstract MDP stands in for the model it was built from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AbstractionQuality {
    /// `max_x |V*_M(x) − V*_M̄(f(x))|` (zero for an exact homomorphism, Cor. 3.4).
    pub max_value_gap: f64,
    /// `max_x (V*_M(x) − V^{π↑}_M(x))` for the lifted optimal abstract policy `π↑ = π̄* ∘ f`,
    /// evaluated on `M` (zero when lifting preserves optimality; bounded by Lemma 3.7). Clamped
    /// at zero: it is non-negative up to the solver tolerance.
    pub lifted_policy_value_loss: f64,
}

/// Solves the quotient, lifts its optimal policy and evaluates it on `model`, whose optimal values
/// are `optimal_values`.
///
/// # Errors
/// [`TabularError::ShapeMismatch`] for inconsistent sizes, and solver errors.
pub fn evaluate_abstraction<M: TabularModel>(
    model: &M,
    optimal_values: &[f64],
    quotient: &QuotientMdp,
    options: &SolveOptions,
) -> Result<AbstractionQuality, TabularError> {
    if optimal_values.len() != model.num_states() {
        return Err(TabularError::ShapeMismatch {
            location: "optimal values".to_string(),
            found: optimal_values.len(),
            expected: model.num_states(),
            unit: "values (one per state)",
        });
    }
    let abstract_solution = value_iteration(quotient.abstract_mdp(), options)?;
    let lifted = quotient.lift_policy(&abstract_solution.policy)?;
    let lifted_values = evaluate_policy(model, &lifted, None, options)?;
    let mut max_value_gap = 0.0f64;
    let mut lifted_policy_value_loss = 0.0f64;
    for (x, &optimal) in optimal_values.iter().enumerate() {
        let abstract_value = abstract_solution.values[quotient.state_map(x)];
        max_value_gap = max_value_gap.max((optimal - abstract_value).abs());
        lifted_policy_value_loss = lifted_policy_value_loss.max(optimal - lifted_values[x]);
    }
    Ok(AbstractionQuality {
        max_value_gap,
        lifted_policy_value_loss,
    })
}

/// Settings of [`analyze`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalysisOptions {
    /// Also build the ε-abstract partition and report the Lemma 3.7 bound.
    pub epsilon: Option<f64>,
    /// Size limit of the augmented MDP.
    pub limits: SizeLimits,
    /// Accuracy of value iteration and policy evaluation.
    pub solve: SolveOptions,
    /// Tolerance of the reward-respecting and SSP checks.
    pub check_tolerance: f64,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            epsilon: None,
            limits: SizeLimits::default(),
            solve: SolveOptions::default(),
            check_tolerance: CHECK_TOLERANCE,
        }
    }
}

/// The ε-abstraction part of a [`TabularReport`] (Lemma 3.7).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ApproximateReport {
    /// The total-variation radius ε.
    pub epsilon: f64,
    /// `|X̄_ε|`.
    pub approx_abstract_states: usize,
    /// `|X̄_ε| / |X|`.
    pub approx_compression_ratio: f64,
    /// Reward discrepancy `C1`.
    pub c1: f64,
    /// Transition discrepancy `C2`.
    pub c2: f64,
    /// Abstract reward range `ξ_ε`.
    pub xi: f64,
    /// The Lemma 3.7 bound `2/(1−γ)(C1 + γ ξ C2 / (2(1−γ)))`.
    pub value_loss_bound: f64,
    /// The measured loss it bounds: `‖V* − V^{(π̄*_ε)↑}‖_∞` on the augmented MDP.
    pub approx_lifted_policy_value_loss: f64,
    /// `max_x |V*(x) − V̄*_ε(f(x))|`.
    pub approx_max_value_gap: f64,
}

/// Everything `dhrl tabular` reports about a delayed MDP.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TabularReport {
    /// `|S|`.
    pub states: usize,
    /// `|A|`.
    pub actions: usize,
    /// `Δ`.
    pub delay: usize,
    /// `γ`.
    pub gamma: f64,
    /// Whether `P` is deterministic (the setting of Prop. 3.3 and 3.5).
    pub deterministic: bool,
    /// `|X| = |S|·|A|^Δ`.
    pub augmented_states: usize,
    /// `|X̄|` of the belief-equivalence partition.
    pub abstract_states: usize,
    /// `ζ = |X̄| / |X|`.
    pub compression_ratio: f64,
    /// Prop. 3.5's bound `1/|A|^Δ` on `ζ`, which holds under deterministic dynamics only:
    /// `None` (JSON `null`) for a stochastic MDP.
    pub compression_bound: Option<f64>,
    /// Whether the belief partition is reward-respecting (Prop. 3.3).
    pub reward_respecting: bool,
    /// Whether the belief partition has the stochastic substitution property (Prop. 3.3).
    pub ssp: bool,
    /// Largest within-block reward difference.
    pub max_reward_difference: f64,
    /// Largest within-block block-transition difference.
    pub max_transition_difference: f64,
    /// `max_x |V*_augmented(x) − V*_abstract(f(x))|` (Cor. 3.4).
    pub max_value_gap: f64,
    /// `max_x (V*_augmented(x) − V^{lifted}_augmented(x))` (Cor. 3.4).
    pub lifted_policy_value_loss: f64,
    /// The ε-abstraction, when requested.
    #[serde(flatten)]
    pub approximate: Option<ApproximateReport>,
}

/// Builds the augmented MDP of `(mdp, delay)`, its belief-equivalence abstraction and (with
/// `options.epsilon`) an ε-abstraction, and measures the paper's guarantees on them.
///
/// # Errors
/// [`TabularError::InvalidParameter`] for a bad ε, [`TabularError::TooLarge`] above the size limit,
/// and solver errors.
pub fn analyze(
    mdp: &FiniteMdp,
    delay: usize,
    options: &AnalysisOptions,
) -> Result<TabularReport, TabularError> {
    if let Some(epsilon) = options.epsilon {
        validate_epsilon(epsilon)?;
    }
    let augmented = AugmentedMdp::new(mdp, delay, &options.limits)?;
    let optimal = value_iteration(&augmented, &options.solve)?;
    let exact = belief_partition(&augmented);
    let check = check_homomorphism(&augmented, &exact, options.check_tolerance)?;
    let quotient = QuotientMdp::new(&augmented, &exact)?;
    let quality = evaluate_abstraction(&augmented, &optimal.values, &quotient, &options.solve)?;
    let approximate = match options.epsilon {
        None => None,
        Some(epsilon) => {
            let partition = approximate_belief_partition(&augmented, epsilon)?;
            let quotient = QuotientMdp::new(&augmented, &partition)?;
            let bound = value_loss_bound(&augmented, &quotient)?;
            let quality =
                evaluate_abstraction(&augmented, &optimal.values, &quotient, &options.solve)?;
            Some(ApproximateReport {
                epsilon,
                approx_abstract_states: partition.num_blocks(),
                approx_compression_ratio: partition.compression_ratio(),
                c1: bound.c1,
                c2: bound.c2,
                xi: bound.xi,
                value_loss_bound: bound.bound,
                approx_lifted_policy_value_loss: quality.lifted_policy_value_loss,
                approx_max_value_gap: quality.max_value_gap,
            })
        }
    };
    let deterministic = mdp.is_deterministic();
    Ok(TabularReport {
        states: mdp.num_states(),
        actions: mdp.num_actions(),
        delay,
        gamma: mdp.gamma(),
        deterministic,
        augmented_states: augmented.num_states(),
        abstract_states: exact.num_blocks(),
        compression_ratio: exact.compression_ratio(),
        compression_bound: deterministic
            .then(|| (mdp.num_actions() as f64).powf(delay as f64).recip()),
        reward_respecting: check.reward_respecting,
        ssp: check.ssp,
        max_reward_difference: check.max_reward_difference,
        max_transition_difference: check.max_transition_difference,
        max_value_gap: quality.max_value_gap,
        lifted_policy_value_loss: quality.lifted_policy_value_loss,
        approximate,
    })
}

/// A number for the text table: plain for moderate magnitudes, scientific otherwise.
fn format_number(value: f64) -> String {
    if value == 0.0 {
        "0".to_string()
    } else if (1e-3..1e6).contains(&value.abs()) {
        format!("{value:.6}")
    } else {
        format!("{value:.3e}")
    }
}

fn yes_no(value: bool) -> String {
    let text = if value { "yes" } else { "no" };
    text.to_string()
}

impl TabularReport {
    /// The report as an aligned two-column text table.
    pub fn to_table(&self) -> String {
        let mut rows: Vec<(&str, String)> = vec![
            ("states |S|", self.states.to_string()),
            ("actions |A|", self.actions.to_string()),
            ("delay", self.delay.to_string()),
            ("gamma", format_number(self.gamma)),
            ("deterministic dynamics", yes_no(self.deterministic)),
            ("augmented states |X|", self.augmented_states.to_string()),
            (
                "abstract states (belief classes)",
                self.abstract_states.to_string(),
            ),
            ("compression ratio", format_number(self.compression_ratio)),
            (
                "Prop. 3.5 bound 1/|A|^delay",
                self.compression_bound.map_or_else(
                    || "n/a (stochastic dynamics; Prop. 3.5 needs deterministic P)".to_string(),
                    format_number,
                ),
            ),
            ("reward-respecting", yes_no(self.reward_respecting)),
            ("SSP", yes_no(self.ssp)),
            (
                "max reward difference in a block",
                format_number(self.max_reward_difference),
            ),
            (
                "max transition difference in a block",
                format_number(self.max_transition_difference),
            ),
            (
                "max value gap |V* - V*_abstract o f|",
                format_number(self.max_value_gap),
            ),
            (
                "lifted policy value loss",
                format_number(self.lifted_policy_value_loss),
            ),
        ];
        if let Some(approximate) = &self.approximate {
            rows.extend([
                ("epsilon (TV radius)", format_number(approximate.epsilon)),
                (
                    "epsilon-abstract states",
                    approximate.approx_abstract_states.to_string(),
                ),
                (
                    "epsilon compression ratio",
                    format_number(approximate.approx_compression_ratio),
                ),
                ("C1 (reward discrepancy)", format_number(approximate.c1)),
                ("C2 (transition discrepancy)", format_number(approximate.c2)),
                ("xi (abstract reward range)", format_number(approximate.xi)),
                (
                    "Lemma 3.7 value-loss bound",
                    format_number(approximate.value_loss_bound),
                ),
                (
                    "epsilon lifted policy value loss",
                    format_number(approximate.approx_lifted_policy_value_loss),
                ),
                (
                    "epsilon max value gap",
                    format_number(approximate.approx_max_value_gap),
                ),
            ]);
        }
        let width = rows
            .iter()
            .map(|(label, _)| label.chars().count())
            .max()
            .unwrap_or(0);
        rows.iter()
            .map(|(label, value)| format!("{label:<width$}  {value}\n"))
            .collect()
    }
}
