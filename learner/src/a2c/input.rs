//! The network's view of an observation batch, in two forms that compute
//! the same first convolution.
//!
//! The input of every actor-critic of Shang et al. 2019 (the A2C baseline,
//! the Manager, the Worker and `π_g`; sections 3.2 and 4) is the bird's-eye
//! maze as one-hot planes `[N, C, H, W]`: one channel per object kind, four
//! for the agent (one per facing), one plane set when the key is carried,
//! and, for the goal-conditioned networks, one marking goal cells.
//!
//! - [`encode_obs`] writes those planes densely: the plain path, a 3×3
//!   convolution over mostly-zero input.
//! - [`CellInput`] lists, for every output position of that convolution,
//!   the `(channel, kernel offset)` pairs whose input is 1. Since the input
//!   is 0/1, the convolution at a position is the sum of the kernel columns
//!   `W[:, c, k]` over that list: an `embedding_bag` (sum mode) over the
//!   kernel viewed as a `[C·9, out]` table ([`first_conv`]). It computes
//!   the same function and the same gradients with a small fraction of the
//!   multiply-adds (about ten table rows per position instead of `C·9`).
//!
//! Both forms are built straight from an [`ObsView`]; [`CellInput`] can
//! append many observation batches (a whole rollout) so the update encodes
//! `T·B` observations in one call.

use tch::{Kind, Tensor};

use crate::batch_env::ObsView;

/// Channels per object kind (`sim::object::NUM_OBJECTS`).
pub const OBJECT_CHANNELS: usize = sim::object::NUM_OBJECTS;
/// Object channels + 4 agent facings + 1 carried key.
pub const BASE_CHANNELS: usize = OBJECT_CHANNELS + 5;
/// Channel of the carried-key plane.
const KEY_CHANNEL: usize = OBJECT_CHANNELS + 4;
/// Channel marking goal cells (goal-conditioned networks only).
pub const GOAL_CHANNEL: usize = BASE_CHANNELS;
/// A goal slot that marks nothing.
pub const NO_GOAL: u32 = u32::MAX;
/// Positions of a 3×3 kernel.
const TAPS: usize = 9;

/// Goal cells to mark, `per_env` slots per environment (unused slots hold
/// [`NO_GOAL`]): one for `π_g` and the Feudal Worker, two (`g_w`, `g_n`)
/// for the Wide-then-Narrow Worker.
#[derive(Debug, Clone, Copy)]
pub struct GoalMarks<'a> {
    /// `N · per_env` cell indices.
    pub cells: &'a [u32],
    /// Slots per environment.
    pub per_env: usize,
}

impl<'a> GoalMarks<'a> {
    /// One goal cell per environment.
    pub fn one(cells: &'a [u32]) -> GoalMarks<'a> {
        GoalMarks { cells, per_env: 1 }
    }

    fn of(&self, env: usize) -> &'a [u32] {
        &self.cells[env * self.per_env..(env + 1) * self.per_env]
    }
}

/// The object channel of a cell code (codes past the last kind share its
/// channel, as in the dense encoding).
#[inline]
fn object_channel(code: u8) -> usize {
    (code as usize).min(OBJECT_CHANNELS - 1)
}

/// Dense one-hot planes `[N, C, H, W]` float32, `C = BASE_CHANNELS (+ 1 with
/// goals)`: the plain path's input.
pub fn encode_obs(obs: &ObsView<'_>, goals: Option<GoalMarks<'_>>) -> Tensor {
    let (n, h, w) = (obs.num_envs(), obs.height, obs.width);
    let c = BASE_CHANNELS + usize::from(goals.is_some());
    let hw = h * w;
    let mut buf = vec![0f32; n * c * hw];
    for i in 0..n {
        let base = i * c * hw;
        for (j, &code) in obs.env_cells(i).iter().enumerate() {
            buf[base + object_channel(code) * hw + j] = 1.0;
        }
        let m = &obs.meta[i];
        let agent = m.y as usize * w + m.x as usize;
        if agent < hw {
            buf[base + (OBJECT_CHANNELS + (m.dir as usize & 3)) * hw + agent] = 1.0;
        }
        if m.carrying == sim::Object::Key as u8 {
            buf[base + KEY_CHANNEL * hw..base + (KEY_CHANNEL + 1) * hw].fill(1.0);
        }
        if let Some(g) = goals {
            for &gc in g.of(i) {
                if (gc as usize) < hw {
                    buf[base + GOAL_CHANNEL * hw + gc as usize] = 1.0;
                }
            }
        }
    }
    Tensor::from_slice(&buf).view([n as i64, c as i64, h as i64, w as i64])
}

/// A batch of observations as the bags of the first convolution's
/// `embedding_bag` (module docs): for every observation and output position
/// `p` (row-major, `H·W` per observation), the table rows
/// `channel · 9 + tap` of the inputs that are 1 under the kernel centred on
/// `p`.
#[derive(Debug, Clone, Default)]
pub struct CellInput {
    width: usize,
    height: usize,
    goal_channel: bool,
    /// Table rows, bag after bag.
    indices: Vec<i64>,
    /// Start of each bag in `indices`, one per output position.
    offsets: Vec<i64>,
    /// Observations appended.
    len: usize,
    /// Per cell and tap: the input cell under that tap, or `u32::MAX`
    /// outside the grid (zero padding).
    neighbours: Vec<u32>,
}

impl CellInput {
    /// An empty batch for `width × height` grids, with or without the goal
    /// channel.
    pub fn new(width: usize, height: usize, goal_channel: bool) -> CellInput {
        let mut neighbours = Vec::with_capacity(width * height * TAPS);
        for y in 0..height as i64 {
            for x in 0..width as i64 {
                for ky in -1..=1 {
                    for kx in -1..=1 {
                        let (qy, qx) = (y + ky, x + kx);
                        let inside =
                            (0..height as i64).contains(&qy) && (0..width as i64).contains(&qx);
                        neighbours.push(if inside {
                            (qy * width as i64 + qx) as u32
                        } else {
                            u32::MAX
                        });
                    }
                }
            }
        }
        CellInput {
            width,
            height,
            goal_channel,
            neighbours,
            ..CellInput::default()
        }
    }

    /// Input channels of the convolution this batch feeds.
    pub fn channels(&self) -> usize {
        BASE_CHANNELS + usize::from(self.goal_channel)
    }

    /// Observations appended so far.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing was appended.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Forgets the observations, keeping the buffers.
    pub fn clear(&mut self) {
        self.indices.clear();
        self.offsets.clear();
        self.len = 0;
    }

    /// Appends every environment of `obs` (goal cells marked when this
    /// batch has the goal channel; `goals` is then required).
    pub fn push_obs(&mut self, obs: &ObsView<'_>, goals: Option<GoalMarks<'_>>) {
        for i in 0..obs.num_envs() {
            self.push_env(obs, i, goals);
        }
    }

    /// Appends environment `i` of `obs` only.
    pub fn push_env(&mut self, obs: &ObsView<'_>, i: usize, goals: Option<GoalMarks<'_>>) {
        debug_assert_eq!((obs.width, obs.height), (self.width, self.height));
        debug_assert_eq!(goals.is_some(), self.goal_channel);
        let hw = self.width * self.height;
        let cells = obs.env_cells(i);
        let m = &obs.meta[i];
        let agent = m.y as usize * self.width + m.x as usize;
        let agent_channel = OBJECT_CHANNELS + (m.dir as usize & 3);
        let key = m.carrying == sim::Object::Key as u8;
        let goal_cells: &[u32] = match goals {
            Some(g) if self.goal_channel => g.of(i),
            _ => &[],
        };
        self.indices.reserve(hw * (TAPS + 1));
        for p in 0..hw {
            self.offsets.push(self.indices.len() as i64);
            for (tap, &q) in self.neighbours[p * TAPS..(p + 1) * TAPS].iter().enumerate() {
                if q == u32::MAX {
                    continue;
                }
                let q = q as usize;
                self.indices
                    .push((object_channel(cells[q]) * TAPS + tap) as i64);
                if q == agent {
                    self.indices.push((agent_channel * TAPS + tap) as i64);
                }
                if key {
                    self.indices.push((KEY_CHANNEL * TAPS + tap) as i64);
                }
                if goal_cells.iter().any(|&g| g as usize == q) {
                    self.indices.push((GOAL_CHANNEL * TAPS + tap) as i64);
                }
            }
        }
        self.len += 1;
    }

    /// Appends every observation of `other` (same grid and channels).
    pub fn extend_from(&mut self, other: &CellInput) {
        debug_assert_eq!(
            (self.width, self.height, self.goal_channel),
            (other.width, other.height, other.goal_channel)
        );
        let shift = self.indices.len() as i64;
        self.offsets.extend(other.offsets.iter().map(|o| o + shift));
        self.indices.extend_from_slice(&other.indices);
        self.len += other.len;
    }

    /// Appends observation `k` of `other` only.
    pub fn extend_one(&mut self, other: &CellInput, k: usize) {
        let hw = self.width * self.height;
        let first = other.offsets[k * hw] as usize;
        let end = other
            .offsets
            .get((k + 1) * hw)
            .map_or(other.indices.len(), |&o| o as usize);
        let shift = self.indices.len() as i64 - first as i64;
        self.offsets.extend(
            other.offsets[k * hw..(k + 1) * hw]
                .iter()
                .map(|o| o + shift),
        );
        self.indices.extend_from_slice(&other.indices[first..end]);
        self.len += 1;
    }

    /// The bags as tensors `(indices, offsets)`.
    fn tensors(&self) -> (Tensor, Tensor) {
        (
            Tensor::from_slice(&self.indices),
            Tensor::from_slice(&self.offsets),
        )
    }
}

/// The first 3×3 convolution (stride 1, zero padding 1) applied to a
/// [`CellInput`]: `[N, out, H, W]` (channels-last in memory), equal to
/// `input.conv2d(weight, bias, 1, 1)` on the dense one-hot planes.
///
/// `weight` is the convolution's `[out, C, 3, 3]` kernel; its view as a
/// `[C·9, out]` table keeps gradients flowing into it.
pub fn first_conv(input: &CellInput, weight: &Tensor, bias: Option<&Tensor>) -> Tensor {
    let out = weight.size()[0];
    let table = weight.permute([1, 2, 3, 0]).reshape([-1, out]);
    let (indices, offsets) = input.tensors();
    let (bags, _, _, _) =
        Tensor::embedding_bag::<Tensor>(&table, &indices, &offsets, false, 0, false, None, false);
    let y = bags
        .view([
            input.len as i64,
            input.height as i64,
            input.width as i64,
            out,
        ])
        .permute([0, 3, 1, 2]);
    match bias {
        Some(b) => y + b.view([1, out, 1, 1]),
        None => y,
    }
}

/// Floats of a dense one-hot input of `n` observations (for FLOP counts).
pub fn dense_input_floats(n: usize, channels: usize, width: usize, height: usize) -> usize {
    n * channels * width * height
}

/// Mean bag size of a batch (table rows summed per output position).
pub fn mean_bag(input: &CellInput) -> f64 {
    if input.offsets.is_empty() {
        0.0
    } else {
        input.indices.len() as f64 / input.offsets.len() as f64
    }
}

/// `[N]` float mask, 1 where `flags[i]`.
pub fn mask(flags: &[bool]) -> Tensor {
    let v: Vec<f32> = flags.iter().map(|&f| f32::from(u8::from(f))).collect();
    Tensor::from_slice(&v).to_kind(Kind::Float)
}

#[cfg(test)]
mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use shm_schemas::EnvMeta;
    use tch::{Device, Kind, Tensor};

    use super::*;

    /// A random observation batch: any cell code, agent anywhere facing
    /// anywhere, the key carried or not.
    fn random_obs(rng: &mut SmallRng, n: usize, w: usize, h: usize) -> (Vec<u8>, Vec<EnvMeta>) {
        let cells: Vec<u8> = (0..n * w * h)
            .map(|_| rng.random_range(0..OBJECT_CHANNELS as u8 + 2))
            .collect();
        let meta = (0..n)
            .map(|_| EnvMeta {
                x: rng.random_range(0..w as u16),
                y: rng.random_range(0..h as u16),
                dir: rng.random_range(0..4),
                carrying: if rng.random_bool(0.5) {
                    sim::Object::Key as u8
                } else {
                    EnvMeta::CARRYING_NOTHING
                },
                ..EnvMeta::EMPTY
            })
            .collect();
        (cells, meta)
    }

    #[test]
    fn the_embedding_bag_first_layer_equals_the_dense_convolution() {
        let mut rng = SmallRng::seed_from_u64(5);
        for (w, h, goal_slots) in [(7, 5, 0), (13, 13, 1), (25, 19, 2), (4, 9, 1)] {
            let n = 6;
            let (cells, meta) = random_obs(&mut rng, n, w, h);
            let obs = ObsView {
                seq: 0,
                cells: &cells,
                meta: &meta,
                width: w,
                height: h,
            };
            let goal_cells: Vec<u32> = (0..n * goal_slots)
                .map(|k| {
                    if k % 3 == 2 {
                        NO_GOAL
                    } else {
                        rng.random_range(0..(w * h) as u32)
                    }
                })
                .collect();
            let goals = (goal_slots > 0).then_some(GoalMarks {
                cells: &goal_cells,
                per_env: goal_slots,
            });
            let channels = BASE_CHANNELS + usize::from(goals.is_some());
            let out = 16;
            // Double precision, so that the comparison is of the functions
            // and not of float rounding in two summation orders.
            let weight = (Tensor::randn([out, channels as i64, 3, 3], (Kind::Double, Device::Cpu))
                * 0.3)
                .set_requires_grad(true);
            let bias = Tensor::randn([out], (Kind::Double, Device::Cpu)).set_requires_grad(true);
            let upstream = Tensor::randn(
                [n as i64, out, h as i64, w as i64],
                (Kind::Double, Device::Cpu),
            );

            let dense = encode_obs(&obs, goals).to_kind(Kind::Double).conv2d(
                &weight,
                Some(&bias),
                [1, 1],
                [1, 1],
                [1, 1],
                1,
            );
            (&dense * &upstream).sum(Kind::Float).backward();
            let (gw_dense, gb_dense) = (weight.grad().copy(), bias.grad().copy());
            weight.grad().zero_();
            bias.grad().zero_();

            let mut input = CellInput::new(w, h, goals.is_some());
            input.push_obs(&obs, goals);
            assert_eq!(input.len(), n);
            let fast = first_conv(&input, &weight, Some(&bias));
            (&fast * &upstream).sum(Kind::Float).backward();
            let (gw_fast, gb_fast) = (weight.grad().copy(), bias.grad().copy());

            let diff = |a: &Tensor, b: &Tensor| (a - b).abs().max().double_value(&[]);
            assert_eq!(fast.size(), dense.size());
            assert!(
                diff(&fast, &dense) < 1e-5,
                "{w}×{h}: outputs differ by {}",
                diff(&fast, &dense)
            );
            assert!(
                diff(&gw_fast, &gw_dense) < 1e-5,
                "{w}×{h}: weight gradients differ by {}",
                diff(&gw_fast, &gw_dense)
            );
            assert!(
                diff(&gb_fast, &gb_dense) < 1e-5,
                "{w}×{h}: bias gradients differ"
            );
            // Far fewer table rows than dense multiply-adds per position.
            assert!(mean_bag(&input) < 12.0, "{}", mean_bag(&input));
        }
    }

    #[test]
    fn appended_batches_equal_one_batch() {
        let mut rng = SmallRng::seed_from_u64(8);
        let (w, h, n) = (6, 5, 4);
        let (cells, meta) = random_obs(&mut rng, n, w, h);
        let obs = ObsView {
            seq: 0,
            cells: &cells,
            meta: &meta,
            width: w,
            height: h,
        };
        let mut whole = CellInput::new(w, h, false);
        whole.push_obs(&obs, None);
        let mut parts = CellInput::new(w, h, false);
        let mut one = CellInput::new(w, h, false);
        for i in 0..n {
            one.clear();
            one.push_env(&obs, i, None);
            parts.extend_from(&one);
        }
        let mut picked = CellInput::new(w, h, false);
        for i in 0..n {
            picked.extend_one(&whole, i);
        }
        assert_eq!(parts.indices, whole.indices);
        assert_eq!(parts.offsets, whole.offsets);
        assert_eq!(picked.indices, whole.indices);
        assert_eq!(picked.offsets, whole.offsets);
    }
}
