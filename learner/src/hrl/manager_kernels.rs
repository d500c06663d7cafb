//! The Manager's decisions in the project's own kernels (the
//! [`GradPath::RustCore`] path): its encoder and LSTM core
//! ([`RustEncoder`], [`LstmCell`]), its value head, the goal map
//! ([`GoalMap`]: the first convolution as [`FirstConv`], the second as a
//! direct 3×3 sum) and the goal heads — FN's softmax over the valid cells
//! (section 4.1), WN's `π^ω` and `π^n` (section 4.2) — on floats, without
//! tch's per-operation dispatch.
//!
//! The Manager decides for one or two environments at most batch steps,
//! so a decision is about sixty tch operations on one or two rows each:
//! small work behind a fixed cost per operation. Here it is one pass over
//! floats. The Manager's update stays in tch ([`super::feudal::Manager::loss`]);
//! the weights are read again after every update ([`OwnManager::load`]).
//!
//! Equal function: `tests` compares the core state, values and every
//! probability with the tch Manager's ([`super::feudal::Manager::act`],
//! [`GoalMap`], [`WideNarrowHead`]) to 1e-5.
//!
//! [`GradPath::RustCore`]: crate::a2c::rollout::GradPath::RustCore
//! [`GoalMap`]: super::feudal::GoalMap
//! [`WideNarrowHead`]: super::wide_narrow::WideNarrowHead

use tch::nn;

use super::feudal::{Manager, ManagerHead, OwnTrunk};
use crate::a2c::MASKED_LOGIT;
use crate::a2c::encoder::RustEncoder;
use crate::a2c::gemm::{Mat, matmul, transposed};
use crate::a2c::input::CellInput;
use crate::a2c::kernels::FirstConv;
use crate::a2c::lstm::{LstmCell, Sequence};
use crate::a2c::rust_net::{CoreWeights, trunk_backward};
use crate::a2c::tensors::floats;

/// A linear layer as the forward reads it: the weight transposed `[in,
/// out]` and the bias.
#[derive(Debug, Default)]
struct Dense {
    w_t: Vec<f32>,
    b: Vec<f32>,
}

impl Dense {
    fn of(l: &nn::Linear) -> Dense {
        let size = l.ws.size();
        let (out, inp) = (size[0] as usize, size[1] as usize);
        Dense {
            w_t: transposed(&floats(&l.ws.detach()), out, inp),
            b: l.bs
                .as_ref()
                .map_or(vec![0.0; out], |b| floats(&b.detach())),
        }
    }

    /// `y = x·Wᵀ + b` over the `n` rows of `x`.
    fn forward(&self, x: &[f32], n: usize) -> Vec<f32> {
        let out = self.b.len();
        let inp = self.w_t.len() / out;
        let mut y = Vec::with_capacity(n * out);
        for _ in 0..n {
            y.extend_from_slice(&self.b);
        }
        matmul(
            &mut y,
            Mat::rows(x, n, inp),
            Mat::rows(&self.w_t, inp, out),
            true,
        );
        y
    }
}

/// The goal map's weights in the kernels' layouts.
#[derive(Debug)]
struct OwnGoalMap {
    first: FirstConv,
    /// The first convolution's table and bias.
    table: Vec<f32>,
    b1: Vec<f32>,
    /// The second convolution's weight per tap and channel `[9, c]`, and
    /// bias.
    w2: Vec<f32>,
    b2: f32,
    /// The cells `π^ω` (or FN's head) reads (`None`: every cell).
    cells: Option<Vec<usize>>,
    /// With windows: every candidate's window cells and valid slots
    /// `[|V|·N·N]`.
    windows: Option<(Vec<usize>, Vec<bool>)>,
}

impl OwnGoalMap {
    fn of(map: &super::feudal::GoalMap, width: usize, height: usize) -> OwnGoalMap {
        let (conv1, conv2, cells, windows) = map.parts();
        let size = conv1.ws.size();
        let first = FirstConv {
            width,
            height,
            channels: size[1] as usize,
            out: size[0] as usize,
        };
        let bias = |c: &nn::Conv2D, n: usize| c.bs.as_ref().map_or(vec![0.0; n], floats);
        let c = first.out;
        let torch2 = floats(&conv2.ws.detach());
        let mut w2 = vec![0f32; 9 * c];
        for ch in 0..c {
            for tap in 0..9 {
                w2[tap * c + ch] = torch2[ch * 9 + tap];
            }
        }
        let cells_of = |t: &tch::Tensor| -> Vec<usize> {
            Vec::<i64>::try_from(&t.flatten(0, -1))
                .expect("invariant: cell indices are int64")
                .into_iter()
                .map(|i| i as usize)
                .collect()
        };
        OwnGoalMap {
            table: first.table(&floats(&conv1.ws.detach())),
            b1: bias(conv1, c),
            w2,
            b2: bias(conv2, 1)[0],
            cells: cells.map(cells_of),
            windows: windows.map(|[cells, valid]| {
                let valid = Vec::<bool>::try_from(&valid.flatten(0, -1))
                    .expect("invariant: window slots are bool");
                (cells_of(cells), valid)
            }),
            first,
        }
    }

    /// The map `[n, H·W]` of the `n` observations of `input`.
    fn map(&self, input: &CellInput) -> Vec<f32> {
        let n = input.len();
        let (w, h, c) = (self.first.width, self.first.height, self.first.out);
        let mut y1 = vec![0f32; n * self.first.out_len()];
        self.first
            .forward(input, 0, n, &self.table, &self.b1, &mut y1);
        let mut map = vec![self.b2; n * w * h];
        for (row, out) in y1
            .chunks_exact(self.first.out_len())
            .zip(map.chunks_exact_mut(w * h))
        {
            for y in 0..h {
                for x in 0..w {
                    let mut acc = 0f32;
                    for ky in 0..3 {
                        let yy = y as isize + ky as isize - 1;
                        if !(0..h as isize).contains(&yy) {
                            continue;
                        }
                        for kx in 0..3 {
                            let xx = x as isize + kx as isize - 1;
                            if !(0..w as isize).contains(&xx) {
                                continue;
                            }
                            let src = &row[(yy as usize * w + xx as usize) * c..][..c];
                            let wt = &self.w2[(ky * 3 + kx) * c..][..c];
                            acc += src.iter().zip(wt).map(|(a, b)| a * b).sum::<f32>();
                        }
                    }
                    out[y * w + x] += acc;
                }
            }
        }
        map
    }
}

/// The goal heads' weights.
#[derive(Debug)]
enum OwnHead {
    /// FN: logits over the `H·W` cells and which are valid subgoals.
    Feudal { cells: Dense, valid: Vec<bool> },
    /// WN: `π^ω`, `π^n`'s hidden and output layers, `|V|` and the window.
    WideNarrow {
        wide: Dense,
        narrow_hidden: Dense,
        narrow_out: Dense,
        candidates: usize,
        window: usize,
    },
}

/// The Manager's network in the kernels' layouts, for its decisions
/// (module docs).
#[derive(Debug)]
pub(super) struct OwnManager {
    encoder: RustEncoder,
    cell: LstmCell,
    core: CoreWeights,
    /// The update's unroll ([`OwnManager::unroll`]): per row `k·B + b`,
    /// the state it started from, its gates, `tanh` of its cell state, and
    /// whether it continues the previous step.
    h_in: Vec<f32>,
    c_in: Vec<f32>,
    gates: Vec<f32>,
    tanh_c: Vec<f32>,
    continues: Vec<bool>,
    value: Dense,
    head: OwnHead,
    map: Option<OwnGoalMap>,
    width: usize,
    height: usize,
}

/// One batch of decisions: the core's new state, the values and the goal
/// map's logits (`[n, H·W]`), every row one environment.
#[derive(Debug)]
pub(super) struct OwnDecision {
    /// Rows.
    pub(super) n: usize,
    /// The core's output `h_t` and cell state `[n, hidden]`.
    pub(super) h: Vec<f32>,
    pub(super) c: Vec<f32>,
    /// `V(s)` `[n]`.
    pub(super) values: Vec<f32>,
    map: Option<Vec<f32>>,
}

impl OwnManager {
    /// The Manager `net` on a `width × height` grid, with its current
    /// weights.
    pub(super) fn new(net: &Manager, width: usize, height: usize) -> OwnManager {
        let trunk = net.trunk();
        let hidden = trunk.hidden() as usize;
        let mut own = OwnManager {
            encoder: RustEncoder::new(trunk),
            cell: LstmCell {
                input: hidden,
                hidden,
            },
            core: CoreWeights::default(),
            h_in: Vec::new(),
            c_in: Vec::new(),
            gates: Vec::new(),
            tanh_c: Vec::new(),
            continues: Vec::new(),
            value: Dense::default(),
            head: OwnHead::Feudal {
                cells: Dense::default(),
                valid: Vec::new(),
            },
            map: None,
            width,
            height,
        };
        own.load(net);
        own
    }

    /// Reads the network's current weights (after each of its updates).
    pub(super) fn load(&mut self, net: &Manager) {
        let trunk = net.trunk();
        self.encoder.load(trunk);
        self.core = CoreWeights::of(trunk, &self.cell);
        self.value = Dense::of(net.value_head());
        self.head = match net.head() {
            ManagerHead::Feudal { cells, valid } => OwnHead::Feudal {
                cells: Dense::of(cells),
                valid: Vec::<bool>::try_from(valid).expect("invariant: valid cells are bool"),
            },
            ManagerHead::WideNarrow(head) => {
                let [wide, narrow_hidden, narrow_out] = head.layers();
                let wide = Dense::of(wide);
                OwnHead::WideNarrow {
                    candidates: wide.b.len(),
                    window: head.window_len(),
                    wide,
                    narrow_hidden: Dense::of(narrow_hidden),
                    narrow_out: Dense::of(narrow_out),
                }
            }
        };
        self.map = net
            .goal_map()
            .map(|m| OwnGoalMap::of(m, self.width, self.height));
    }

    /// One step of the core on the `n` observations of `input` from the
    /// state `h`, `c` (`[n, hidden]`, already reset where a decision starts
    /// an episode), the values, and the goal map's logits.
    pub(super) fn act(&mut self, input: &CellInput, h: &[f32], c: &[f32]) -> OwnDecision {
        let n = input.len();
        let hd = self.cell.hidden;
        self.encoder.clear();
        let x = self.encoder.encode(input);
        let mut gates = vec![0f32; n * 4 * hd];
        let (mut c_out, mut tanh_c, mut h_out) =
            (vec![0f32; n * hd], vec![0f32; n * hd], vec![0f32; n * hd]);
        self.cell.forward(
            x,
            h,
            c,
            n,
            &self.core.w_ih_t,
            &self.core.w_hh_t,
            &self.core.bias,
            &mut gates,
            &mut c_out,
            &mut tanh_c,
            &mut h_out,
        );
        let values = self.value.forward(&h_out, n);
        OwnDecision {
            n,
            map: self.map.as_ref().map(|m| m.map(input)),
            h: h_out,
            c: c_out,
            values,
        }
    }

    /// FN: the subgoal probabilities `[n, H·W]` (section 4.1), the goal
    /// map's logits added and invalid cells at probability 0.
    pub(super) fn feudal_probs(&self, d: &OwnDecision) -> Vec<f32> {
        let OwnHead::Feudal { cells, valid } = &self.head else {
            panic!("feudal_probs of a Wide-then-Narrow Manager");
        };
        let mut logits = cells.forward(&d.h, d.n);
        let width = valid.len();
        if let (Some(map), Some(m)) = (&d.map, &self.map) {
            for (row, map_row) in logits
                .chunks_exact_mut(width)
                .zip(map.chunks_exact(self.width * self.height))
            {
                match &m.cells {
                    Some(cs) => row.iter_mut().zip(cs).for_each(|(l, &k)| *l += map_row[k]),
                    None => row.iter_mut().zip(map_row).for_each(|(l, v)| *l += v),
                }
            }
        }
        let valid: Vec<bool> = (0..d.n).flat_map(|_| valid.iter().copied()).collect();
        softmax_rows(&mut logits, width, Some(&valid));
        logits
    }

    /// WN: `π^ω`'s probabilities `[n, |V|]`, plus the goal map's logits
    /// (its log-sum-exp over each window when the map has windows).
    pub(super) fn wide_probs(&self, d: &OwnDecision) -> Vec<f32> {
        let OwnHead::WideNarrow {
            wide, candidates, ..
        } = &self.head
        else {
            panic!("wide_probs of a Feudal Manager");
        };
        let v = *candidates;
        let mut logits = wide.forward(&d.h, d.n);
        if let (Some(map), Some(m)) = (&d.map, &self.map) {
            for (row, map_row) in logits
                .chunks_exact_mut(v)
                .zip(map.chunks_exact(self.width * self.height))
            {
                match (&m.windows, &m.cells) {
                    (Some((cells, valid)), _) => {
                        let len = cells.len() / v;
                        for (j, l) in row.iter_mut().enumerate() {
                            let at: Vec<f32> = (j * len..(j + 1) * len)
                                .map(|s| {
                                    if valid[s] {
                                        map_row[cells[s]]
                                    } else {
                                        MASKED_LOGIT as f32
                                    }
                                })
                                .collect();
                            *l += logsumexp(&at);
                        }
                    }
                    (None, Some(cells)) => {
                        row.iter_mut()
                            .zip(cells)
                            .for_each(|(l, &k)| *l += map_row[k]);
                    }
                    (None, None) => row.iter_mut().zip(map_row).for_each(|(l, x)| *l += x),
                }
            }
        }
        softmax_rows(&mut logits, v, None);
        logits
    }

    /// WN: `π^n`'s probabilities `[n, N·N]` around the drawn wide goals
    /// `wide` (indices in `V`), from the local inputs `local` `[n,
    /// N·N·WINDOW_CHANNELS]` and valid slots `valid` `[n, N·N]`, plus the
    /// goal map's logits of the window cells when the map has windows.
    pub(super) fn narrow_probs(
        &self,
        d: &OwnDecision,
        wide: &[usize],
        local: &[f32],
        valid: &[bool],
    ) -> Vec<f32> {
        let OwnHead::WideNarrow {
            narrow_hidden,
            narrow_out,
            candidates,
            window,
            ..
        } = &self.head
        else {
            panic!("narrow_probs of a Feudal Manager");
        };
        let (n, hd, v, win) = (d.n, self.cell.hidden, *candidates, *window);
        let per_local = local.len() / n.max(1);
        let inp = hd + per_local + v;
        let mut x = vec![0f32; n * inp];
        for (r, row) in x.chunks_exact_mut(inp).enumerate() {
            row[..hd].copy_from_slice(&d.h[r * hd..][..hd]);
            row[hd..hd + per_local].copy_from_slice(&local[r * per_local..][..per_local]);
            row[hd + per_local + wide[r]] = 1.0;
        }
        let mut hidden = narrow_hidden.forward(&x, n);
        hidden.iter_mut().for_each(|z| *z = z.max(0.0));
        let mut logits = narrow_out.forward(&hidden, n);
        if let (Some(map), Some((cells, _))) =
            (&d.map, self.map.as_ref().and_then(|m| m.windows.as_ref()))
        {
            for (r, row) in logits.chunks_exact_mut(win).enumerate() {
                let map_row = &map[r * self.width * self.height..][..self.width * self.height];
                let slots = &cells[wide[r] * win..][..win];
                row.iter_mut()
                    .zip(slots)
                    .for_each(|(l, &k)| *l += map_row[k]);
            }
        }
        softmax_rows(&mut logits, win, Some(valid));
        logits
    }
}

impl OwnTrunk for OwnManager {
    /// The update's forward pass through the trunk: the features of the
    /// `K·B` observations of `input` (step-major: row `k·B + b` is
    /// environment `b`'s decision `k`), then the core over the `K` steps
    /// from `init_h`, `init_c` (`[B, hidden]`), its state zeroed before
    /// row `i` where `reset[i]` (as [`crate::a2c::net::Trunk::unroll_states`]).
    /// Returns the hidden and cell states after every row, `[K·B,
    /// hidden]` each; the activations stay for [`Self::unroll_backward`].
    fn unroll(
        &mut self,
        input: &CellInput,
        init_h: &[f32],
        init_c: &[f32],
        reset: &[bool],
        b: usize,
    ) -> (Vec<f32>, Vec<f32>) {
        let (hd, g4) = (self.cell.hidden, 4 * self.cell.hidden);
        let rows = input.len();
        let k = rows / b;
        self.encoder.clear();
        self.encoder.encode(input);
        let x = self.encoder.features();
        let (mut hs, mut cs) = (vec![0f32; rows * hd], vec![0f32; rows * hd]);
        self.h_in = vec![0f32; rows * hd];
        self.c_in = vec![0f32; rows * hd];
        self.gates = vec![0f32; rows * g4];
        self.tanh_c = vec![0f32; rows * hd];
        self.continues = vec![false; rows];
        for t in 0..k {
            for e in 0..b {
                let i = t * b + e;
                let dst = i * hd..(i + 1) * hd;
                if reset[i] {
                    continue;
                }
                self.continues[i] = t > 0;
                let (h, c) = if t == 0 {
                    (&init_h[e * hd..][..hd], &init_c[e * hd..][..hd])
                } else {
                    (&hs[(i - b) * hd..][..hd], &cs[(i - b) * hd..][..hd])
                };
                self.h_in[dst.clone()].copy_from_slice(h);
                self.c_in[dst].copy_from_slice(c);
            }
            let r = t * b..(t + 1) * b;
            self.cell.forward(
                &x[r.start * hd..r.end * hd],
                &self.h_in[r.start * hd..r.end * hd],
                &self.c_in[r.start * hd..r.end * hd],
                b,
                &self.core.w_ih_t,
                &self.core.w_hh_t,
                &self.core.bias,
                &mut self.gates[r.start * g4..r.end * g4],
                &mut cs[r.start * hd..r.end * hd],
                &mut self.tanh_c[r.start * hd..r.end * hd],
                &mut hs[r.start * hd..r.end * hd],
            );
        }
        (hs, cs)
    }

    /// The backward pass of [`Self::unroll`] from the loss's gradient
    /// `dh` `[K·B, hidden]` of its hidden states: the gradients of the
    /// trunk's [`crate::a2c::net::Trunk::encoder_parameters`] then
    /// [`crate::a2c::net::Trunk::core_parameters`], in tch's layouts.
    fn unroll_backward(&mut self, dh: &[f32], b: usize) -> Vec<tch::Tensor> {
        let seq = Sequence {
            gates: &self.gates,
            c_in: &self.c_in,
            tanh_c: &self.tanh_c,
            continues: &self.continues,
        };
        trunk_backward(
            &mut self.encoder,
            &self.cell,
            &self.core,
            &seq,
            &self.h_in,
            b,
            dh,
        )
    }
}

/// `log Σ eˣ` of `x`, as tch computes it (the maximum taken out first).
fn logsumexp(x: &[f32]) -> f32 {
    let m = x.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    m + x.iter().map(|&v| (v - m).exp()).sum::<f32>().ln()
}

/// Each `width`-wide row of `logits` turned into probabilities in place,
/// as [`crate::a2c::Categorical`] does: invalid entries (`valid` false)
/// masked to [`MASKED_LOGIT`], then `exp(log_softmax)`.
fn softmax_rows(logits: &mut [f32], width: usize, valid: Option<&[bool]>) {
    if let Some(valid) = valid {
        for (l, &ok) in logits.iter_mut().zip(valid) {
            if !ok {
                *l = MASKED_LOGIT as f32;
            }
        }
    }
    for row in logits.chunks_exact_mut(width) {
        let lse = logsumexp(row);
        row.iter_mut().for_each(|l| *l = (*l - lse).exp());
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use sim::Maze;
    use tch::{Kind, Tensor};

    use super::*;
    use crate::a2c::kernels::tests::rel_diff;
    use crate::a2c::net::LstmState;
    use crate::hrl::config::{AgentConfig, AgentKind, Candidates};
    use crate::hrl::feudal::{Decision, DecisionQueue};
    use crate::hrl::manager::ManagerSide;

    /// A Manager of `kind` on the small maze with a goal map (over windows
    /// for WN), its weights moved off their initial values (the map's last
    /// layer starts at zero), and observations from the simulator.
    fn manager(kind: AgentKind) -> (ManagerSide, CellInput, usize, usize) {
        let layout = Maze::Small.layout(false);
        let cfg = AgentConfig {
            kind,
            candidates: Candidates::All,
            goal_map: true,
            goal_map_windows: true,
            ..AgentConfig::default()
        };
        // The noise is drawn under the generator's lock too: a draw outside
        // it would interleave with another test's seeded initialisation.
        let side = crate::seeding::init_seeded(3, || {
            let side = ManagerSide::new(&cfg, &layout, None);
            tch::no_grad(|| {
                for (_, mut t) in side.vs.variables() {
                    let noise = Tensor::randn_like(&t) * 0.1;
                    t.copy_(&(&t + noise));
                }
            });
            side
        });
        let (cells, meta) = observations(layout.width, layout.height);
        let view = crate::a2c::input::test_view(&cells, &meta, layout.width, layout.height);
        let mut input = CellInput::new(layout.width, layout.height, 0);
        for e in 0..3 {
            input.push_env(&view, e, None);
        }
        (side, input, layout.width, layout.height)
    }

    /// Three random observations of a `w × h` grid (the same every call).
    fn observations(w: usize, h: usize) -> (Vec<u8>, Vec<shm_schemas::EnvMeta>) {
        crate::a2c::input::random_obs(&mut SmallRng::seed_from_u64(11), 3, w, h, 0.3)
    }

    fn state(n: i64, hidden: i64, seed: u64) -> LstmState {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut draw = || {
            let v: Vec<f32> = (0..n * hidden)
                .map(|_| rng.random_range(-0.5..0.5))
                .collect();
            Tensor::from_slice(&v).view([n, hidden])
        };
        LstmState {
            h: draw(),
            c: draw(),
        }
    }

    #[test]
    fn a_wide_then_narrow_decision_equals_the_tch_managers() {
        let (side, input, width, height) = manager(AgentKind::WideNarrow);
        let net = &side.net;
        let hidden = net.trunk().hidden();
        let s = state(3, hidden, 5);
        let mut own = OwnManager::new(net, width, height);
        let d = own.act(&input, &floats(&s.h), &floats(&s.c));
        let step = net.act(&input, &s);
        assert!(rel_diff(&d.h, &floats(&step.state.h)) < 1e-5);
        assert!(rel_diff(&d.c, &floats(&step.state.c)) < 1e-5);
        assert!(rel_diff(&d.values, &step.values) < 1e-5);
        let ManagerHead::WideNarrow(head) = net.head() else {
            unreachable!()
        };
        let bias = tch::no_grad(|| net.goal_bias(&input)).expect("a goal map");
        let wide = tch::no_grad(|| head.wide(&step.h, Some(&bias.wide)).probs());
        assert!(rel_diff(&own.wide_probs(&d), &floats(&wide)) < 1e-5);
        // Narrow goals around three different wide goals, with masked slots.
        let picks = [0usize, 7, side.candidates.len() - 1];
        let window = side.window.as_ref().expect("WN has a window");
        let (cells, meta) = observations(width, height);
        let view = crate::a2c::input::test_view(&cells, &meta, width, height);
        let (mut local, mut valid) = (Vec::new(), Vec::new());
        for (e, &k) in picks.iter().enumerate() {
            local.extend(window.local_input(&view, e, side.candidates[k]));
            valid.extend(window.valid(side.candidates[k]));
        }
        let wide_idx = Tensor::from_slice(&picks.iter().map(|&k| k as i64).collect::<Vec<_>>());
        let narrow = tch::no_grad(|| {
            let map = crate::hrl::wide_narrow::WideNarrowHead::narrow_bias(
                bias.windows.as_ref().expect("windows"),
                &wide_idx,
            );
            head.narrow(
                &step.h,
                &wide_idx,
                &Tensor::from_slice(&local).view([3, -1]),
                &Tensor::from_slice(&valid).view([3, -1]),
                Some(&map),
            )
            .probs()
        });
        let own_narrow = own.narrow_probs(&d, &picks, &local, &valid);
        assert!(rel_diff(&own_narrow, &floats(&narrow)) < 1e-5);
        assert!(
            own_narrow
                .iter()
                .zip(&valid)
                .all(|(&p, &ok)| ok || p == 0.0),
            "a masked slot has probability 0"
        );
        // The map is not all zero: its logits reach both choices.
        assert!(floats(&bias.wide).iter().any(|&b| b.abs() > 1e-3));
    }

    #[test]
    fn a_feudal_decision_equals_the_tch_managers() {
        let (side, input, width, height) = manager(AgentKind::Feudal);
        let net = &side.net;
        let s = state(3, net.trunk().hidden(), 9);
        let mut own = OwnManager::new(net, width, height);
        let d = own.act(&input, &floats(&s.h), &floats(&s.c));
        let step = net.act(&input, &s);
        assert!(rel_diff(&d.h, &floats(&step.state.h)) < 1e-5);
        assert!(rel_diff(&d.values, &step.values) < 1e-5);
        let bias = tch::no_grad(|| net.goal_bias(&input)).expect("a goal map");
        let probs = tch::no_grad(|| {
            net.feudal_policy(&step.h, Some(&bias.wide))
                .expect("feudal")
                .probs()
                .to_kind(Kind::Float)
        });
        assert!(rel_diff(&own.feudal_probs(&d), &floats(&probs)) < 1e-5);
    }

    /// Decision queues of three environments as training records them
    /// (one, four and three decisions; the second environment's core reset
    /// before its third decision; the last decision of each under way, the
    /// others complete, so the loss reaches back through time),
    /// on random observations of the small maze.
    fn queues(side: &ManagerSide, width: usize, height: usize) -> Vec<DecisionQueue> {
        let (cells, meta) = observations(width, height);
        let view = crate::a2c::input::test_view(&cells, &meta, width, height);
        let mut rng = SmallRng::seed_from_u64(17);
        let mut queues = Vec::new();
        for (e, len) in [1usize, 4, 3].into_iter().enumerate() {
            let mut decisions = Vec::new();
            for k in 0..len {
                let mut input = CellInput::new(width, height, 0);
                input.push_env(&view, (e + k) % 3, None);
                let (wide, local, valid) = match &side.window {
                    Some(window) => {
                        let w = rng.random_range(0..side.candidates.len());
                        let gw = side.candidates[w];
                        (w as i64, window.local_input(&view, e, gw), window.valid(gw))
                    }
                    None => (
                        rng.random_range(0..(width * height) as i64),
                        Vec::new(),
                        Vec::new(),
                    ),
                };
                let narrow = valid.iter().rposition(|&v| v).unwrap_or(0) as i64;
                decisions.push(Decision {
                    input,
                    wide,
                    narrow,
                    local,
                    valid,
                    value: rng.random_range(-1.0..1.0),
                    reset_before: e == 1 && k == 2,
                    rewards: (0..3).map(|_| rng.random_range(-0.1..1.0)).collect(),
                    complete: k + 1 < len,
                    episode_ended: false,
                    final_value: None,
                });
            }
            queues.push(DecisionQueue { decisions });
        }
        queues
    }

    /// The loss and every weight's gradient of the Manager's update, its
    /// trunk in the own kernels or in tch.
    fn update_gradients(side: &ManagerSide, own: bool) -> (f64, Vec<(String, Vec<f32>)>) {
        let layout = Maze::Small.layout(false);
        let (w, h) = (layout.width, layout.height);
        let init = state(3, side.net.trunk().hidden(), 4);
        let mut kernels = OwnManager::new(&side.net, w, h);
        let l = side.net.loss_with(
            &queues(side, w, h),
            &init,
            &crate::a2c::A2cConfig::default(),
            0.99,
            own.then_some(&mut kernels as &mut dyn OwnTrunk),
        );
        let mut vars = side.vs.variables().into_iter().collect::<Vec<_>>();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        for (_, t) in &vars {
            let mut g = t.grad();
            if g.defined() {
                let _ = g.zero_();
            }
        }
        l.loss.backward();
        let grads = vars
            .into_iter()
            .map(|(name, t)| (name, floats(&t.grad())))
            .collect();
        (l.loss.double_value(&[]), grads)
    }

    fn the_update_equals_the_tch_managers(kind: AgentKind) {
        let (side, _, _, _) = manager(kind);
        let (loss_tch, tch_grads) = update_gradients(&side, false);
        let (loss_own, own_grads) = update_gradients(&side, true);
        assert!((loss_tch - loss_own).abs() < 1e-5 * loss_tch.abs().max(1.0));
        assert_eq!(tch_grads.len(), own_grads.len());
        let largest = |g: &[f32]| g.iter().fold(0f32, |m, x| m.max(x.abs()));
        let scale = tch_grads
            .iter()
            .map(|(_, g)| largest(g))
            .fold(0f32, f32::max);
        for ((name, g), (_, o)) in tch_grads.iter().zip(&own_grads) {
            if largest(g) < 1e-5 * scale {
                // A gradient that is 0 but for rounding: the goal map's
                // last bias shifts every logit of a softmax alike.
                assert!(largest(o) < 1e-5 * scale, "{name}: 0 on one path only");
                continue;
            }
            let d = rel_diff(o, g);
            assert!(d < 1e-5, "{name}: gradients differ by {d}");
        }
    }

    #[test]
    fn a_wide_then_narrow_update_equals_the_tch_managers() {
        the_update_equals_the_tch_managers(AgentKind::WideNarrow);
    }

    #[test]
    fn a_feudal_update_equals_the_tch_managers() {
        the_update_equals_the_tch_managers(AgentKind::Feudal);
    }
}
