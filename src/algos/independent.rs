//! A stack served in several learner passes (`--runs-per-pass`): stacks of a few runs each,
//! updated one after the other. Every run computes exactly what it computes alone.
use std::ops::Range;
use std::path::Path;

use burn::prelude::{Device, Tensor};

use super::agent::{ActMode, Agent, AgentSpec};
use super::context::UpdateContext;
use super::stats::Stats;
use crate::acting::ActingNetwork;
use crate::delay::{BatchExtras, ReplayError};
use crate::learn::LearnError;

pub struct Independent {
    /// In run order: the first `agents[0].runs()` runs are the first agent's, and so on.
    agents: Vec<Box<dyn Agent>>,
}

impl Independent {
    /// The stacks, in run order; all of one algorithm and configuration.
    pub fn new(agents: Vec<Box<dyn Agent>>) -> Independent {
        assert!(!agents.is_empty(), "a stack of at least one run");
        Independent { agents }
    }

    /// `items` (one per run) cut into each agent's part.
    fn per_agent<'a, T>(&self, mut items: &'a mut [T]) -> Vec<&'a mut [T]> {
        let mut parts = Vec::with_capacity(self.agents.len());
        for agent in &self.agents {
            let (part, rest) = items.split_at_mut(agent.runs());
            parts.push(part);
            items = rest;
        }
        parts
    }
}

impl Agent for Independent {
    fn act_delay_free(&mut self, states: &[f32], rows: usize) -> Option<Vec<f32>> {
        self.agents[0].act_delay_free(states, rows)
    }

    fn stat_names(&self) -> Vec<&'static str> {
        self.agents[0].stat_names()
    }

    fn batch_extras(&self) -> BatchExtras {
        self.agents[0].batch_extras()
    }

    fn acting_network(&self) -> ActingNetwork {
        self.agents[0].acting_network()
    }

    fn runs(&self) -> usize {
        self.agents.iter().map(|agent| agent.runs()).sum()
    }

    fn spec(&self) -> &AgentSpec {
        self.agents[0].spec()
    }

    fn acting_device(&self) -> &Device {
        self.agents[0].acting_device()
    }

    /// Each agent acts for its part of `runs`, on its slices of `augmented`.
    fn act_tensor(
        &mut self,
        runs: Range<usize>,
        augmented: Tensor<3>,
        counts: &[usize],
        mode: ActMode,
    ) -> Tensor<3> {
        let mut actions = Vec::new();
        let mut first = 0;
        for agent in &mut self.agents {
            let (start, end) = (runs.start.max(first), runs.end.min(first + agent.runs()));
            if start < end {
                let slices = start - runs.start..end - runs.start;
                let part = augmented.clone().narrow(0, slices.start, slices.len());
                actions.push(agent.act_tensor(
                    start - first..end - first,
                    part,
                    &counts[slices],
                    mode,
                ));
            }
            first += agent.runs();
        }
        Tensor::cat(actions, 0)
    }

    fn update_runs(&mut self, contexts: &mut [UpdateContext<'_>]) -> Result<Stats, ReplayError> {
        let parts = self.per_agent(contexts);
        let mut stats = Vec::new();
        for (agent, contexts) in self.agents.iter_mut().zip(parts) {
            stats.push(agent.update_runs(contexts)?);
        }
        Ok(Stats::concat_runs(stats))
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        let mut dirs = dirs;
        for agent in &self.agents {
            let (part, rest) = dirs.split_at(agent.runs());
            agent.save_runs(part)?;
            dirs = rest;
        }
        Ok(())
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        let mut dirs = dirs;
        for agent in &mut self.agents {
            let (part, rest) = dirs.split_at(agent.runs());
            agent.load_runs(part)?;
            dirs = rest;
        }
        Ok(())
    }
}
