//! Initialisation from the goal-conditioned policy `π_g` (Shang et al.
//! 2019, section 4.4; section 5, control experiments: "we test initializing the
//! Manager and Worker with the weights of `π_g`").
//!
//! The Worker has `π_g`'s architecture (a goal channel, the same trunk), so
//! its encoder, core and heads start as copies of `π_g`'s. The Manager
//! shares the encoder's shape: its encoder starts from `π_g`'s, without the
//! goal channel's input weights (the Manager's input has none). Where a
//! tensor's shape differs only in size along some dimensions (a Door-Key
//! Worker has six actions where `π_g` had three; the Manager's first
//! convolution has one input plane fewer), the overlapping block is copied
//! and the rest keeps its fresh initialisation.

use tch::{Tensor, nn};

use super::config::{AgentConfig, ObjectActionInit};
use crate::a2c::input::GOAL_CHANNEL;
use crate::error::{ConfigError, LearnerError};
use crate::gcp::GoalConditionedPolicy;

/// What an initialisation copied.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InitReport {
    /// Tensors copied whole.
    pub copied: Vec<String>,
    /// Tensors of which the overlapping block was copied.
    pub partial: Vec<String>,
}

/// Copies `src`'s variables whose names start with one of `prefixes` into
/// the variables of the same name in `dst` (module docs).
pub fn copy_from(src: &nn::VarStore, dst: &nn::VarStore, prefixes: &[&str]) -> InitReport {
    let from = src.variables();
    let mut report = InitReport::default();
    let mut names: Vec<(String, Tensor)> = dst.variables().into_iter().collect();
    names.sort_by(|a, b| a.0.cmp(&b.0));
    tch::no_grad(|| {
        for (name, mut to) in names {
            if !prefixes.iter().any(|p| name.starts_with(p)) {
                continue;
            }
            let Some(src_t) = from.get(&name) else {
                continue;
            };
            let (a, b) = (src_t.size(), to.size());
            if a == b {
                to.copy_(src_t);
                report.copied.push(name);
            } else if a.len() == b.len() {
                let mut s = src_t.shallow_clone();
                let mut d = to.shallow_clone();
                for (dim, (&x, &y)) in a.iter().zip(&b).enumerate() {
                    let n = x.min(y);
                    s = s.narrow(dim as i64, 0, n);
                    d = d.narrow(dim as i64, 0, n);
                }
                d.copy_(&s);
                report.partial.push(name);
            }
        }
    });
    report
}

/// Starts every goal plane of `dst`'s first convolution past
/// `goal_channel` from `src`'s goal plane `goal_channel`: the
/// Wide-then-Narrow Worker marks `g_w` and `g_n` on planes of their own,
/// and both are cells to reach, as `π_g`'s one goal is.
pub fn copy_goal_plane(src: &nn::VarStore, dst: &nn::VarStore, goal_channel: usize) {
    const CONV1: &str = "encoder/conv1/weight";
    let (from, to) = (src.variables(), dst.variables());
    let (Some(s), Some(d)) = (from.get(CONV1), to.get(CONV1)) else {
        return;
    };
    let (planes_src, planes_dst) = (s.size()[1], d.size()[1]);
    let g = goal_channel as i64;
    if planes_src <= g || s.size()[0] != d.size()[0] {
        return;
    }
    tch::no_grad(|| {
        for k in planes_src..planes_dst {
            d.narrow(1, k, 1).copy_(&s.narrow(1, g, 1));
        }
    });
}

/// Starts the policy rows past `π_g`'s own (Door-Key's pick and open) as
/// copies of its `forward` row: acting on an object goal in front is what
/// stepping onto a cell goal in front is ([`ObjectActionInit::Forward`]).
pub fn copy_forward_row(src: &nn::VarStore, dst: &nn::VarStore) {
    let (from, to) = (src.variables(), dst.variables());
    tch::no_grad(|| {
        for name in ["policy.weight", "policy.bias"] {
            let (Some(s), Some(d)) = (from.get(name), to.get(name)) else {
                continue;
            };
            let (own, all) = (s.size()[0], d.size()[0]);
            let forward = s.narrow(0, i64::from(sim::action::FORWARD), 1);
            for k in own..all {
                d.narrow(0, k, 1).copy_(&forward);
            }
        }
    });
}

/// Initialises an agent of `cfg` from `gcp` (module docs): the Worker's
/// weights `worker` (encoder, core, heads, the goal plane) and the
/// Manager's encoder in `manager`. `π_g`'s sizes must be the agent's.
pub fn from_pi_g(
    gcp: &GoalConditionedPolicy,
    cfg: &AgentConfig,
    worker: &nn::VarStore,
    manager: Option<&nn::VarStore>,
) -> Result<InitReport, LearnerError> {
    let g = gcp.config();
    if g.conv_channels != cfg.conv_channels || g.hidden != cfg.hidden {
        return Err(ConfigError::new(
            "init_from_gcp",
            format!(
                "π_g has conv {:?} / hidden {}; the agent has {:?} / {}",
                g.conv_channels, g.hidden, cfg.conv_channels, cfg.hidden
            ),
        )
        .into());
    }
    let mut report = copy_from(
        gcp.var_store(),
        worker,
        &["encoder", "core", "policy", "value"],
    );
    copy_goal_plane(gcp.var_store(), worker, GOAL_CHANNEL);
    if cfg.object_action_init == ObjectActionInit::Forward {
        copy_forward_row(gcp.var_store(), worker);
    }
    if let Some(vs) = manager {
        let m = copy_from(gcp.var_store(), vs, &["encoder"]);
        report
            .copied
            .extend(m.copied.into_iter().map(|n| format!("manager/{n}")));
        report
            .partial
            .extend(m.partial.into_iter().map(|n| format!("manager/{n}")));
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::a2c::net::{ActorCritic, ActorCriticConfig, Trunk};
    use tch::Device;

    #[test]
    fn initialisation_copies_the_tensors_exactly() {
        let (w, h) = (13, 13);
        let src = nn::VarStore::new(Device::Cpu);
        let gcp_cfg = ActorCriticConfig {
            conv_channels: [4, 8],
            hidden: 16,
            num_actions: 3,
            goal_planes: 1,
        };
        let _gcp = crate::seeding::init_seeded(1, || ActorCritic::new(&src.root(), &gcp_cfg, w, h));
        // A Door-Key Worker: six actions.
        let worker_vs = nn::VarStore::new(Device::Cpu);
        let worker_cfg = ActorCriticConfig {
            num_actions: 6,
            ..gcp_cfg.clone()
        };
        let _worker = crate::seeding::init_seeded(2, || {
            ActorCritic::new(&worker_vs.root(), &worker_cfg, w, h)
        });
        let report = copy_from(&src, &worker_vs, &["encoder", "core", "policy", "value"]);
        let s = src.variables();
        let d = worker_vs.variables();
        for name in &report.copied {
            assert!(s[name].equal(&d[name]), "{name} not copied exactly");
        }
        assert_eq!(
            report.partial,
            vec!["policy.bias".to_string(), "policy.weight".to_string()]
        );
        assert!(
            d["policy.weight"]
                .narrow(0, 0, 3)
                .equal(&s["policy.weight"])
        );
        assert!(
            !d["policy.weight"]
                .narrow(0, 3, 3)
                .equal(&Tensor::zeros([3, 16], (tch::Kind::Float, Device::Cpu)))
        );
        assert_eq!(report.copied.len() + report.partial.len(), d.len());
        // Pick and open started from π_g's forward row.
        copy_forward_row(&src, &worker_vs);
        let d = worker_vs.variables();
        for k in 3..6 {
            assert!(d["policy.weight"].narrow(0, k, 1).equal(&s["policy.weight"].narrow(0, 2, 1)));
            assert!(d["policy.bias"].narrow(0, k, 1).equal(&s["policy.bias"].narrow(0, 2, 1)));
        }
        assert!(d["policy.weight"].narrow(0, 0, 3).equal(&s["policy.weight"]), "π_g's rows stay");

        // A Manager trunk without the goal channel: the encoder is copied,
        // the first convolution without its goal plane; the core is not.
        let manager_vs = nn::VarStore::new(Device::Cpu);
        let _m = crate::seeding::init_seeded(3, || {
            Trunk::new(
                &manager_vs.root(),
                gcp_cfg.in_channels() - 1,
                [4, 8],
                16,
                w,
                h,
            )
        });
        let before = manager_vs.variables()["core.weight_ih_l0"].copy();
        let report = copy_from(&src, &manager_vs, &["encoder"]);
        let d = manager_vs.variables();
        assert_eq!(report.partial, vec!["encoder.conv1.weight".to_string()]);
        let planes = gcp_cfg.in_channels() - 1;
        assert!(d["encoder.conv1.weight"].equal(&s["encoder.conv1.weight"].narrow(1, 0, planes)));
        for name in [
            "encoder.conv2.weight",
            "encoder.fc.weight",
            "encoder.fc.bias",
        ] {
            assert!(d[name].equal(&s[name]), "{name}");
        }
        assert!(
            d["core.weight_ih_l0"].equal(&before),
            "the Manager's core is its own"
        );
    }
}
