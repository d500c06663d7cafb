//! Save and resume of the discovery loop: at the end of every round the
//! checkpoint directory gets, as one commit ([`crate::checkpoint::commit`]),
//!
//! - `latent.ot`: the latent model's weights;
//! - `gcp.ot`: `π_g`'s weights;
//! - `state.json`: everything else ([`State`]): the settings, the maze's
//!   name, the rounds done and their figures, visit counts, recorded
//!   paths, `V_p`, the plateau bookkeeping, the training buffers, the
//!   latent model's Lagrange multipliers, the goal distance and the
//!   observed transitions.
//!
//! A resumed run refuses a checkpoint of another maze or other settings
//! ([`super::config_difference`]).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{Discovery, DiscoveryConfig, RoundStats, config_difference};
use crate::checkpoint;
use crate::error::LearnerError;
use crate::experience::Experience;
use crate::vae::{AgentPose, Trajectory};

/// A buffered trajectory as checkpointed: `(cell, direction, carried)`
/// for each state, then the actions.
type SavedTrajectory = (Vec<(u32, u8, u8)>, Vec<u8>);

/// What is checkpointed besides the weights.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct State {
    pub(super) config: DiscoveryConfig,
    pub(super) layout_name: String,
    pub(super) rounds_done: u32,
    pub(super) history: Vec<RoundStats>,
    pub(super) visits: BTreeMap<u32, u64>,
    /// Shortest recorded action path from the start to each visited cell.
    pub(super) paths: BTreeMap<u32, Vec<u8>>,
    pub(super) pivotal: Vec<u32>,
    pub(super) best_accuracy: f64,
    pub(super) rounds_without_improvement: u32,
    /// The walks' half of the training buffer.
    pub(super) buffer: Vec<SavedTrajectory>,
    /// `π_g`'s half of the training buffer.
    #[serde(default)]
    pub(super) gcp_buffer: Vec<SavedTrajectory>,
    /// The latent model's Lagrange multipliers (eq. 3), which live outside
    /// its weights; `None` only in checkpoints written before they were kept.
    #[serde(default)]
    pub(super) multipliers: Option<crate::vae::Multipliers>,
    /// The most moves away `π_g`'s training goals lie in the next round
    /// ([`super::GoalCurriculum`]); 0 in checkpoints written before it was kept
    /// (read as `gcp.goal_walk_len`).
    #[serde(default)]
    pub(super) goal_distance: usize,
    /// Every transition observed so far, when the known routes are used
    /// ([`DiscoveryConfig::shortest_known_paths`], [`super::GoalChains`]).
    #[serde(default)]
    pub(super) experience: Experience,
    /// The goal chains' third of the training buffer.
    #[serde(default)]
    pub(super) chain_buffer: Vec<SavedTrajectory>,
}

impl Discovery {
    /// Saves the loop's state into `dir` as one commit
    /// ([`crate::checkpoint::commit`]): the weights are serialised in
    /// memory, and `latent.ot`, `gcp.ot` and `state.json` replace the
    /// previous checkpoint together or not at all. A failed write (a full
    /// disk) is an error naming the file and the cause, and leaves the
    /// previous checkpoint intact.
    pub fn save(&mut self, dir: &Path) -> Result<(), LearnerError> {
        let latent = checkpoint::var_store_bytes(self.latent.var_store())?;
        let gcp = checkpoint::var_store_bytes(self.gcp.var_store())?;
        self.state.buffer = self.buffer.iter().map(saved).collect();
        self.state.gcp_buffer = self.gcp_buffer.iter().map(saved).collect();
        self.state.chain_buffer = self.chain_buffer.iter().map(saved).collect();
        self.state.multipliers = Some(*self.latent.model().multipliers());
        let json = serde_json::to_vec(&self.state).map_err(|e| ckpt(dir, e));
        self.state.buffer.clear();
        self.state.gcp_buffer.clear();
        self.state.chain_buffer.clear();
        checkpoint::commit(
            dir,
            &[
                ("latent.ot", &latent),
                ("gcp.ot", &gcp),
                ("state.json", &json?),
            ],
        )
    }

    /// Resumes from a checkpoint in `dir` if there is one for this
    /// configuration and layout; returns whether it did. A larger budget
    /// (`max_rounds`, `patience`) is a continuation: the new one applies.
    /// Any other difference is refused, naming the field.
    pub fn resume(&mut self, dir: &Path) -> Result<bool, LearnerError> {
        checkpoint::recover(dir)?;
        let path = dir.join("state.json");
        let Ok(bytes) = std::fs::read(&path) else {
            return Ok(false);
        };
        let state: State = serde_json::from_slice(&bytes).map_err(|e| ckpt(&path, e))?;
        if state.layout_name != self.layout.name {
            return Err(ckpt(
                &path,
                format!(
                    "belongs to maze {:?}, this run uses {:?}; use another run directory",
                    state.layout_name, self.layout.name
                ),
            ));
        }
        if let Some(field) = config_difference(&state.config, &self.state.config) {
            return Err(ckpt(
                &path,
                format!("{field}; use another run directory or the same configuration"),
            ));
        }
        let latent = dir.join("latent.ot");
        checkpoint::load_var_store_file(self.latent.var_store_mut(), &latent)?;
        self.gcp.load(dir.join("gcp.ot"))?;
        if let Some(m) = state.multipliers {
            self.latent.model_mut().set_multipliers(m);
        }
        self.buffer = state.buffer.iter().map(restored).collect();
        self.gcp_buffer = state.gcp_buffer.iter().map(restored).collect();
        self.chain_buffer = state.chain_buffer.iter().map(restored).collect();
        self.state = State {
            buffer: Vec::new(),
            config: self.state.config.clone(),
            gcp_buffer: Vec::new(),
            chain_buffer: Vec::new(),
            ..state
        };
        Ok(true)
    }
}

fn saved(t: &Trajectory) -> SavedTrajectory {
    (
        t.states
            .iter()
            .map(|s| (s.cell, s.direction, s.carried))
            .collect(),
        t.actions.clone(),
    )
}

fn restored((states, actions): &SavedTrajectory) -> Trajectory {
    Trajectory {
        states: states
            .iter()
            .map(|&(cell, direction, carried)| AgentPose {
                cell,
                direction,
                carried,
            })
            .collect(),
        actions: actions.clone(),
    }
}

fn ckpt(path: &Path, e: impl std::fmt::Display) -> LearnerError {
    LearnerError::Checkpoint {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}
