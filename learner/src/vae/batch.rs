//! Padded, time-major batches of trajectories `τ = {(s_t, a_t)}_{t=0..T}`
//! for the latent model (Shang et al. 2019, section 3.1).
//!
//! Trajectory `b` has `len_b = T_b + 1` states and `T_b` actions. Every
//! tensor is `[L, B]` with `L = max_b len_b`; the action slot of the last
//! state (and of padding) holds the padding value 0 and is masked out of
//! every loss.

use tch::{Device, Tensor};

use crate::error::LearnerError;

use super::config::LatentConfig;

/// The agent's pose in a fixed maze: what the latent model reads as a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct AgentPose {
    /// Cell index `y·W + x`.
    pub cell: u32,
    /// Facing direction (0 right, 1 down, 2 left, 3 up).
    pub direction: u8,
    /// Carried object kind, 0 for nothing.
    pub carried: u8,
}

impl AgentPose {
    /// A pose facing right and carrying nothing.
    pub fn at(cell: u32) -> Self {
        Self {
            cell,
            direction: 0,
            carried: 0,
        }
    }

    /// The pose an observation record shows, on a grid `width` cells wide:
    /// the one constructor of every trajectory source (random walks, path
    /// replays and `π_g`'s goal episodes go into one buffer, so one pose
    /// must have one encoding). `carried` is the carried object's cell code
    /// (`sim::Object as u8`: a ball 2, a key 3), 0 for nothing: no object
    /// that can be carried has code 0 (floor).
    pub fn from_meta(meta: &sim::EnvMeta, width: usize) -> Self {
        let carried = if meta.carrying == sim::EnvMeta::CARRYING_NOTHING {
            0
        } else {
            meta.carrying
        };
        Self {
            cell: (meta.y as usize * width + meta.x as usize) as u32,
            direction: meta.dir & 3,
            carried,
        }
    }
}

/// One trajectory: `states.len() == actions.len() + 1 ≥ 2`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    /// `s_0 … s_T`.
    pub states: Vec<AgentPose>,
    /// `a_0 … a_{T−1}`; `a_t` is taken in `s_t`.
    pub actions: Vec<u8>,
}

/// A padded batch of trajectories, time-major.
#[derive(Debug)]
pub struct TrajectoryBatch {
    /// Cell indices, `[L, B]` int64 (padding 0).
    pub cells: Tensor,
    /// Directions, `[L, B]` int64 (padding 0).
    pub directions: Tensor,
    /// Carried-object kinds, `[L, B]` int64 (padding 0).
    pub carried: Tensor,
    /// Actions, `[L, B]` int64; valid where `action_mask` is 1, else 0.
    pub actions: Tensor,
    /// States per trajectory, `len_b = T_b + 1`.
    pub lengths: Vec<i64>,
    /// 1 where `t < len_b`, `[L, B]` float.
    pub state_mask: Tensor,
    /// 1 where `t < len_b − 1` (an action was taken), `[L, B]` float.
    pub action_mask: Tensor,
    /// 1 on the boundary states `t = 0` and `t = len_b − 1`, whose latents
    /// are fixed to `z = 1`; `[L, B]` float.
    pub boundary_mask: Tensor,
    /// `index[t, b] = len_b − 1 − t` for `t < len_b`, else `t`: reverses each
    /// trajectory in place, padding untouched (for the backward LSTMs);
    /// `[L, B]` int64.
    pub reverse_index: Tensor,
}

impl TrajectoryBatch {
    /// Pads `trajectories` into `[L, B]` tensors on `device`, checking them
    /// against the spaces of `cfg`.
    pub fn new(
        trajectories: &[Trajectory],
        cfg: &LatentConfig,
        device: Device,
    ) -> Result<Self, LearnerError> {
        if trajectories.is_empty() {
            return Err(LearnerError::EmptyBatch);
        }
        for (index, tau) in trajectories.iter().enumerate() {
            check_trajectory(index, tau, cfg)?;
        }
        let batch = trajectories.len();
        let max_len = trajectories
            .iter()
            .map(|tau| tau.states.len())
            .max()
            .unwrap_or(0);
        let cells_of = |len: usize| vec![0_i64; len * batch];
        let (mut cells, mut directions, mut carried, mut actions) = (
            cells_of(max_len),
            cells_of(max_len),
            cells_of(max_len),
            cells_of(max_len),
        );
        let mut state_mask = vec![0_f32; max_len * batch];
        let mut action_mask = vec![0_f32; max_len * batch];
        let mut boundary_mask = vec![0_f32; max_len * batch];
        let mut reverse_index: Vec<i64> =
            (0..max_len * batch).map(|i| (i / batch) as i64).collect();
        for (b, tau) in trajectories.iter().enumerate() {
            let len = tau.states.len();
            for (t, pose) in tau.states.iter().enumerate() {
                let i = t * batch + b;
                cells[i] = i64::from(pose.cell);
                directions[i] = cfg.facing_index(pose.direction);
                carried[i] = i64::from(pose.carried);
                state_mask[i] = 1.0;
                reverse_index[i] = (len - 1 - t) as i64;
            }
            for (t, &action) in tau.actions.iter().enumerate() {
                actions[t * batch + b] = i64::from(action);
                action_mask[t * batch + b] = 1.0;
            }
            boundary_mask[b] = 1.0;
            boundary_mask[(len - 1) * batch + b] = 1.0;
        }
        let shape = [max_len as i64, batch as i64];
        let ints = |v: &[i64]| Tensor::from_slice(v).view(shape).to_device(device);
        let floats = |v: &[f32]| Tensor::from_slice(v).view(shape).to_device(device);
        Ok(Self {
            cells: ints(&cells),
            directions: ints(&directions),
            carried: ints(&carried),
            actions: ints(&actions),
            lengths: trajectories
                .iter()
                .map(|tau| tau.states.len() as i64)
                .collect(),
            state_mask: floats(&state_mask),
            action_mask: floats(&action_mask),
            boundary_mask: floats(&boundary_mask),
            reverse_index: ints(&reverse_index),
        })
    }

    /// `L`, the padded length.
    pub fn max_len(&self) -> i64 {
        self.cells.size()[0]
    }

    /// `B`, the number of trajectories.
    pub fn batch_size(&self) -> i64 {
        self.cells.size()[1]
    }

    /// 1 on the interior states `0 < t < len_b − 1`, whose latents are
    /// inferred; `[L, B]` float.
    pub fn interior_mask(&self) -> Tensor {
        &self.state_mask - &self.boundary_mask
    }

    /// Reverses each trajectory of a time-major tensor `[L, B, ...]` within
    /// its own length (an involution: applying it twice is the identity).
    pub fn reverse_in_time(&self, x: &Tensor) -> Tensor {
        let mut index = self.reverse_index.shallow_clone();
        let mut shape = index.size();
        for &extra in &x.size()[2..] {
            index = index.unsqueeze(-1);
            shape.push(extra);
        }
        x.gather(0, &index.expand(shape.as_slice(), false), false)
    }
}

fn check_trajectory(
    index: usize,
    tau: &Trajectory,
    cfg: &LatentConfig,
) -> Result<(), LearnerError> {
    let states = tau.states.len();
    if states < 2 {
        return Err(LearnerError::TrajectoryTooShort { index, states });
    }
    if tau.actions.len() + 1 != states {
        return Err(LearnerError::ActionCountMismatch {
            index,
            states,
            actions: tau.actions.len(),
        });
    }
    let out_of_range = |what, value: i64, limit: i64| {
        (value >= limit).then_some(LearnerError::OutOfRange { what, value, limit })
    };
    for pose in &tau.states {
        let checks = [
            out_of_range("cell", i64::from(pose.cell), cfg.num_cells),
            out_of_range(
                "direction",
                cfg.facing_index(pose.direction),
                cfg.num_directions,
            ),
            out_of_range("carried", i64::from(pose.carried), cfg.num_carried),
        ];
        if let Some(err) = checks.into_iter().flatten().next() {
            return Err(err);
        }
    }
    for &action in &tau.actions {
        if let Some(err) = out_of_range("action", i64::from(action), cfg.num_actions) {
            return Err(err);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Kind;

    fn walk(cells: &[u32], actions: &[u8]) -> Trajectory {
        Trajectory {
            states: cells.iter().map(|&c| AgentPose::at(c)).collect(),
            actions: actions.to_vec(),
        }
    }

    fn cfg() -> LatentConfig {
        LatentConfig {
            num_cells: 10,
            num_actions: 4,
            ..Default::default()
        }
    }

    #[test]
    fn pads_time_major_with_masks_and_boundaries() {
        let batch = TrajectoryBatch::new(
            &[walk(&[1, 2, 3, 4], &[0, 0, 1]), walk(&[7, 8], &[2])],
            &cfg(),
            Device::Cpu,
        )
        .expect("valid batch");
        assert_eq!((batch.max_len(), batch.batch_size()), (4, 2));
        assert_eq!(batch.lengths, vec![4, 2]);
        let column = |t: &Tensor, b: i64| {
            Vec::<f64>::try_from(t.select(1, b).to_kind(Kind::Double)).expect("1-d")
        };
        assert_eq!(column(&batch.cells, 1), vec![7.0, 8.0, 0.0, 0.0]);
        assert_eq!(column(&batch.state_mask, 1), vec![1.0, 1.0, 0.0, 0.0]);
        assert_eq!(column(&batch.action_mask, 0), vec![1.0, 1.0, 1.0, 0.0]);
        assert_eq!(column(&batch.action_mask, 1), vec![1.0, 0.0, 0.0, 0.0]);
        assert_eq!(column(&batch.boundary_mask, 0), vec![1.0, 0.0, 0.0, 1.0]);
        assert_eq!(column(&batch.interior_mask(), 0), vec![0.0, 1.0, 1.0, 0.0]);
        assert_eq!(column(&batch.interior_mask(), 1), vec![0.0, 0.0, 0.0, 0.0]);
        let reversed = batch
            .reverse_in_time(&batch.cells.unsqueeze(-1))
            .squeeze_dim(-1);
        assert_eq!(column(&reversed, 0), vec![4.0, 3.0, 2.0, 1.0]);
        assert_eq!(column(&reversed, 1), vec![8.0, 7.0, 0.0, 0.0]);
    }

    #[test]
    fn one_direction_reads_every_facing_as_one_and_four_keep_them() {
        let facing = |d: u8| AgentPose {
            cell: 1,
            direction: d,
            carried: 0,
        };
        let tau = Trajectory {
            states: vec![facing(0), facing(1), facing(3)],
            actions: vec![1, 1],
        };
        let directions = |num_directions| {
            let cfg = LatentConfig {
                num_directions,
                ..cfg()
            };
            let batch = TrajectoryBatch::new(std::slice::from_ref(&tau), &cfg, Device::Cpu)
                .expect("valid batch");
            Vec::<i64>::try_from(batch.directions.select(1, 0)).expect("1-d")
        };
        assert_eq!(directions(1), vec![0, 0, 0]);
        assert_eq!(directions(4), vec![0, 1, 3]);
        // Two facings are one too many for a model of two.
        let two = LatentConfig {
            num_directions: 2,
            ..cfg()
        };
        assert!(TrajectoryBatch::new(&[tau], &two, Device::Cpu).is_err());
    }

    #[test]
    fn rejects_malformed_trajectories() {
        let cfg = cfg();
        let cases = [
            (vec![], "empty"),
            (vec![walk(&[1], &[])], "short"),
            (vec![walk(&[1, 2], &[])], "mismatch"),
            (vec![walk(&[1, 12], &[0])], "cell"),
            (vec![walk(&[1, 2], &[4])], "action"),
        ];
        for (trajectories, case) in cases {
            let err = TrajectoryBatch::new(&trajectories, &cfg, Device::Cpu).expect_err(case);
            let matches = match case {
                "empty" => matches!(err, LearnerError::EmptyBatch),
                "short" => matches!(err, LearnerError::TrajectoryTooShort { states: 1, .. }),
                "mismatch" => matches!(err, LearnerError::ActionCountMismatch { actions: 0, .. }),
                "cell" => matches!(
                    err,
                    LearnerError::OutOfRange {
                        what: "cell",
                        value: 12,
                        ..
                    }
                ),
                _ => matches!(
                    err,
                    LearnerError::OutOfRange {
                        what: "action",
                        value: 4,
                        ..
                    }
                ),
            };
            assert!(matches, "{case}: {err}");
        }
    }
}
