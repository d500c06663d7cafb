//! The picture of one test episode (the paper's Figure 1, bottom): the
//! maze as the episode started, the agent's path (red where the Worker
//! acted, light blue where the world graph was traversed, section 4.3),
//! the wide and narrow goals the Manager gave (section 4.2), the graph's
//! nodes, what the episode collected and the exit, with a title and a
//! legend of every mark.

use learner::hrl::{AgentConfig, AgentKind, EpisodeTrace};
use learner::run::protocol::EpisodeOutcome;
use sim::render::{Canvas, Rgb, draw_grid, object_color};
use sim::{Layout, Object, Task};

use crate::chart::{LEGEND_CELL, LegendEntry, Mark, captioned};

/// Colours of the episode picture's marks.
const WORKER_RED: Rgb = [220, 30, 40];
const TRAVERSAL_BLUE: Rgb = [100, 180, 255];
const NARROW_BLUE: Rgb = [120, 190, 255];
const WIDE_BLUE: Rgb = [20, 60, 220];
const NODE_BLUE: Rgb = [90, 90, 200];
/// The frame around the exit cells.
pub const EXIT_FRAME: Rgb = [255, 190, 0];
const TICK_GREEN: Rgb = [20, 140, 50];
/// Pixels per cell of the episode picture.
pub const EPISODE_PX: usize = 28;

/// The narrow goal's mark on the cell at `(x, y)`.
fn narrow_goal_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, d) = (px as i64, (px * 3 / 28) as i64);
    c.fill_rect(x + d, y + d, p - 2 * d, p - 2 * d, NARROW_BLUE, 0.55);
}

/// The wide goal's mark on the cell at `(x, y)`.
fn wide_goal_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, d) = (px as i64, (px * 5 / 28) as i64);
    c.fill_rect(x + d, y + d, p - 2 * d, p - 2 * d, WIDE_BLUE, 0.8);
}

/// A ball on the cell at `(x, y)`: as the grid draws one while it lies
/// there; a ring with a tick once collected.
fn ball_mark(c: &mut Canvas, x: i64, y: i64, px: usize, collected: bool) {
    let s = px as f32;
    let (cx, cy) = (x as f32 + s / 2.0, y as f32 + s / 2.0);
    let ball = object_color(Object::Ball);
    if !collected {
        c.fill_disc(cx, cy, s * 0.32, ball, 1.0);
        return;
    }
    let (r_out, r_in) = (s * 0.32, s * 0.21);
    for yy in y..y + px as i64 {
        for xx in x..x + px as i64 {
            let (dx, dy) = (xx as f32 + 0.5 - cx, yy as f32 + 0.5 - cy);
            let d2 = dx * dx + dy * dy;
            if d2 <= r_out * r_out && d2 > r_in * r_in {
                c.blend(xx, yy, ball, 1.0);
            }
        }
    }
    tick_mark(c, x, y, px);
}

/// A green tick over the cell at `(x, y)`: what the episode took.
fn tick_mark(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let s = px as f32;
    let at = |u: f32, v: f32| (x as f32 + u * s, y as f32 + v * s);
    c.line(at(0.3, 0.52), at(0.45, 0.68), s * 0.1, TICK_GREEN, 1.0);
    c.line(at(0.45, 0.68), at(0.72, 0.36), s * 0.1, TICK_GREEN, 1.0);
}

/// The frame that marks an exit cell at `(x, y)`.
fn exit_frame(c: &mut Canvas, x: i64, y: i64, px: usize) {
    let (p, t) = (px as i64, (px / 9).max(2) as i64);
    c.fill_rect(x, y, p, t, EXIT_FRAME, 1.0);
    c.fill_rect(x, y + p - t, p, t, EXIT_FRAME, 1.0);
    c.fill_rect(x, y, t, p, EXIT_FRAME, 1.0);
    c.fill_rect(x + p - t, y, t, p, EXIT_FRAME, 1.0);
}

/// A legend sample: one floor cell with `draw` applied, as the picture
/// applies it.
fn legend_sample(base: Object, draw: impl Fn(&mut Canvas, i64, i64, usize)) -> Mark {
    let mut c = crate::chart::cell_sample(base as u8);
    draw(&mut c, 0, 0, LEGEND_CELL);
    Mark::Sample(c)
}

/// The maze with one test episode, `px` pixels a cell, without caption:
/// the grid the episode started on, the agent's path (red where the Worker
/// acted, light blue where the world graph was traversed), the wide goals
/// (dark blue squares) and narrow goals (light blue squares), the graph's
/// nodes (the paper's Figure 1, bottom), the balls (a ring with a tick
/// where collected), the key taken (ticked) and the exits (framed).
pub fn episode_maze(
    layout: &Layout,
    t: &EpisodeTrace,
    graph: Option<&planner::WorldGraph>,
    px: usize,
) -> Canvas {
    let start: &[u8] = if t.start_cells.len() == layout.cells.len() {
        &t.start_cells
    } else {
        &layout.cells
    };
    let end: Option<&[u8]> = (t.end_cells.len() == start.len()).then_some(&t.end_cells);
    // The grid as it started, less its balls (drawn on top), its doors as
    // they ended.
    let ground: Vec<u8> = start
        .iter()
        .enumerate()
        .map(|(i, &c)| {
            let door = [Object::DoorOpen, Object::DoorClosed, Object::DoorLocked]
                .iter()
                .any(|&d| c == d as u8);
            match end {
                _ if c == Object::Ball as u8 => Object::Floor as u8,
                Some(e) if door => e[i],
                _ => c,
            }
        })
        .collect();
    let mut c = Canvas::new(layout.width * px, layout.height * px, [255, 255, 255]);
    draw_grid(&mut c, &ground, layout.width, 0, 0, px);
    let centre = |cell: u32| {
        let (x, y) = (cell as usize % layout.width, cell as usize / layout.width);
        ((x as f32 + 0.5) * px as f32, (y as f32 + 0.5) * px as f32)
    };
    let corner = |cell: usize| {
        (
            (cell % layout.width * px) as i64,
            (cell / layout.width * px) as i64,
        )
    };
    if let Some(g) = graph {
        for n in g.nodes() {
            let (x, y) = centre(n.0);
            c.fill_disc(x, y, px as f32 * 0.18, NODE_BLUE, 0.5);
        }
    }
    for &(_, gw, gn) in &t.goals {
        let (x, y) = corner(gn as usize);
        narrow_goal_mark(&mut c, x, y, px);
        let (x, y) = corner(gw as usize);
        wide_goal_mark(&mut c, x, y, px);
    }
    for (k, w) in t.cells.windows(2).enumerate() {
        let traversed = t.traversed.get(k).copied().unwrap_or(false);
        let colour = if traversed {
            TRAVERSAL_BLUE
        } else {
            WORKER_RED
        };
        c.line(
            centre(w[0]),
            centre(w[1]),
            if traversed { 5.0 } else { 3.0 },
            colour,
            0.8,
        );
    }
    for (i, &code) in start.iter().enumerate() {
        let (x, y) = corner(i);
        let taken = end.is_some_and(|e| e[i] != code);
        if code == Object::Ball as u8 {
            ball_mark(&mut c, x, y, px, taken);
        } else if code == Object::Key as u8 && taken {
            tick_mark(&mut c, x, y, px);
        } else if code == Object::Exit as u8 {
            exit_frame(&mut c, x, y, px);
        }
    }
    if let Some(&first) = t.cells.first() {
        let (x, y) = centre(first);
        c.fill_disc(x, y, px as f32 * 0.3, WORKER_RED, 1.0);
    }
    c
}

/// The picture of one test episode ([`episode_maze`]) with its title (the
/// agent, maze, task, test seed and what the episode did) and a legend of
/// every mark drawn.
pub fn episode_picture(
    layout: &Layout,
    t: &EpisodeTrace,
    graph: Option<&planner::WorldGraph>,
    agent: &AgentConfig,
    task: Task,
    test_seed: u64,
) -> Canvas {
    let maze = episode_maze(layout, t, graph, EPISODE_PX);
    let outcome = EpisodeOutcome::of(t);
    let mut title = format!(
        "{} — {} maze, {}, test seed {test_seed}: return {:.2}",
        agent.label(),
        layout.name,
        task.label(),
        t.episode_return
    );
    if let Some(o) = outcome {
        if o.balls > 0 {
            title.push_str(&format!(", {} of {} balls", o.collected, o.balls));
        }
        let at = |step: Option<u32>| step.map(|k| format!(" at step {k}")).unwrap_or_default();
        if o.key_taken {
            title.push_str(&format!(", key taken{}", at(t.key_step)));
        }
        if o.door_opened {
            title.push_str(&format!(", door opened{}", at(t.door_step)));
        }
        title.push_str(if o.exited {
            ", exited"
        } else {
            ", did not exit"
        });
    }
    let start: &[u8] = if t.start_cells.len() == layout.cells.len() {
        &t.start_cells
    } else {
        &layout.cells
    };
    let has = |o: Object| start.contains(&(o as u8));
    let mut legend = vec![
        LegendEntry::new(
            Mark::Disc {
                fill: WORKER_RED,
                alpha: 1.0,
                radius: 0.3,
                outline: None,
            },
            "where the episode started",
        ),
        LegendEntry::new(
            Mark::Line {
                colour: WORKER_RED,
                alpha: 0.8,
                width: 3.0 / EPISODE_PX as f32,
                arrow: false,
            },
            if agent.kind == AgentKind::A2c {
                "a step of the agent"
            } else {
                "a step the Worker took"
            },
        ),
    ];
    if agent.traversal || t.traversed.iter().any(|&b| b) {
        legend.push(LegendEntry::new(
            Mark::Line {
                colour: TRAVERSAL_BLUE,
                alpha: 0.8,
                width: 5.0 / EPISODE_PX as f32,
                arrow: false,
            },
            "a step of world graph traversal",
        ));
    }
    if let Some(g) = graph {
        legend.push(LegendEntry::new(
            Mark::Disc {
                fill: NODE_BLUE,
                alpha: 0.5,
                radius: 0.18,
                outline: None,
            },
            format!(
                "world graph node ({}, {} nodes)",
                agent.candidates.label(),
                g.num_nodes()
            ),
        ));
    }
    match agent.kind {
        AgentKind::WideNarrow => {
            legend.push(LegendEntry::new(
                legend_sample(Object::Floor, wide_goal_mark),
                "wide goal g_w the Manager chose",
            ));
            legend.push(LegendEntry::new(
                legend_sample(Object::Floor, narrow_goal_mark),
                "narrow goal g_n in its window",
            ));
        }
        AgentKind::Feudal => legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| {
                narrow_goal_mark(c, x, y, px);
                wide_goal_mark(c, x, y, px);
            }),
            "subgoal the Manager chose",
        )),
        AgentKind::A2c => {}
    }
    if has(Object::Ball) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| ball_mark(c, x, y, px, false)),
            "ball, not collected",
        ));
        legend.push(LegendEntry::new(
            legend_sample(Object::Floor, |c, x, y, px| ball_mark(c, x, y, px, true)),
            "ball collected in this episode (ring, ticked)",
        ));
    }
    if outcome.is_some_and(|o| o.key_taken) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Key, tick_mark),
            "key, taken in this episode (ticked)",
        ));
    }
    if has(Object::Exit) {
        legend.push(LegendEntry::new(
            legend_sample(Object::Exit, exit_frame),
            match outcome.map(|o| o.exited) {
                Some(true) => "exit (framed): the episode ended here",
                Some(false) => "exit (framed): not reached",
                None => "exit (framed)",
            },
        ));
    }
    let mut skip = vec![Object::Ball, Object::Exit];
    if let Some(e) = Some(&t.end_cells).filter(|e| e.len() == start.len()) {
        // Doors are drawn as they ended.
        legend.extend(crate::chart::object_entries(
            e,
            &[
                Object::Floor,
                Object::Wall,
                Object::Ball,
                Object::Exit,
                Object::Key,
                Object::Lava,
            ],
        ));
        skip.extend([Object::DoorOpen, Object::DoorClosed, Object::DoorLocked]);
    }
    legend.extend(crate::chart::object_entries(start, &skip));
    captioned(&maze, &title, &legend)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::Maze;

    fn pixel(c: &Canvas, x: usize, y: usize) -> Rgb {
        let i = (y * c.width + x) * 3;
        [c.rgb[i], c.rgb[i + 1], c.rgb[i + 2]]
    }

    /// The row at which `picture` sits at column `x` of `c`, if anywhere.
    fn find_picture(c: &Canvas, picture: &Canvas, x: usize) -> Option<usize> {
        let row = |cv: &Canvas, y: usize, x0: usize| {
            cv.rgb[(y * cv.width + x0) * 3..(y * cv.width + x0 + picture.width) * 3].to_vec()
        };
        (0..=c.height.saturating_sub(picture.height))
            .find(|&y| (0..picture.height).all(|r| row(c, y + r, x) == row(picture, r, 0)))
    }

    /// A hand-made episode on the small maze: balls on two floor cells
    /// `a` and `b` far from the start, the agent walking from the start to
    /// `a`; with `collected`, the end grid lacks `a`'s ball.
    fn ball_episode(collected: bool) -> (Layout, EpisodeTrace, usize, usize, usize) {
        let layout = Maze::Small.layout(false);
        let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize);
        let free = layout.free_cells();
        let floor: Vec<usize> = free
            .iter()
            .map(|&c| c as usize)
            .filter(|&c| layout.cells[c] == Object::Floor as u8 && c != start)
            .collect();
        let (a, b) = (floor[floor.len() / 2], floor[floor.len() - 1]);
        let exit = (0..layout.cells.len())
            .find(|&i| layout.cells[i] == Object::Exit as u8)
            .expect("the small maze has an exit");
        let mut start_cells = layout.cells.clone();
        start_cells[a] = Object::Ball as u8;
        start_cells[b] = Object::Ball as u8;
        let mut end_cells = start_cells.clone();
        if collected {
            end_cells[a] = Object::Floor as u8;
        }
        let t = EpisodeTrace {
            cells: vec![start as u32, a as u32],
            traversed: vec![false],
            goals: Vec::new(),
            episode_return: 0.99,
            start_cells,
            end_cells,
            ..EpisodeTrace::default()
        };
        (layout, t, a, b, exit)
    }

    /// Issue 21: the episode picture draws the balls the episode started
    /// with, a collected one as a ring (its centre no longer the ball's
    /// colour) and an uncollected one as the grid draws a ball, and frames
    /// the exit.
    #[test]
    fn the_episode_picture_tells_collected_balls_from_the_others_and_frames_the_exit() {
        let px = EPISODE_PX;
        let ball = object_color(Object::Ball);
        let centre = |layout: &Layout, cell: usize| {
            (
                cell % layout.width * px + px / 2,
                cell / layout.width * px + px / 2,
            )
        };
        let (layout, t, a, b, exit) = ball_episode(true);
        let c = episode_maze(&layout, &t, None, px);
        let (ax, ay) = centre(&layout, a);
        let (bx, by) = centre(&layout, b);
        assert_eq!(
            pixel(&c, bx, by),
            ball,
            "the uncollected ball is drawn whole"
        );
        assert_ne!(pixel(&c, ax, ay), ball, "the collected ball is hollow");
        let ring = (px as f32 * 0.27) as usize;
        assert_eq!(pixel(&c, ax, ay - ring), ball, "the collected ball's ring");
        // The same episode without the collection: a's ball is whole.
        let (_, t_kept, ..) = ball_episode(false);
        let kept = episode_maze(&layout, &t_kept, None, px);
        assert_eq!(
            pixel(&kept, ax, ay),
            ball,
            "an uncollected ball under the path"
        );
        // The exit is framed; a floor cell is not.
        let (ex, ey) = (exit % layout.width * px, exit / layout.width * px);
        assert_eq!(pixel(&c, ex + 1, ey + px / 2), EXIT_FRAME);
        assert_ne!(pixel(&c, bx - px / 2 + 1, by), EXIT_FRAME);
        assert_eq!(
            EpisodeOutcome::of(&t),
            Some(EpisodeOutcome {
                balls: 2,
                collected: 1,
                exited: false,
                ..EpisodeOutcome::default()
            })
        );
        let mut exited = t.clone();
        exited.cells.push(exit as u32);
        assert!(EpisodeOutcome::of(&exited).is_some_and(|o| o.exited));
    }

    /// Issue 21: the saved picture is the maze with a title above it and a
    /// legend below that shows the collected-ball mark.
    #[test]
    fn the_episode_picture_has_a_title_and_a_legend_of_its_marks() {
        let (layout, t, ..) = ball_episode(true);
        let agent = AgentConfig {
            kind: AgentKind::WideNarrow,
            traversal: true,
            init_from_gcp: true,
            ..AgentConfig::default()
        };
        let maze = episode_maze(&layout, &t, None, EPISODE_PX);
        let c = episode_picture(&layout, &t, None, &agent, Task::MultiGoal, 7);
        let x = (c.width - maze.width) / 2;
        let y = find_picture(&c, &maze, x).expect("the maze, whole");
        assert!(
            y > 20 && c.height > y + maze.height + 100,
            "{y} {}",
            c.height
        );
        let dark_title = (0..y * c.width)
            .filter(|&i| c.rgb[3 * i..3 * i + 3].iter().all(|&v| v < 100))
            .count();
        assert!(dark_title > 50, "the title is written: {dark_title} px");
        let legend = &c.rgb[(y + maze.height) * c.width * 3..];
        let ticks = legend.chunks(3).filter(|p| *p == TICK_GREEN).count();
        assert!(ticks > 5, "the legend shows the collected ball's tick");
        let frame = legend.chunks(3).filter(|p| *p == EXIT_FRAME).count();
        assert!(frame > 20, "the legend shows the exit's frame");
        assert_eq!(
            agent.label(),
            "WN V_p + traversal + π_g init",
            "the configuration's name in the title"
        );
    }
}
