//! The network's view of an observation batch, in two forms that compute
//! the same first convolution.
//!
//! The input of every actor-critic of Shang et al. 2019 (the A2C baseline,
//! the Manager, the Worker and `π_g`; sections 3.2 and 4) is the bird's-eye
//! maze as one-hot planes `[N, C, H, W]`: one channel per object kind, four
//! for the agent (one per facing), one plane set when the key is carried,
//! and, for the goal-conditioned networks, one plane per goal slot marking
//! its cell (`π_g` and the Feudal Worker: the goal; the Wide-then-Narrow
//! Worker: `g_w` and `g_n` on planes of their own, so it can tell them
//! apart).
//!
//! - [`encode_obs`] writes those planes densely: the plain path, a 3×3
//!   convolution over mostly-zero input.
//! - [`CellInput`] keeps the observation compact (each cell's object
//!   channel, the agent's pose, the key, the goal cells). Since the input
//!   is 0/1, the convolution at a position is the sum of the kernel columns
//!   `W[:, c, k]` of the inputs that are 1 under it: per tap `k`, one row of
//!   a 10-row table per cell (its object kind, or zero padding), plus the
//!   nine positions each agent or goal cell touches, plus the key plane's
//!   per-position sum ([`first_conv`], [`FirstLayer::Gather`]). It computes
//!   the same function and the same gradients with a small fraction of the
//!   multiply-adds (ten table rows per position instead of `C·9`).
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
pub const KEY_CHANNEL: usize = OBJECT_CHANNELS + 4;
/// Channel marking the first goal slot's cell (goal-conditioned networks
/// only); slot `k` marks channel `GOAL_CHANNEL + k`.
pub const GOAL_CHANNEL: usize = BASE_CHANNELS;
/// A goal slot that marks nothing.
pub const NO_GOAL: u32 = u32::MAX;
/// Positions of a 3×3 kernel.
const TAPS: usize = 9;
/// The object code of a neighbour outside the grid (zero padding).
const PAD_CODE: u64 = 0xF;

/// Goal cells to mark, `per_env` slots per environment (unused slots hold
/// [`NO_GOAL`]): one for `π_g` and the Feudal Worker, two (`g_w`, `g_n`)
/// for the Wide-then-Narrow Worker. Slot `k` has its own input plane.
#[derive(Debug, Clone, Copy)]
pub struct GoalMarks<'a> {
    /// `N · per_env` cell indices.
    pub cells: &'a [u32],
    /// Slots per environment.
    pub per_env: usize,
}

/// Goal planes of a network input with `goals` (0 without).
pub fn goal_planes(goals: Option<GoalMarks<'_>>) -> usize {
    goals.map_or(0, |g| g.per_env)
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
    let c = BASE_CHANNELS + goal_planes(goals);
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
            for (k, &gc) in g.of(i).iter().enumerate() {
                if (gc as usize) < hw {
                    buf[base + (GOAL_CHANNEL + k) * hw + gc as usize] = 1.0;
                }
            }
        }
    }
    Tensor::from_slice(&buf).view([n as i64, c as i64, h as i64, w as i64])
}

/// How the first convolution is computed from a [`CellInput`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FirstLayer {
    /// Gather-and-sum: per kernel tap, the kernel column of each cell's
    /// object kind (an `index_select` from a 10-row table), plus the few
    /// positions the agent and the goals touch, plus the key plane's
    /// per-position sum.
    #[default]
    Gather,
    /// The dense one-hot planes through the convolution.
    Dense,
}

/// A batch of observations in the compact form the first convolution
/// reads (module docs): each cell's object channel, the agent's cell and
/// facing, whether the key is carried, and the goal cells.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct CellInput {
    width: usize,
    height: usize,
    /// Goal slots (and goal planes) per observation.
    slots: usize,
    /// Object channel of every cell, observation after observation.
    codes: Vec<u8>,
    /// The agent's cell (or `u32::MAX` off the grid) and facing.
    agents: Vec<(u32, u8)>,
    /// The key is carried.
    keys: Vec<bool>,
    /// Goal cells, `slots` per observation ([`NO_GOAL`] for none).
    goals: Vec<u32>,
}

impl CellInput {
    /// An empty batch for `width × height` grids with `goal_planes` goal
    /// slots, each on its own input plane (0: no goal).
    pub fn new(width: usize, height: usize, goal_planes: usize) -> CellInput {
        CellInput {
            width,
            height,
            slots: goal_planes,
            ..CellInput::default()
        }
    }

    /// Input channels of the convolution this batch feeds.
    pub fn channels(&self) -> usize {
        BASE_CHANNELS + self.slots
    }

    /// Grid `(width, height)`.
    pub fn grid(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Observations appended so far.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// True when nothing was appended.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Forgets the observations, keeping the buffers.
    pub fn clear(&mut self) {
        self.codes.clear();
        self.agents.clear();
        self.keys.clear();
        self.goals.clear();
    }

    /// Appends every environment of `obs` (goal cells marked when this
    /// batch has the goal channel).
    pub fn push_obs(&mut self, obs: &ObsView<'_>, goals: Option<GoalMarks<'_>>) {
        for i in 0..obs.num_envs() {
            self.push_env(obs, i, goals);
        }
    }

    /// Appends environment `i` of `obs` only.
    pub fn push_env(&mut self, obs: &ObsView<'_>, i: usize, goals: Option<GoalMarks<'_>>) {
        let m = &obs.meta[i];
        let agent = m.y as usize * self.width + m.x as usize;
        self.push_grid(obs, obs.env_cells(i), agent, m.dir, m.carrying, i, goals);
    }

    /// Appends the *final* state of environment `i`'s episode that ended
    /// with the step that produced `obs`: the grid it ended on and the pose
    /// the last action led to (`obs.meta[i].done()` must hold). The input
    /// of the value that bootstraps a truncated step.
    pub fn push_final_env(&mut self, obs: &ObsView<'_>, i: usize, goals: Option<GoalMarks<'_>>) {
        let m = &obs.meta[i];
        debug_assert!(m.done(), "only an ended episode has a final state");
        let agent = m.end_y as usize * self.width + m.end_x as usize;
        self.push_grid(
            obs,
            obs.env_final_cells(i),
            agent,
            m.end_dir,
            m.end_carrying,
            i,
            goals,
        );
    }

    #[allow(clippy::too_many_arguments)]
    fn push_grid(
        &mut self,
        obs: &ObsView<'_>,
        cells: &[u8],
        agent: usize,
        dir: u8,
        carrying: u8,
        i: usize,
        goals: Option<GoalMarks<'_>>,
    ) {
        debug_assert_eq!((obs.width, obs.height), (self.width, self.height));
        let hw = self.width * self.height;
        self.codes
            .extend(cells.iter().map(|&c| object_channel(c) as u8));
        self.agents
            .push((if agent < hw { agent as u32 } else { u32::MAX }, dir & 3));
        self.keys.push(carrying == sim::Object::Key as u8);
        if self.slots > 0 {
            let g = goals.map_or(&[][..], |g| g.of(i));
            debug_assert!(g.len() <= self.slots, "more goal slots than planes");
            for k in 0..self.slots {
                self.goals.push(g.get(k).copied().unwrap_or(NO_GOAL));
            }
        }
    }

    /// Appends every observation of `other` (same grid and channels).
    pub fn extend_from(&mut self, other: &CellInput) {
        for k in 0..other.len() {
            self.extend_one(other, k);
        }
    }

    /// Appends observation `k` of `other` only.
    pub fn extend_one(&mut self, other: &CellInput, k: usize) {
        let hw = self.width * self.height;
        self.codes
            .extend_from_slice(&other.codes[k * hw..(k + 1) * hw]);
        self.agents.push(other.agents[k]);
        self.keys.push(other.keys[k]);
        if self.slots > 0 {
            debug_assert_eq!(self.slots, other.slots, "goal planes differ");
            self.goals
                .extend_from_slice(&other.goals[k * other.slots..(k + 1) * other.slots]);
        }
    }

    /// The dense one-hot planes `[N, C, H, W]` of the batch.
    pub fn to_dense(&self) -> Tensor {
        let (n, hw) = (self.len(), self.width * self.height);
        let c = self.channels();
        let mut buf = vec![0f32; n * c * hw];
        for i in 0..n {
            let base = i * c * hw;
            for (j, &code) in self.codes[i * hw..(i + 1) * hw].iter().enumerate() {
                buf[base + code as usize * hw + j] = 1.0;
            }
            let (agent, dir) = self.agents[i];
            if agent != u32::MAX {
                buf[base + (OBJECT_CHANNELS + dir as usize) * hw + agent as usize] = 1.0;
            }
            if self.keys[i] {
                buf[base + KEY_CHANNEL * hw..base + (KEY_CHANNEL + 1) * hw].fill(1.0);
            }
            for (k, &g) in self.goals[i * self.slots..(i + 1) * self.slots]
                .iter()
                .enumerate()
            {
                if (g as usize) < hw {
                    buf[base + (GOAL_CHANNEL + k) * hw + g as usize] = 1.0;
                }
            }
        }
        Tensor::from_slice(&buf).view([n as i64, c as i64, self.height as i64, self.width as i64])
    }

    /// The ones of observation `i`'s dense planes under a 3×3 kernel
    /// (stride 1, zero padding 1) from its objects and the key, position by
    /// position: calls `f(position, rows)` for every output cell `position
    /// = y · width + x` with the table rows `channel · 9 + tap` (`tap = 3 ·
    /// (dy + 1) + (dx + 1)`) of its inputs (at most 18). With
    /// [`Self::for_each_mark`], the first convolution at a position is the
    /// sum of the kernel columns of its rows (the own kernel of
    /// [`crate::a2c::kernels::FirstConv`]).
    #[inline(always)]
    pub fn for_each_position(&self, i: usize, mut f: impl FnMut(usize, &[usize])) {
        let (w, h) = (self.width as i64, self.height as i64);
        let hw = self.width * self.height;
        let codes = &self.codes[i * hw..(i + 1) * hw];
        let key = self.keys[i];
        let mut rows = [0usize; 2 * TAPS];
        for y in 0..h {
            for x in 0..w {
                let mut len = 0;
                for (k, dy, dx) in CellInput::taps() {
                    let (qy, qx) = (y + dy, x + dx);
                    if (0..h).contains(&qy) && (0..w).contains(&qx) {
                        rows[len] = codes[(qy * w + qx) as usize] as usize * TAPS + k;
                        len += 1;
                        if key {
                            rows[len] = KEY_CHANNEL * TAPS + k;
                            len += 1;
                        }
                    }
                }
                f((y * w + x) as usize, &rows[..len]);
            }
        }
    }

    /// The rest of [`Self::for_each_position`]'s ones: calls
    /// `mark(position, row)` for each input the agent's and the goals'
    /// planes put under the kernel at `position` (nine or fewer per marked
    /// cell).
    #[inline(always)]
    pub fn for_each_mark(&self, i: usize, mut mark: impl FnMut(usize, usize)) {
        let (w, h) = (self.width as i64, self.height as i64);
        let hw = self.width * self.height;
        let mut marks = |q: u32, channel: usize| {
            let (qy, qx) = (i64::from(q) / w, i64::from(q) % w);
            for (k, dy, dx) in CellInput::taps() {
                let (py, px) = (qy - dy, qx - dx);
                if (0..h).contains(&py) && (0..w).contains(&px) {
                    mark((py * w + px) as usize, channel * TAPS + k);
                }
            }
        };
        let (agent, dir) = self.agents[i];
        if agent != u32::MAX {
            marks(agent, OBJECT_CHANNELS + dir as usize);
        }
        for (k, &g) in self.goals[i * self.slots..(i + 1) * self.slots]
            .iter()
            .enumerate()
        {
            if (g as usize) < hw {
                marks(g, GOAL_CHANNEL + k);
            }
        }
    }

    /// The kernel tap offsets `(dy, dx)` in the order of a 3×3 kernel.
    fn taps() -> impl Iterator<Item = (usize, i64, i64)> {
        (0..TAPS).map(|k| (k, k as i64 / 3 - 1, k as i64 % 3 - 1))
    }
}

/// The first 3×3 convolution (stride 1, zero padding 1) of a
/// [`CellInput`], `[N, out, H, W]`, equal to `conv2d` over the dense
/// one-hot planes; `weight` is the `[out, C, 3, 3]` kernel.
pub fn first_conv(
    input: &CellInput,
    weight: &Tensor,
    bias: Option<&Tensor>,
    layer: FirstLayer,
) -> Tensor {
    let (w, h) = (input.width, input.height);
    let (n, hw) = (input.len(), w * h);
    let out = weight.size()[0];
    let y = match layer {
        FirstLayer::Dense => {
            return input
                .to_dense()
                .conv2d(weight, bias, [1, 1], [1, 1], [1, 1], 1);
        }
        FirstLayer::Gather => {
            // Each position's 3×3 neighbourhood of object channels (10 for
            // zero padding) and the key bit is a *pattern*; mazes have few.
            // The object and key part of the convolution at a position is
            // its pattern's row of `M · W`, `M` counting, per pattern, the
            // table rows `channel · 9 + tap` that are 1 under the kernel.
            let mut ids: std::collections::HashMap<u64, i64> = std::collections::HashMap::new();
            let mut patterns: Vec<u64> = Vec::new();
            let mut pid = vec![0i64; n * hw];
            for i in 0..n {
                let codes = &input.codes[i * hw..(i + 1) * hw];
                let key = u64::from(input.keys[i]) << 40;
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let mut p = key;
                        for (k, dy, dx) in CellInput::taps() {
                            let (qy, qx) = (y + dy, x + dx);
                            let code = if (0..h as i64).contains(&qy) && (0..w as i64).contains(&qx)
                            {
                                u64::from(codes[(qy * w as i64 + qx) as usize])
                            } else {
                                PAD_CODE
                            };
                            p |= code << (4 * k);
                        }
                        let next = patterns.len() as i64;
                        let id = *ids.entry(p).or_insert(next);
                        if id == next {
                            patterns.push(p);
                        }
                        pid[i * hw + (y * w as i64 + x) as usize] = id;
                    }
                }
            }
            let channels = weight.size()[1];
            let rows = channels * TAPS as i64;
            let mut m = vec![0f32; patterns.len() * rows as usize];
            for (j, &p) in patterns.iter().enumerate() {
                let key = p >> 40 & 1 == 1;
                for k in 0..TAPS {
                    let code = (p >> (4 * k)) & 0xF;
                    if code != PAD_CODE {
                        m[j * rows as usize + code as usize * TAPS + k] += 1.0;
                        if key {
                            m[j * rows as usize + KEY_CHANNEL * TAPS + k] += 1.0;
                        }
                    }
                }
            }
            let table = weight.permute([1, 2, 3, 0]).reshape([rows, out]); // [C·9, out]
            let m = Tensor::from_slice(&m)
                .view([patterns.len() as i64, rows])
                .to_kind(weight.kind());
            let mut y = m.matmul(&table).index_select(0, &Tensor::from_slice(&pid));
            // The agent's and the goals' few positions: for every cell q
            // they mark and every tap k with p = q − offset(k) inside.
            let (mut pos, mut rows) = (Vec::new(), Vec::new());
            let mut mark = |i: usize, q: u32, channel: usize| {
                let (qy, qx) = ((q as usize / w) as i64, (q as usize % w) as i64);
                for (k, dy, dx) in CellInput::taps() {
                    let (py, px) = (qy - dy, qx - dx);
                    if (0..h as i64).contains(&py) && (0..w as i64).contains(&px) {
                        pos.push((i * hw) as i64 + py * w as i64 + px);
                        rows.push((channel * TAPS + k) as i64);
                    }
                }
            };
            for i in 0..n {
                let (agent, dir) = input.agents[i];
                if agent != u32::MAX {
                    mark(i, agent, OBJECT_CHANNELS + dir as usize);
                }
                for (k, &g) in input.goals[i * input.slots..(i + 1) * input.slots]
                    .iter()
                    .enumerate()
                {
                    if (g as usize) < hw {
                        mark(i, g, GOAL_CHANNEL + k);
                    }
                }
            }
            if !pos.is_empty() {
                let extra = table.index_select(0, &Tensor::from_slice(&rows));
                y = y.index_add(0, &Tensor::from_slice(&pos), &extra);
            }
            y.view([n as i64, h as i64, w as i64, out])
                .permute([0, 3, 1, 2])
        }
    };
    match bias {
        Some(b) => y + b.view([1, out, 1, 1]),
        None => y,
    }
}

/// `[N]` float mask, 1 where `flags[i]`.
pub fn mask(flags: &[bool]) -> Tensor {
    let v: Vec<f32> = flags.iter().map(|&f| f32::from(u8::from(f))).collect();
    Tensor::from_slice(&v).to_kind(Kind::Float)
}

/// A random observation batch for tests: any cell code, agents anywhere
/// facing anywhere, each carrying the key with probability `p_key`.
#[cfg(test)]
pub(crate) fn random_obs(
    rng: &mut rand::rngs::SmallRng,
    n: usize,
    w: usize,
    h: usize,
    p_key: f64,
) -> (Vec<u8>, Vec<shm_schemas::EnvMeta>) {
    use rand::Rng;
    use shm_schemas::EnvMeta;
    let cells: Vec<u8> = (0..n * w * h)
        .map(|_| rng.random_range(0..OBJECT_CHANNELS as u8 + 2))
        .collect();
    let meta = (0..n)
        .map(|_| EnvMeta {
            x: rng.random_range(0..w as u16),
            y: rng.random_range(0..h as u16),
            dir: rng.random_range(0..4),
            carrying: if rng.random_bool(p_key) {
                sim::Object::Key as u8
            } else {
                EnvMeta::CARRYING_NOTHING
            },
            ..EnvMeta::EMPTY
        })
        .collect();
    (cells, meta)
}

/// The observation view of a test batch: `cells` and `meta` of
/// `meta.len()` environments on a `w × h` grid, no final states.
#[cfg(test)]
pub(crate) fn test_view<'a>(
    cells: &'a [u8],
    meta: &'a [shm_schemas::EnvMeta],
    w: usize,
    h: usize,
) -> ObsView<'a> {
    ObsView {
        seq: 0,
        cells,
        final_cells: &[],
        meta,
        width: w,
        height: h,
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use tch::{Device, Kind, Tensor};

    use super::*;

    #[test]
    fn the_embedding_bag_first_layer_equals_the_dense_convolution() {
        let mut rng = SmallRng::seed_from_u64(5);
        for (w, h, goal_slots) in [(7, 5, 0), (13, 13, 1), (25, 19, 2), (4, 9, 1)] {
            let n = 6;
            let (cells, meta) = random_obs(&mut rng, n, w, h, 0.5);
            let obs = test_view(&cells, &meta, w, h);
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
            let channels = BASE_CHANNELS + goal_planes(goals);
            let out = 16;
            // Double precision, so that the comparison is of the functions
            // and not of float rounding in two summation orders.
            let (weight, bias, upstream) = crate::seeding::init_seeded(rng.random(), || {
                let opts = (Kind::Double, Device::Cpu);
                (
                    (Tensor::randn([out, channels as i64, 3, 3], opts) * 0.3)
                        .set_requires_grad(true),
                    Tensor::randn([out], opts).set_requires_grad(true),
                    Tensor::randn([n as i64, out, h as i64, w as i64], opts),
                )
            });

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
            let _ = weight.grad().zero_();
            let _ = bias.grad().zero_();

            let mut input = CellInput::new(w, h, goal_planes(goals));
            input.push_obs(&obs, goals);
            assert_eq!(input.len(), n);
            assert!(
                input
                    .to_dense()
                    .to_kind(Kind::Double)
                    .equal(&encode_obs(&obs, goals).to_kind(Kind::Double))
            );
            let fast = first_conv(&input, &weight, Some(&bias), FirstLayer::Gather);
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
        }
    }

    #[test]
    fn appended_batches_equal_one_batch() {
        let mut rng = SmallRng::seed_from_u64(8);
        let (w, h, n) = (6, 5, 4);
        let (cells, meta) = random_obs(&mut rng, n, w, h, 0.5);
        let obs = test_view(&cells, &meta, w, h);
        let mut whole = CellInput::new(w, h, 0);
        whole.push_obs(&obs, None);
        let mut parts = CellInput::new(w, h, 0);
        let mut one = CellInput::new(w, h, 0);
        for i in 0..n {
            one.clear();
            one.push_env(&obs, i, None);
            parts.extend_from(&one);
        }
        let mut picked = CellInput::new(w, h, 0);
        for i in 0..n {
            picked.extend_one(&whole, i);
        }
        assert!(parts.to_dense().equal(&whole.to_dense()));
        assert!(picked.to_dense().equal(&whole.to_dense()));
    }
}
