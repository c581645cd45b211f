//! A stack of solo agents: the runs of an algorithm whose learners are not stacked, each its
//! own agent, updated one after the other. Every run computes exactly what it computes alone.
use std::path::Path;

use super::agent::{ActMode, Agent, Stats};
use super::context::UpdateContext;
use crate::acting::ActingNetwork;
use crate::delay::{BatchExtras, ReplayError};
use crate::learn::LearnError;

pub struct Independent {
    agents: Vec<Box<dyn Agent>>,
}

impl Independent {
    /// The runs, in order; all of one algorithm and configuration.
    pub fn new(agents: Vec<Box<dyn Agent>>) -> Independent {
        assert!(!agents.is_empty(), "a stack of at least one run");
        Independent { agents }
    }
}

impl Agent for Independent {
    fn act(&mut self, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.agents[0].act(augmented, rows, mode)
    }

    fn act_delay_free(&mut self, states: &[f32], rows: usize) -> Option<Vec<f32>> {
        self.agents[0].act_delay_free(states, rows)
    }

    fn stat_names(&self) -> Vec<&'static str> {
        self.agents[0].stat_names()
    }

    fn batch_extras(&self) -> BatchExtras {
        self.agents[0].batch_extras()
    }

    fn update(&mut self, ctx: &mut UpdateContext<'_>) -> Result<Stats, ReplayError> {
        self.agents[0].update(ctx)
    }

    fn save(&self, dir: &Path) -> Result<(), LearnError> {
        self.agents[0].save(dir)
    }

    fn load(&mut self, dir: &Path) -> Result<(), LearnError> {
        self.agents[0].load(dir)
    }

    fn acting_network(&self) -> ActingNetwork {
        self.agents[0].acting_network()
    }

    fn runs(&self) -> usize {
        self.agents.len()
    }

    fn act_run(&mut self, run: usize, augmented: &[f32], rows: usize, mode: ActMode) -> Vec<f32> {
        self.agents[run].act(augmented, rows, mode)
    }

    fn update_runs(
        &mut self,
        contexts: &mut [UpdateContext<'_>],
    ) -> Result<Vec<Stats>, ReplayError> {
        self.agents
            .iter_mut()
            .zip(contexts)
            .map(|(agent, ctx)| agent.update(ctx))
            .collect()
    }

    fn save_runs(&self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.agents
            .iter()
            .zip(dirs)
            .try_for_each(|(agent, dir)| agent.save(dir))
    }

    fn load_runs(&mut self, dirs: &[&Path]) -> Result<(), LearnError> {
        self.agents
            .iter_mut()
            .zip(dirs)
            .try_for_each(|(agent, dir)| agent.load(dir))
    }
}
