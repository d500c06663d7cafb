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

use super::config::{AgentConfig, NarrowPlaneInit, ObjectActionInit, UnseenInputs};
use crate::a2c::input::{GOAL_CHANNEL, KEY_CHANNEL, OBJECT_CHANNELS};
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

/// The first convolution's weights, `[out, planes, 3, 3]`.
const CONV1: &str = "encoder.conv1.weight";

/// Starts the input planes of `dst`'s first convolution that `π_g` never
/// saw ([`UnseenInputs::AsFloor`]): each object kind not in `trained`
/// (indexed by code) as a copy of the floor plane, the carried-key plane
/// at zero. `dst` is the Worker's or the Manager's store.
pub fn unseen_planes_as_floor(dst: &nn::VarStore, trained: &[bool; OBJECT_CHANNELS]) {
    let vars = dst.variables();
    let Some(w) = vars.get(CONV1) else {
        return;
    };
    tch::no_grad(|| {
        let floor = w.narrow(1, sim::Object::Floor as i64, 1).copy();
        for (kind, _) in trained.iter().enumerate().filter(|(_, seen)| !**seen) {
            w.narrow(1, kind as i64, 1).copy_(&floor);
        }
        let _ = w.narrow(1, KEY_CHANNEL as i64, 1).fill_(0.0);
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
    if cfg.narrow_plane_init == NarrowPlaneInit::PiGGoal {
        copy_goal_plane(gcp.var_store(), worker, GOAL_CHANNEL);
    }
    if cfg.object_action_init == ObjectActionInit::Forward {
        copy_forward_row(gcp.var_store(), worker);
    }
    if cfg.unseen_inputs == UnseenInputs::AsFloor {
        unseen_planes_as_floor(worker, &gcp.trained_kinds());
    }
    if let Some(vs) = manager {
        let m = copy_from(gcp.var_store(), vs, &["encoder"]);
        if cfg.unseen_inputs == UnseenInputs::AsFloor {
            unseen_planes_as_floor(vs, &gcp.trained_kinds());
        }
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
            assert!(
                d["policy.weight"]
                    .narrow(0, k, 1)
                    .equal(&s["policy.weight"].narrow(0, 2, 1))
            );
            assert!(
                d["policy.bias"]
                    .narrow(0, k, 1)
                    .equal(&s["policy.bias"].narrow(0, 2, 1))
            );
        }
        assert!(
            d["policy.weight"]
                .narrow(0, 0, 3)
                .equal(&s["policy.weight"]),
            "π_g's rows stay"
        );

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

    /// A Wide-then-Narrow Door-Key Worker initialised from a `π_g` of the
    /// plain small maze (floor, walls, exit): both goal planes start as
    /// `π_g`'s goal plane, the planes of the kinds `π_g` never saw (ball,
    /// key, doors, lava) as its floor plane, the carried-key plane at zero;
    /// so the Worker's first layer sees the Door-Key maze as `π_g` sees its
    /// structure. With the old settings the `g_n` plane and the unseen
    /// planes keep draws of their own.
    #[test]
    fn a_door_key_worker_starts_from_pi_g_on_the_structure() {
        use crate::a2c::input::{CellInput, GoalMarks, NO_GOAL};
        use crate::batch_env::ObsView;
        use crate::gcp::{GcpConfig, GoalConditionedPolicy};
        use shm_schemas::EnvMeta;
        use sim::{Maze, Object};

        let plain = Maze::Small.layout(false);
        let dk = Maze::Small.layout(true);
        let gcfg = GcpConfig::default();
        let mut gcp = GoalConditionedPolicy::new(&gcfg, &dk, 1, 3, 7).expect("π_g");
        gcp.set_trained_on(&plain);
        let trained = gcp.trained_kinds();
        assert!(trained[Object::Exit as usize] && !trained[Object::DoorLocked as usize]);
        assert!(!trained[Object::Key as usize] && !trained[Object::Ball as usize]);
        let cfg = AgentConfig {
            init_from_gcp: true,
            conv_channels: gcfg.conv_channels,
            hidden: gcfg.hidden,
            ..AgentConfig::default()
        };
        let worker_cfg = ActorCriticConfig {
            num_actions: 5,
            goal_planes: 2,
            ..gcfg.network(3)
        };
        let worker = |cfg: &AgentConfig| {
            let vs = nn::VarStore::new(Device::Cpu);
            let net = crate::seeding::init_seeded(11, || {
                ActorCritic::new(&vs.root(), &worker_cfg, dk.width, dk.height)
            });
            from_pi_g(&gcp, cfg, &vs, None).expect("init");
            (vs, net)
        };
        let (vs, net) = worker(&cfg);
        let (w, s) = (&vs.variables()[CONV1], &gcp.var_store().variables()[CONV1]);
        let plane = |t: &Tensor, k: usize| t.narrow(1, k as i64, 1);
        assert!(
            plane(w, GOAL_CHANNEL + 1).equal(&plane(s, GOAL_CHANNEL)),
            "g_n plane"
        );
        for kind in [Object::Ball, Object::Key, Object::DoorLocked, Object::Lava] {
            assert!(
                plane(w, kind as usize).equal(&plane(s, Object::Floor as usize)),
                "{kind:?}"
            );
        }
        assert!(plane(w, Object::Exit as usize).equal(&plane(s, Object::Exit as usize)));
        assert_eq!(
            plane(w, KEY_CHANNEL)
                .abs()
                .sum(tch::Kind::Float)
                .double_value(&[]),
            0.0
        );

        // In front of the locked door with the key in hand, `g_n` on the
        // door (`g_w` unmarked): the Worker's policy is π_g's on the
        // structure (door as floor, hands empty) — the first three
        // actions' logits agree.
        let at = |x, y| dk.cell_index(x, y) as u32;
        let door = at(6, 9);
        let mut meta = [EnvMeta::EMPTY];
        meta[0].x = 5;
        meta[0].y = 9;
        meta[0].dir = 0;
        let logits =
            |cells: &[u8], meta: &[EnvMeta], goals: &[u32], planes: usize, net: &ActorCritic| {
                let view = ObsView {
                    seq: 0,
                    cells,
                    final_cells: &[],
                    meta,
                    width: dk.width,
                    height: dk.height,
                };
                let mut input = CellInput::new(dk.width, dk.height, planes);
                input.push_obs(
                    &view,
                    Some(GoalMarks {
                        cells: goals,
                        per_env: planes,
                    }),
                );
                tch::no_grad(|| net.step(&input, &net.zero_state(1)))
                    .logits
                    .narrow(1, 0, 3)
            };
        let mut with_key = meta;
        with_key[0].carrying = Object::Key as u8;
        let structure: Vec<u8> = dk
            .structural()
            .cells
            .iter()
            .map(|&c| {
                if c == Object::DoorOpen as u8 {
                    Object::Floor as u8
                } else {
                    c
                }
            })
            .collect();
        let worker_view = logits(&dk.cells, &with_key, &[NO_GOAL, door], 2, &net);
        let pi_g_view = logits(&structure, &meta, &[door], 1, gcp.network());
        assert!(
            worker_view.allclose(&pi_g_view, 1e-5, 1e-5, false),
            "{worker_view} vs {pi_g_view}"
        );

        // The settings of before: the carried key moves the logits.
        let old = AgentConfig {
            unseen_inputs: UnseenInputs::Copied,
            narrow_plane_init: NarrowPlaneInit::Fresh,
            ..cfg
        };
        let (vs, net) = worker(&old);
        assert!(!plane(&vs.variables()[CONV1], GOAL_CHANNEL + 1).equal(&plane(s, GOAL_CHANNEL)));
        let old_view = logits(&dk.cells, &with_key, &[NO_GOAL, door], 2, &net);
        assert!(!old_view.allclose(&pi_g_view, 1e-3, 1e-3, false));
    }
}
