//! Wide-then-Narrow Manager instructions (Shang et al. 2019, section 4.2).
//!
//! "Given a pre-defined set of candidate states `V`, the Manager uses a
//! 'wide' policy `π^ω(s_t)` that outputs a 'wide' subgoal `g_w ∈ V`. Next,
//! the Manager zooms its attention to an `N×N` local area `s_w(g_w)` around
//! `g_w`. A 'narrow-goal' policy `π^n` then selects a final 'narrow' goal
//! `g_n ∈ s_w`, using both global `s_t` and local `s_{w,t}` information."
//!
//! - [`Window`]: the `N×N` cells around a wide goal, which of them are valid
//!   narrow goals (inside the grid, not a wall), and the local input
//!   `s_w(g_w)` (one-hot object kind per window cell, plus the agent's
//!   cell);
//! - [`WideNarrowHead`]: `π^ω` a linear layer over the Manager's core
//!   output onto `V`, `π^n` a two-layer net over `[h_t ; s_w(g_w)]` onto the
//!   `N·N` window cells, masked;
//! - [`coverage`] and [`covering_side`]: which free cells can be a narrow
//!   goal at all under a candidate set, and the smallest side for which
//!   every one can.
//!
//! The Manager's log-probability is `log π^ω(g_w) + log π^n(g_n | g_w)`
//! and its entropy bonus `H(π^ω) + H(π^n(·|g_w))` (the paper's tractable
//! stand-in for the joint entropy); see [`WideNarrowHead::terms`].

use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Kind, Tensor};

use crate::a2c::Categorical;
use crate::a2c::input::OBJECT_CHANNELS;
use crate::batch_env::ObsView;
use crate::hrl::{AgentConfig, AgentKind, Candidates};

/// Floats per window cell of the local input: object kinds + agent here.
pub const WINDOW_CHANNELS: usize = OBJECT_CHANNELS + 1;

/// The `N×N` window geometry of a layout.
#[derive(Debug, Clone)]
pub struct Window {
    /// Side `N` (odd).
    pub side: usize,
    width: usize,
    height: usize,
    /// Cells that are walls in the layout.
    wall: Vec<bool>,
}

impl Window {
    /// Windows of side `side` (odd, ≥ 1) on `layout`.
    pub fn new(side: usize, layout: &sim::Layout) -> Window {
        debug_assert!(side % 2 == 1);
        Window {
            side,
            width: layout.width,
            height: layout.height,
            wall: layout
                .cells
                .iter()
                .map(|&c| c == sim::Object::Wall as u8)
                .collect(),
        }
    }

    /// Cells of the window.
    pub fn len(&self) -> usize {
        self.side * self.side
    }

    /// Always false (a window has at least its centre).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The grid cell under window slot `k` around `centre`, or `None`
    /// outside the grid.
    pub fn cell(&self, centre: u32, k: usize) -> Option<u32> {
        let r = (self.side / 2) as i64;
        let (cx, cy) = (
            (centre as usize % self.width) as i64,
            (centre as usize / self.width) as i64,
        );
        let (x, y) = (
            cx - r + (k % self.side) as i64,
            cy - r + (k / self.side) as i64,
        );
        if (0..self.width as i64).contains(&x) && (0..self.height as i64).contains(&y) {
            Some((y * self.width as i64 + x) as u32)
        } else {
            None
        }
    }

    /// The window slot around `centre` that holds `cell`, if any.
    pub fn slot_of(&self, centre: u32, cell: u32) -> Option<usize> {
        let r = (self.side / 2) as i64;
        let w = self.width as i64;
        let (dx, dy) = (
            i64::from(cell) % w - i64::from(centre) % w,
            i64::from(cell) / w - i64::from(centre) / w,
        );
        (dx.abs() <= r && dy.abs() <= r).then(|| ((dy + r) * self.side as i64 + dx + r) as usize)
    }

    /// Which window slots around `centre` are valid narrow goals: inside the
    /// grid and not a wall.
    pub fn valid(&self, centre: u32) -> Vec<bool> {
        (0..self.len())
            .map(|k| self.cell(centre, k).is_some_and(|c| !self.wall[c as usize]))
            .collect()
    }

    /// Which free cells (inside the grid, not a wall: the rule of
    /// [`Window::valid`]) lie in the window around at least one of
    /// `candidates`: the cells `π^n` can ever choose as `g_n` when `π^ω`
    /// draws `g_w` from `candidates`.
    pub fn coverage(&self, candidates: &[u32]) -> Coverage {
        let mut reached = vec![false; self.wall.len()];
        for &centre in candidates {
            for k in 0..self.len() {
                if let Some(c) = self.cell(centre, k) {
                    reached[c as usize] = true;
                }
            }
        }
        let mut covered = 0;
        let mut uncovered = Vec::new();
        for (c, (&wall, &hit)) in self.wall.iter().zip(&reached).enumerate() {
            match (wall, hit) {
                (true, _) => {}
                (false, true) => covered += 1,
                (false, false) => uncovered.push([c % self.width, c / self.width]),
            }
        }
        Coverage {
            side: self.side,
            candidates: candidates.len(),
            covered,
            free: covered + uncovered.len(),
            uncovered,
        }
    }

    /// The local input `s_w(g_w)` of environment `env` of `obs`:
    /// `N·N·WINDOW_CHANNELS` floats (zeros outside the grid).
    pub fn local_input(&self, obs: &ObsView<'_>, env: usize, centre: u32) -> Vec<f32> {
        let cells = obs.env_cells(env);
        let m = &obs.meta[env];
        let agent = m.y as usize * self.width + m.x as usize;
        let mut out = vec![0f32; self.len() * WINDOW_CHANNELS];
        for k in 0..self.len() {
            if let Some(c) = self.cell(centre, k) {
                let code = (cells[c as usize] as usize).min(OBJECT_CHANNELS - 1);
                out[k * WINDOW_CHANNELS + code] = 1.0;
                if c as usize == agent {
                    out[k * WINDOW_CHANNELS + OBJECT_CHANNELS] = 1.0;
                }
            }
        }
        out
    }
}

/// How much of the maze the narrow goals can reach: the free cells (inside
/// the grid, not a wall) that lie in the `N×N` window around at least one
/// wide-goal candidate. Section 4.2 of the paper picks `g_n` inside
/// `s_w(g_w)` with `g_w ∈ V`, so a free cell outside every window (the exit,
/// say) can never be a Manager goal; the paper sizes the windows "based on
/// this ratio [of pivotal states] as well as maze size".
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Coverage {
    /// Window side `N`.
    pub side: usize,
    /// Wide-goal candidates `|V|`.
    pub candidates: usize,
    /// Free cells inside at least one window.
    pub covered: usize,
    /// Free cells.
    pub free: usize,
    /// Free cells outside every window, `[x, y]`, in cell order.
    pub uncovered: Vec<[usize; 2]>,
}

impl Coverage {
    /// Share of the free cells that can be a narrow goal (1 when there are
    /// none).
    pub fn share(&self) -> f64 {
        if self.free == 0 {
            1.0
        } else {
            self.covered as f64 / self.free as f64
        }
    }

    /// Whether every free cell can be a narrow goal.
    pub fn is_complete(&self) -> bool {
        self.uncovered.is_empty()
    }
}

impl std::fmt::Display for Coverage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "window {n}×{n} around {} wide goals covers {} of {} free cells",
            self.candidates,
            self.covered,
            self.free,
            n = self.side
        )?;
        if !self.uncovered.is_empty() {
            const SHOWN: usize = 12;
            write!(f, "; outside every window:")?;
            for [x, y] in self.uncovered.iter().take(SHOWN) {
                write!(f, " ({x}, {y})")?;
            }
            if self.uncovered.len() > SHOWN {
                write!(f, " and {} more", self.uncovered.len() - SHOWN)?;
            }
        }
        Ok(())
    }
}

/// The [`Coverage`] of windows of side `side` (odd) around `candidates` on
/// `layout`.
pub fn coverage(side: usize, candidates: &[u32], layout: &sim::Layout) -> Coverage {
    Window::new(side, layout).coverage(candidates)
}

/// The smallest odd side `≥ min_side` whose windows around `candidates`
/// cover every free cell of `layout`, so that every cell the agent can
/// stand on (the exit first) can be a narrow goal (section 4.2: the paper
/// chooses the window size "based on this ratio [of pivotal states] as well
/// as maze size"). A side of `2·max(width, height) + 1` covers the whole
/// grid from any centre, so the search ends there; with no candidates no
/// side covers, and `min_side` (made odd) is returned.
pub fn covering_side(min_side: usize, candidates: &[u32], layout: &sim::Layout) -> usize {
    let first = min_side.max(1) | 1;
    let widest = (2 * layout.width.max(layout.height) + 1).max(first);
    if candidates.is_empty() {
        return first;
    }
    (first..=widest)
        .step_by(2)
        .find(|&side| coverage(side, candidates, layout).is_complete())
        .unwrap_or(widest)
}

/// The wide-goal candidates `V` of a WN Manager of `cfg` on `layout`
/// (section 4.2): `V_all`, every standable cell and the cells
/// [`AgentConfig::extra_candidates`] adds (the task's objects), or the
/// nodes of the world graph `graph` (`V_p` or `V_rand`); none for FN and
/// the flat A2C.
pub fn wide_goal_candidates(
    cfg: &AgentConfig,
    layout: &sim::Layout,
    graph: Option<&planner::WorldGraph>,
) -> Vec<u32> {
    match (cfg.kind, cfg.candidates) {
        // V_all: every standable cell, and the cells
        // `AgentConfig::extra_candidates` adds (the task's objects).
        (AgentKind::WideNarrow, Candidates::All) => {
            let mut v: Vec<u32> = planner::pivotal::v_all(layout)
                .iter()
                .map(|c| c.0)
                .collect();
            for c in cfg.extra_candidates(layout) {
                if !v.contains(&c) {
                    v.push(c);
                }
            }
            v
        }
        (AgentKind::WideNarrow, _) => graph
            .map(|g| g.nodes().iter().map(|c| c.0).collect())
            .unwrap_or_default(),
        _ => Vec::new(),
    }
}

/// `π^ω` and `π^n`.
#[derive(Debug)]
pub struct WideNarrowHead {
    wide: nn::Linear,
    narrow_hidden: nn::Linear,
    narrow_out: nn::Linear,
    window_len: usize,
    candidates: i64,
}

impl WideNarrowHead {
    /// Heads under `p` for a core of width `hidden`, `candidates` wide
    /// goals and windows of `window_len` cells. `π^n` reads `[h_t ;
    /// s_w(g_w) ; onehot(g_w)]`: the paper's `π^n(g_n | s_t, g_w, s_w)` is
    /// told which wide goal it zooms in on, not only what its window holds.
    pub fn new(p: &nn::Path, hidden: i64, candidates: usize, window_len: usize) -> WideNarrowHead {
        let local = (window_len * WINDOW_CHANNELS) as i64;
        let candidates = candidates as i64;
        WideNarrowHead {
            wide: nn::linear(p / "wide", hidden, candidates, Default::default()),
            narrow_hidden: nn::linear(
                p / "narrow_hidden",
                hidden + local + candidates,
                hidden,
                Default::default(),
            ),
            narrow_out: nn::linear(p / "narrow", hidden, window_len as i64, Default::default()),
            window_len,
            candidates,
        }
    }

    /// `π^ω(·|s_t)` of core outputs `h` `[N, hidden]`, plus the Manager's
    /// goal-map logits of the candidates `bias` (`[N, |V|]`) if it has a
    /// map ([`crate::hrl::feudal::GoalMap`]).
    pub fn wide(&self, h: &Tensor, bias: Option<&Tensor>) -> Categorical {
        let logits = self.wide.forward(h);
        match bias {
            Some(b) => Categorical::new(&(logits + b), None),
            None => Categorical::new(&logits, None),
        }
    }

    /// `π^n(·|s_t, g_w, s_w)` of core outputs `h` `[N, hidden]`, the wide
    /// goals' indices in `V` `wide` `[N]` (int64) and local inputs `[N,
    /// window·WINDOW_CHANNELS]`, masked by `valid` `[N, window]`.
    /// `bias` `[N, window]`: the goal map's logits of the window cells, if
    /// the map reaches `π^n` ([`Self::narrow_bias`]).
    pub fn narrow(
        &self,
        h: &Tensor,
        wide: &Tensor,
        local: &Tensor,
        valid: &Tensor,
        bias: Option<&Tensor>,
    ) -> Categorical {
        let which = wide.one_hot(self.candidates).to_kind(h.kind());
        let x = Tensor::cat(&[h, local, &which], 1)
            .apply(&self.narrow_hidden)
            .relu();
        let logits = self.narrow_out.forward(&x);
        match bias {
            Some(b) => Categorical::new(&(logits + b), Some(valid)),
            None => Categorical::new(&logits, Some(valid)),
        }
    }

    /// The goal map's logits of the windows of the taken wide goals `wide`
    /// `[N]` (int64), from its logits at every candidate's window `windows`
    /// `[N, |V|, window]`: `[N, window]`.
    pub fn narrow_bias(windows: &Tensor, wide: &Tensor) -> Tensor {
        let n = wide.size()[0];
        let len = windows.size()[2];
        windows
            .gather(1, &wide.view([n, 1, 1]).expand([n, 1, len], false), false)
            .squeeze_dim(1)
    }

    /// `π^ω`'s layer, then `π^n`'s hidden and output layers.
    pub(super) fn layers(&self) -> [&nn::Linear; 3] {
        [&self.wide, &self.narrow_hidden, &self.narrow_out]
    }

    /// Window cells.
    pub fn window_len(&self) -> usize {
        self.window_len
    }

    /// `(log π^ω(g_w) + log π^n(g_n|g_w), H(π^ω) + H(π^n(·|g_w)))` `[N]`
    /// each, for taken wide indices `wide` and narrow slots `narrow`
    /// (`[N]` int64); `bias` and `windows`: the goal map's logits of the
    /// candidates and of their windows, if any.
    #[allow(clippy::too_many_arguments)]
    pub fn terms(
        &self,
        h: &Tensor,
        bias: Option<&Tensor>,
        windows: Option<&Tensor>,
        local: &Tensor,
        valid: &Tensor,
        wide: &Tensor,
        narrow: &Tensor,
    ) -> (Tensor, Tensor) {
        let pw = self.wide(h, bias);
        let narrow_bias = windows.map(|w| Self::narrow_bias(w, wide));
        let pn = self.narrow(h, wide, local, valid, narrow_bias.as_ref());
        (
            pw.log_prob(wide) + pn.log_prob(narrow),
            (pw.entropy() + pn.entropy()).to_kind(Kind::Float),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::{Layout, Maze};
    use tch::Device;

    #[test]
    fn narrow_goals_are_inside_the_window_and_on_valid_cells() {
        for maze in Maze::ALL {
            let layout = maze.layout(false);
            for side in [5, 7] {
                let win = Window::new(side, &layout);
                for centre in layout.free_cells() {
                    let valid = win.valid(centre);
                    assert!(valid[win.len() / 2], "the centre of a window is valid");
                    for (k, ok) in valid.iter().enumerate() {
                        let cell = win.cell(centre, k);
                        if *ok {
                            let c = cell.expect("a valid slot is inside the grid") as usize;
                            assert_ne!(layout.cells[c], sim::Object::Wall as u8);
                            let (dx, dy) = (
                                (c % layout.width) as i64 - (centre as usize % layout.width) as i64,
                                (c / layout.width) as i64 - (centre as usize / layout.width) as i64,
                            );
                            let r = (side / 2) as i64;
                            assert!(dx.abs() <= r && dy.abs() <= r);
                        }
                    }
                }
            }
        }
    }

    /// Four room centres of the small maze, the bottom-right one off
    /// centre towards the top-left: the exit corner is 3 cells away.
    fn small_maze_rooms() -> (Layout, Vec<u32>) {
        let layout = Maze::Small.layout(false);
        let v = [(3, 3), (9, 3), (3, 9), (8, 8)]
            .iter()
            .map(|&(x, y)| layout.cell_index(x, y) as u32)
            .collect();
        (layout, v)
    }

    /// Free cells within Chebyshev distance `side / 2` of a candidate,
    /// computed without [`Window`].
    fn reachable_by_distance(layout: &Layout, candidates: &[u32], side: usize) -> Vec<bool> {
        let r = (side / 2) as i64;
        let xy = |c: usize| ((c % layout.width) as i64, (c / layout.width) as i64);
        (0..layout.cells.len())
            .map(|c| {
                let (x, y) = xy(c);
                layout.cells[c] != sim::Object::Wall as u8
                    && candidates.iter().any(|&v| {
                        let (vx, vy) = xy(v as usize);
                        (x - vx).abs() <= r && (y - vy).abs() <= r
                    })
            })
            .collect()
    }

    #[test]
    fn coverage_counts_the_free_cells_inside_some_window() {
        let (layout, v) = small_maze_rooms();
        let free = layout
            .cells
            .iter()
            .filter(|&&c| c != sim::Object::Wall as u8)
            .count();
        for side in [1, 3, 5, 7, 9] {
            let cov = coverage(side, &v, &layout);
            let expected = reachable_by_distance(&layout, &v, side);
            assert_eq!(cov.free, free);
            assert_eq!(cov.covered, expected.iter().filter(|&&b| b).count());
            assert_eq!(cov.covered + cov.uncovered.len(), cov.free);
            for [x, y] in &cov.uncovered {
                assert!(!expected[layout.cell_index(*x, *y)]);
            }
            assert!((cov.share() - cov.covered as f64 / free as f64).abs() < 1e-12);
        }
    }

    #[test]
    fn covering_side_widens_the_window_until_the_exit_is_a_possible_narrow_goal() {
        let (layout, v) = small_maze_rooms();
        let five = coverage(5, &v, &layout);
        assert!(!five.is_complete());
        assert!(
            five.uncovered.contains(&[11, 11]),
            "the exit is 3 cells away"
        );
        assert!(five.to_string().contains("(11, 11)"), "{five}");

        let side = covering_side(5, &v, &layout);
        assert_eq!(side, 7);
        let seven = coverage(side, &v, &layout);
        assert!(seven.is_complete(), "{seven}");
        assert_eq!(seven.covered, seven.free);
        assert_eq!(seven.share(), 1.0);
        assert!(
            reachable_by_distance(&layout, &v, side)
                .iter()
                .zip(&layout.cells)
                .all(|(&hit, &c)| hit || c == sim::Object::Wall as u8),
            "every free cell is within 3 cells of a candidate"
        );
        assert_eq!(
            seven.to_string(),
            format!(
                "window 7×7 around 4 wide goals covers {} of {} free cells",
                seven.free, seven.free
            )
        );
    }

    #[test]
    fn covering_side_keeps_a_side_that_already_covers_and_stays_odd() {
        let (layout, v) = small_maze_rooms();
        assert_eq!(covering_side(4, &v, &layout), 7);
        assert_eq!(covering_side(7, &v, &layout), 7);
        assert_eq!(covering_side(9, &v, &layout), 9);
        let all = planner::pivotal::v_all(&layout)
            .iter()
            .map(|c| c.0)
            .collect::<Vec<_>>();
        assert_eq!(covering_side(1, &all, &layout), 1, "V_all covers itself");
        // One candidate in a corner: the window must reach the far corner.
        let corner = [layout.cell_index(1, 1) as u32];
        assert_eq!(covering_side(5, &corner, &layout), 21);
        assert!(coverage(21, &corner, &layout).is_complete());
        assert_eq!(covering_side(5, &[], &layout), 5);
    }

    #[test]
    fn the_narrow_policy_is_told_which_wide_goal_it_zooms_in_on() {
        // Same core output, same window contents, two wide goals: π^n must
        // be able to tell them apart (the paper's π^n(g_n | s_t, g_w, s_w)).
        let vs = nn::VarStore::new(Device::Cpu);
        let (head, h) = crate::seeding::init_seeded(3, || {
            let head = WideNarrowHead::new(&vs.root(), 8, 5, 9);
            (head, Tensor::randn([1, 8], (Kind::Float, Device::Cpu)))
        });
        let h = h.repeat([2, 1]);
        let local = Tensor::zeros(
            [2, (9 * WINDOW_CHANNELS) as i64],
            (Kind::Float, Device::Cpu),
        );
        let valid = Tensor::ones([2, 9], (Kind::Bool, Device::Cpu));
        let p = head
            .narrow(&h, &Tensor::from_slice(&[0i64, 4]), &local, &valid, None)
            .probs();
        let diff = (p.get(0) - p.get(1)).abs().max().double_value(&[]);
        assert!(diff > 1e-4, "π^n ignores g_w ({diff})");
    }

    #[test]
    fn slot_of_inverts_cell() {
        let layout = sim::Maze::Small.layout(false);
        let win = Window::new(5, &layout);
        let centre = layout.cell_index(6, 6) as u32;
        for k in 0..win.len() {
            let c = win.cell(centre, k).expect("inside");
            assert_eq!(win.slot_of(centre, c), Some(k));
        }
        assert_eq!(win.slot_of(centre, layout.cell_index(9, 6) as u32), None);
    }

    #[test]
    fn masked_narrow_slots_are_never_drawn() {
        let layout =
            Layout::parse("corner", "#####\n#>..#\n#...#\n#..E#\n#####\n").expect("layout");
        let win = Window::new(5, &layout);
        let centre = layout.cell_index(1, 1) as u32;
        let valid = win.valid(centre);
        let vs = nn::VarStore::new(Device::Cpu);
        let (head, h, local) = crate::seeding::init_seeded(4, || {
            let head = WideNarrowHead::new(&vs.root(), 8, 4, win.len());
            let h = Tensor::randn([64, 8], (Kind::Float, Device::Cpu)) * 10.0;
            let local = Tensor::randn(
                [64, (win.len() * WINDOW_CHANNELS) as i64],
                (Kind::Float, Device::Cpu),
            );
            (head, h, local)
        });
        let mask = Tensor::from_slice(&valid)
            .view([1, -1])
            .expand([64, -1], false);
        let wide = Tensor::from_slice(&[2i64]).expand([64], false);
        let pn = head.narrow(&h, &wide, &local, &mask, None);
        let mut rng = <rand::rngs::SmallRng as rand::SeedableRng>::seed_from_u64(1);
        for _ in 0..20 {
            for k in crate::seeding::sample_index(&mut rng, &pn.probs()) {
                assert!(valid[k], "slot {k} is masked");
            }
        }
    }

    #[test]
    fn wide_narrow_log_probability_and_entropy_equal_the_hand_computed_values() {
        let vs = nn::VarStore::new(Device::Cpu);
        let head = crate::seeding::init_seeded(5, || WideNarrowHead::new(&vs.root(), 2, 3, 4));
        tch::no_grad(|| {
            // Wide logits [0, ln 2, ln 3] → π^ω = [1/6, 2/6, 3/6]; narrow
            // logits all 0 over 4 slots, slot 3 masked → uniform over 3.
            let mut w = head.wide.ws.shallow_clone();
            w.copy_(&Tensor::from_slice(&[0f32, 0., 2f32.ln(), 0., 3f32.ln(), 0.]).view([3, 2]));
            let mut b = head.wide.bs.as_ref().expect("bias").shallow_clone();
            let _ = b.zero_();
            let _ = head.narrow_out.ws.shallow_clone().zero_();
            let _ = head
                .narrow_out
                .bs
                .as_ref()
                .expect("bias")
                .shallow_clone()
                .zero_();
        });
        let h = Tensor::from_slice(&[1f32, 0.]).view([1, 2]);
        let local = Tensor::zeros(
            [1, (4 * WINDOW_CHANNELS) as i64],
            (Kind::Float, Device::Cpu),
        );
        let valid = Tensor::from_slice(&[true, true, true, false]).view([1, 4]);
        let (logp, ent) = head.terms(
            &h,
            None,
            None,
            &local,
            &valid,
            &Tensor::from_slice(&[2i64]),
            &Tensor::from_slice(&[1i64]),
        );
        let expected_logp = (0.5f64).ln() + (1.0f64 / 3.0).ln();
        let pw = [1.0 / 6.0, 2.0 / 6.0, 3.0 / 6.0f64];
        let expected_ent = -pw.iter().map(|p| p * p.ln()).sum::<f64>() + 3f64.ln();
        assert!((logp.double_value(&[0]) - expected_logp).abs() < 1e-5);
        assert!((ent.double_value(&[0]) - expected_ent).abs() < 1e-5);
    }
}
