//! `π_g`'s weights, saved and loaded: atomically, through
//! [`crate::checkpoint`]. The goal samplers, the action RNG and Adam's
//! moments are not saved: a discovery round starts them afresh
//! ([`GoalConditionedPolicy::start_round`]).

use std::path::Path;

use tch::nn;

use super::GoalConditionedPolicy;
use crate::error::LearnerError;

impl GoalConditionedPolicy {
    /// The weights (the Manager's and Worker's encoders start from them,
    /// section 4).
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// Saves the weights, serialised in memory and written atomically
    /// ([`crate::checkpoint`]): a full disk is an error naming the file,
    /// never an abort or a torn file.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LearnerError> {
        crate::checkpoint::save_var_store_file(&self.vs, path.as_ref())
    }

    /// Loads weights saved by [`Self::save`] from a policy of the same
    /// configuration.
    pub fn load(&mut self, path: impl AsRef<Path>) -> Result<(), LearnerError> {
        crate::checkpoint::load_var_store_file(&mut self.vs, path.as_ref())
    }
}
