//! The A2C baseline (Shang et al. 2019, section 4.1): one A2C-LSTM on the
//! task's observation and actions (left, right, forward for the MultiGoal
//! tasks; pickup, drop and toggle too for Door-Key), trained on the task's
//! own rewards. Its network is the Worker's trunk without a goal channel
//! ([`crate::a2c::net::ActorCritic`]); [`HrlAgent`](super::HrlAgent) runs it
//! with [`AgentKind::A2c`](super::AgentKind::A2c).

use shm_schemas::EnvMeta;

/// The baseline's reward and episode end for a step: the task's reward,
/// and the end of the task's episode.
pub fn task_step(meta: &EnvMeta) -> (f32, bool) {
    (meta.reward, meta.done())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::flags;

    #[test]
    fn the_baseline_learns_from_the_task_reward_and_episode() {
        let ball = EnvMeta {
            reward: 0.99,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&ball), (0.99, false));
        let exit = EnvMeta {
            reward: 0.99,
            flags: flags::TERMINATED | flags::RESET,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&exit), (0.99, true));
        let timeout = EnvMeta {
            reward: -0.01,
            flags: flags::TRUNCATED,
            ..EnvMeta::EMPTY
        };
        assert_eq!(task_step(&timeout), (-0.01, true));
    }
}
