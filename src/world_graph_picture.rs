//! The pictures of a discovery run (section 3): the maze shaded by the
//! latent model's prior mean with the pivotal states `V_p` and the world
//! graph's edges over it, and the world graph alone with the maze's
//! passages shaded under it, each with a title and a legend.

use planner::WorldGraph;
use sim::render::{Canvas, Rgb, draw_grid, object_color};
use sim::{Layout, Object};

use crate::chart::{LegendEntry, Mark, blended, captioned, object_entries};

/// The maze shaded by prior mean, with `V_p` and the graph's edges (along
/// their paths).
fn render_pivotal(layout: &Layout, prior: &[f32], pivotal: &[u32], graph: &WorldGraph) -> Canvas {
    let px = 24usize;
    let mut c = Canvas::new(layout.width * px, layout.height * px, [255, 255, 255]);
    draw_grid(&mut c, &layout.cells, layout.width, 0, 0, px);
    let free: Vec<usize> = (0..layout.cells.len())
        .filter(|&i| layout.cells[i] != Object::Wall as u8)
        .collect();
    let (lo, hi) = free
        .iter()
        .map(|&i| prior[i])
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    for &i in &free {
        let t = if hi > lo {
            (prior[i] - lo) / (hi - lo)
        } else {
            0.0
        };
        let (x, y) = (
            (i % layout.width * px) as i64,
            (i / layout.width * px) as i64,
        );
        c.fill_rect(
            x + 1,
            y + 1,
            px as i64 - 1,
            px as i64 - 1,
            PRIOR_SHADE,
            0.75 * t,
        );
    }
    let centre = |cell: u32| {
        let (x, y) = (cell as usize % layout.width, cell as usize / layout.width);
        ((x as f32 + 0.5) * px as f32, (y as f32 + 0.5) * px as f32)
    };
    // Each edge along its path, through the cells it visits.
    for e in graph.edges() {
        let mut at = graph.nodes()[e.from.index()].0;
        for cell in &e.cells {
            if cell.0 != at {
                c.line(centre(at), centre(cell.0), 2.0, EDGE_GREY, 0.4);
                at = cell.0;
            }
        }
    }
    for &p in pivotal {
        let (x, y) = centre(p);
        c.fill_disc(x, y, px as f32 * 0.3, PIVOTAL_ORANGE, 1.0);
    }
    c
}

/// Colour of the prior-mean shade of [`render_pivotal`] (at 0.75 opacity
/// for the highest mean).
const PRIOR_SHADE: Rgb = [120, 40, 160];
/// Colour of the pivotal states' discs.
const PIVOTAL_ORANGE: Rgb = [255, 140, 0];
/// Colour of the edges drawn along their paths.
const EDGE_GREY: Rgb = [30, 30, 30];
/// Colour of the passages' shade in the graph picture.
const PASSAGE_GREEN: Rgb = [40, 170, 60];

/// [`render_pivotal`] with its title and legend.
pub fn pivotal_picture(
    layout: &Layout,
    prior: &[f32],
    pivotal: &[u32],
    graph: &WorldGraph,
    seed: u64,
) -> Canvas {
    let floor = object_color(Object::Floor);
    let title = format!(
        "Pivotal states V_p ({}) over the prior mean — {} maze, discovery seed {seed}",
        pivotal.len(),
        layout.name
    );
    let mut legend = vec![
        LegendEntry::new(
            Mark::Ramp {
                low: floor,
                high: blended(floor, PRIOR_SHADE, 0.75),
            },
            "shade: the prior's mean at the cell, low → high",
        ),
        LegendEntry::new(
            Mark::Disc {
                fill: PIVOTAL_ORANGE,
                alpha: 1.0,
                radius: 0.3,
                outline: None,
            },
            "pivotal state (V_p)",
        ),
        LegendEntry::new(
            Mark::Line {
                colour: EDGE_GREY,
                alpha: 0.4,
                width: 2.0 / 24.0,
                arrow: false,
            },
            format!(
                "world graph edge along its path ({} edges)",
                graph.edges().len()
            ),
        ),
    ];
    legend.extend(object_entries(&layout.cells, &[]));
    captioned(
        &render_pivotal(layout, prior, pivotal, graph),
        &title,
        &legend,
    )
}

/// The world graph's picture ([`WorldGraph::render`]: edges along
/// their paths, coloured by length, an arrow head at the end node; the
/// nodes), with the maze's passages shaded green under it when `passages`,
/// and its title and legend. `discover` and the planner role write it as
/// `graph.png`.
pub fn graph_picture(graph: &WorldGraph, passages: bool) -> Canvas {
    let layout = graph.layout();
    let title = format!(
        "World graph — {} maze: {} nodes, {} edges",
        layout.name,
        graph.num_nodes(),
        graph.edges().len()
    );
    let (short, long) = WorldGraph::EDGE_COLOURS;
    let mut legend = vec![
        LegendEntry::new(
            Mark::Disc {
                fill: WorldGraph::NODE_COLOUR,
                alpha: 1.0,
                radius: 0.24,
                outline: Some([255, 255, 255]),
            },
            "world graph node",
        ),
        LegendEntry::new(
            Mark::Line {
                colour: short,
                alpha: 0.8,
                width: 0.08,
                arrow: true,
            },
            "edge along its path, arrow head at its end node",
        ),
        LegendEntry::new(
            Mark::Ramp {
                low: short,
                high: long,
            },
            "edge colour: short (dark blue) → long (light blue)",
        ),
    ];
    if passages {
        legend.push(LegendEntry::new(
            Mark::Square {
                fill: PASSAGE_GREEN,
                alpha: 0.35,
                inset: 1.0 / 24.0,
            },
            "passage between rooms (green shade)",
        ));
    }
    legend.extend(object_entries(&layout.cells, &[]));
    let picture = if passages {
        render_graph(graph)
    } else {
        graph.render(24)
    };
    captioned(&picture, &title, &legend)
}

/// The world graph ([`WorldGraph::render`]: edges along their
/// paths) with the maze's passages shaded green under it.
fn render_graph(graph: &WorldGraph) -> Canvas {
    let px = 24usize;
    let layout = graph.layout();
    let mut c = graph.render(px);
    for p in planner::MazeStructure::new(layout).passages() {
        for &cell in p {
            let (x, y) = (
                cell as usize % layout.width * px,
                cell as usize / layout.width * px,
            );
            c.fill_rect(
                x as i64 + 1,
                y as i64 + 1,
                px as i64 - 1,
                px as i64 - 1,
                PASSAGE_GREEN,
                0.35,
            );
        }
    }
    c
}
