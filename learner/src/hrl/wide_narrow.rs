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
//!   `N·N` window cells, masked.
//!
//! The Manager's log-probability is `log π^ω(g_w) + log π^n(g_n | g_w)`
//! and its entropy bonus `H(π^ω) + H(π^n(·|g_w))` (the paper's tractable
//! stand-in for the joint entropy); see [`WideNarrowHead::terms`].

use tch::nn::{self, Module};
use tch::{Kind, Tensor};

use crate::a2c::Categorical;
use crate::a2c::input::OBJECT_CHANNELS;
use crate::batch_env::ObsView;

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

    /// Which window slots around `centre` are valid narrow goals: inside the
    /// grid and not a wall.
    pub fn valid(&self, centre: u32) -> Vec<bool> {
        (0..self.len())
            .map(|k| self.cell(centre, k).is_some_and(|c| !self.wall[c as usize]))
            .collect()
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

/// `π^ω` and `π^n`.
#[derive(Debug)]
pub struct WideNarrowHead {
    wide: nn::Linear,
    narrow_hidden: nn::Linear,
    narrow_out: nn::Linear,
    window_len: usize,
}

impl WideNarrowHead {
    /// Heads under `p` for a core of width `hidden`, `candidates` wide
    /// goals and windows of `window_len` cells.
    pub fn new(p: &nn::Path, hidden: i64, candidates: usize, window_len: usize) -> WideNarrowHead {
        let local = (window_len * WINDOW_CHANNELS) as i64;
        WideNarrowHead {
            wide: nn::linear(p / "wide", hidden, candidates as i64, Default::default()),
            narrow_hidden: nn::linear(
                p / "narrow_hidden",
                hidden + local,
                hidden,
                Default::default(),
            ),
            narrow_out: nn::linear(p / "narrow", hidden, window_len as i64, Default::default()),
            window_len,
        }
    }

    /// `π^ω(·|s_t)` of core outputs `h` `[N, hidden]`.
    pub fn wide(&self, h: &Tensor) -> Categorical {
        Categorical::new(&self.wide.forward(h), None)
    }

    /// `π^n(·|s_t, g_w, s_w)` of core outputs `h` `[N, hidden]` and local
    /// inputs `[N, window·WINDOW_CHANNELS]`, masked by `valid` `[N, window]`.
    pub fn narrow(&self, h: &Tensor, local: &Tensor, valid: &Tensor) -> Categorical {
        let x = Tensor::cat(&[h, local], 1)
            .apply(&self.narrow_hidden)
            .relu();
        Categorical::new(&self.narrow_out.forward(&x), Some(valid))
    }

    /// Window cells.
    pub fn window_len(&self) -> usize {
        self.window_len
    }

    /// `(log π^ω(g_w) + log π^n(g_n|g_w), H(π^ω) + H(π^n(·|g_w)))` `[N]`
    /// each, for taken wide indices `wide` and narrow slots `narrow`
    /// (`[N]` int64).
    pub fn terms(
        &self,
        h: &Tensor,
        local: &Tensor,
        valid: &Tensor,
        wide: &Tensor,
        narrow: &Tensor,
    ) -> (Tensor, Tensor) {
        let pw = self.wide(h);
        let pn = self.narrow(h, local, valid);
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

    #[test]
    fn masked_narrow_slots_are_never_drawn() {
        let layout =
            Layout::parse("corner", "#####\n#>..#\n#...#\n#..E#\n#####\n").expect("layout");
        let win = Window::new(5, &layout);
        let centre = layout.cell_index(1, 1) as u32;
        let valid = win.valid(centre);
        let vs = nn::VarStore::new(Device::Cpu);
        let head = WideNarrowHead::new(&vs.root(), 8, 4, win.len());
        let h = Tensor::randn([64, 8], (Kind::Float, Device::Cpu)) * 10.0;
        let local = Tensor::randn(
            [64, (win.len() * WINDOW_CHANNELS) as i64],
            (Kind::Float, Device::Cpu),
        );
        let mask = Tensor::from_slice(&valid)
            .view([1, -1])
            .expand([64, -1], false);
        let pn = head.narrow(&h, &local, &mask);
        let mut rng = rand::SeedableRng::seed_from_u64(1);
        for _ in 0..20 {
            for k in crate::seeding::sample_index(&mut rng, &pn.probs()) {
                assert!(valid[k], "slot {k} is masked");
            }
        }
    }

    #[test]
    fn wide_narrow_log_probability_and_entropy_equal_the_hand_computed_values() {
        let vs = nn::VarStore::new(Device::Cpu);
        let head = WideNarrowHead::new(&vs.root(), 2, 3, 4);
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
