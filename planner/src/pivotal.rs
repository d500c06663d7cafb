//! Candidate node sets of the world graph: the pivotal states `V_p` and the
//! comparison sets `V_all` and `V_rand` of Shang et al. 2019
//! (arXiv:1907.00664), sections 3.2 and 4.
//!
//! - [`v_all`]: every cell the agent can stand on at the start of an
//!   episode (floor, open doors and the exit, reachable from the start).
//! - [`v_rand`]: `k` of those, drawn uniformly with a seed.
//! - [`parse_node_list`] / [`read_node_file`]: a hand-made list.
//! - [`top_ratio`]: the paper's rule for `V_p`, the top fraction of the
//!   visited states ranked by the prior mean of the latent model.
//!
//! Every set goes through [`check_nodes`], which refuses cells outside the
//! grid, cells the agent cannot stand on and duplicates, with messages that
//! name the cell.

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand::seq::SliceRandom;
use sim::{Layout, Object};

use crate::config::{CandidateSet, MAX_NODES, PlannerConfig};
use crate::error::PlannerError;
use crate::ids::CellIdx;

/// True when the agent can stand on `object` at the start of an episode and
/// a node there makes sense: floor, an open door, or the exit (the exit ends
/// the episode, so it is a node with edges in only).
#[inline]
pub fn is_node_object(object: Object) -> bool {
    matches!(object, Object::Floor | Object::DoorOpen | Object::Exit)
}

/// `V_all`: every cell reachable from the start on which the agent can
/// stand, in cell order.
pub fn v_all(layout: &Layout) -> Vec<CellIdx> {
    layout
        .free_cells()
        .into_iter()
        .filter(|&i| Object::from_code(layout.cells[i as usize]).is_some_and(is_node_object))
        .map(CellIdx)
        .collect()
}

/// `V_rand`: `k` distinct cells of [`v_all`] drawn uniformly with `seed`,
/// returned in cell order.
pub fn v_rand(layout: &Layout, k: usize, seed: u64) -> Result<Vec<CellIdx>, PlannerError> {
    let mut all = v_all(layout);
    if k > all.len() {
        return Err(PlannerError::NotEnoughCells {
            requested: k,
            available: all.len(),
        });
    }
    let mut rng = SmallRng::seed_from_u64(sim::env_seed(seed, 0x0056_5241_4e44)); // "VRAND"
    let (chosen, _) = all.partial_shuffle(&mut rng, k);
    let mut chosen = chosen.to_vec();
    chosen.sort_unstable();
    Ok(chosen)
}

/// `V_p`'s rule (section 3.1): the top `ratio` of `(cell, pivotality)`
/// pairs, at least one, most pivotal first, ties broken by the lower cell
/// index. The learner ranks the visited cells by the mean of the latent
/// model's Beta prior (`learner::vae`); [`nodes_from_cells`] turns the
/// result into graph nodes.
pub fn top_ratio(mut ranked: Vec<(u32, f32)>, ratio: f64) -> Vec<u32> {
    if ranked.is_empty() {
        return Vec::new();
    }
    ranked.sort_by(|x, y| y.1.total_cmp(&x.1).then(x.0.cmp(&y.0)));
    let count =
        ((ratio.clamp(0.0, 1.0) * ranked.len() as f64).ceil() as usize).clamp(1, ranked.len());
    ranked
        .into_iter()
        .take(count)
        .map(|(cell, _)| cell)
        .collect()
}

/// Node cells from raw cell indices (e.g. the learner's pivotal states,
/// `y · width + x`): cells the agent cannot stand on at the start of an
/// episode (keys, closed doors, walls, out of the grid) are dropped, as are
/// repeats; the order is kept. The result passes [`check_nodes`] (up to
/// [`MAX_NODES`] cells).
pub fn nodes_from_cells(layout: &Layout, cells: &[u32]) -> Vec<CellIdx> {
    let mut standable = standable_mask(layout);
    let mut out = Vec::with_capacity(cells.len().min(MAX_NODES));
    for &c in cells {
        if out.len() < MAX_NODES && standable.get(c as usize).copied().unwrap_or(false) {
            standable[c as usize] = false;
            out.push(CellIdx(c));
        }
    }
    out
}

fn standable_mask(layout: &Layout) -> Vec<bool> {
    let mut mask = vec![false; layout.cells.len()];
    for c in v_all(layout) {
        mask[c.index()] = true;
    }
    mask
}

/// Checks a node list against the layout: every cell inside the grid, one
/// the agent can stand on ([`v_all`]), no duplicates, at most
/// [`MAX_NODES`]. Returns the cells as given (order kept: node `i` is
/// `cells[i]`).
pub fn check_nodes(layout: &Layout, cells: &[CellIdx]) -> Result<Vec<CellIdx>, PlannerError> {
    if cells.len() > MAX_NODES {
        return Err(PlannerError::TooManyNodes {
            count: cells.len(),
            max: MAX_NODES,
        });
    }
    let standable = standable_mask(layout);
    let mut seen = vec![false; layout.cells.len()];
    for &c in cells {
        if c.index() >= layout.cells.len() {
            return Err(PlannerError::OutOfGrid {
                x: (c.index() % layout.width) as i64,
                y: (c.index() / layout.width) as i64,
                width: layout.width,
                height: layout.height,
            });
        }
        let (x, y) = c.xy(layout.width);
        if !standable[c.index()] {
            let object = match Object::from_code(layout.cells[c.index()]) {
                Some(o) if !is_node_object(o) => format!("{} '{}'", o.name(), o.to_char()),
                _ => "a cell unreachable from the agent's start".to_string(),
            };
            return Err(PlannerError::NotStandable { x, y, object });
        }
        if std::mem::replace(&mut seen[c.index()], true) {
            return Err(PlannerError::DuplicateNode { x, y });
        }
    }
    Ok(cells.to_vec())
}

/// Parses a node list. Two formats, told apart by the first non-blank
/// character:
///
/// - **JSON** (`[` or `{`): an array of `[x, y]` pairs or of `{"x": .., "y": ..}`
///   objects, optionally wrapped as `{"nodes": [...]}`.
/// - **Text**: one `x,y` (or `x y`) pair per line; blank lines and lines
///   starting with `#` are ignored.
///
/// `x` is the column from the left, `y` the row from the top (as in the
/// layout files). `source` names the input in errors, which give the
/// 1-based line. The cells are then checked with [`check_nodes`].
pub fn parse_node_list(
    layout: &Layout,
    source: &str,
    text: &str,
) -> Result<Vec<CellIdx>, PlannerError> {
    let err = |line: usize, message: String| PlannerError::NodeList {
        source_name: source.to_string(),
        line,
        message,
    };
    let trimmed = text.trim_start();
    let pairs: Vec<ListedCell> = if trimmed.starts_with('[') || trimmed.starts_with('{') {
        parse_json_pairs(text).map_err(|(line, m)| err(line, m))?
    } else {
        let mut pairs = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = line
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|f| !f.is_empty())
                .collect();
            let [xs, ys] = fields[..] else {
                return Err(err(
                    n + 1,
                    format!("expected two integers \"x,y\", found {line:?}"),
                ));
            };
            let num = |f: &str, what| {
                f.parse::<i64>()
                    .map_err(|_| err(n + 1, format!("{what} {f:?} is not an integer")))
            };
            pairs.push((num(xs, "x")?, num(ys, "y")?, n + 1));
        }
        pairs
    };
    if pairs.is_empty() {
        return Err(err(0, "the node list is empty".into()));
    }
    let mut cells = Vec::with_capacity(pairs.len());
    for &(x, y, line) in &pairs {
        if x < 0 || y < 0 || x as usize >= layout.width || y as usize >= layout.height {
            let e = PlannerError::OutOfGrid {
                x,
                y,
                width: layout.width,
                height: layout.height,
            };
            return Err(err(line, e.to_string()));
        }
        cells.push(CellIdx::from_xy(x as usize, y as usize, layout.width));
    }
    check_nodes(layout, &cells).map_err(|e| {
        // Name the line of the offending cell when there is one.
        let line = match &e {
            PlannerError::NotStandable { x, y, .. } | PlannerError::DuplicateNode { x, y } => pairs
                .iter()
                .filter(|p| (p.0, p.1) == (*x as i64, *y as i64))
                .map(|p| p.2)
                .next_back()
                .unwrap_or(0),
            _ => 0,
        };
        err(line, e.to_string())
    })
}

/// `(x, y, line)` of one listed cell.
type ListedCell = (i64, i64, usize);

/// The cells of a JSON node list (line 0: JSON values carry no line);
/// errors as `(line, message)`.
fn parse_json_pairs(text: &str) -> Result<Vec<ListedCell>, (usize, String)> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| (e.line(), format!("invalid JSON: {e}")))?;
    let list = match &value {
        serde_json::Value::Array(a) => a,
        serde_json::Value::Object(o) => match o.get("nodes") {
            Some(serde_json::Value::Array(a)) => a,
            _ => return Err((0, "a JSON object must hold the list under \"nodes\"".into())),
        },
        _ => return Err((0, "expected a JSON array of [x, y] pairs".into())),
    };
    let int = |v: Option<&serde_json::Value>, i: usize, what: &str| {
        v.and_then(serde_json::Value::as_i64)
            .ok_or_else(|| (0, format!("entry {i}: {what} missing or not an integer")))
    };
    list.iter()
        .enumerate()
        .map(|(i, v)| match v {
            serde_json::Value::Array(p) if p.len() == 2 => {
                Ok((int(p.first(), i, "x")?, int(p.get(1), i, "y")?, 0))
            }
            serde_json::Value::Object(o) => {
                Ok((int(o.get("x"), i, "x")?, int(o.get("y"), i, "y")?, 0))
            }
            _ => Err((
                0,
                format!("entry {i}: expected [x, y] or {{\"x\": .., \"y\": ..}}, found {v}"),
            )),
        })
        .collect()
}

/// Reads a node list file ([`parse_node_list`]).
pub fn read_node_file(layout: &Layout, path: &Path) -> Result<Vec<CellIdx>, PlannerError> {
    let text = std::fs::read_to_string(path).map_err(|source| PlannerError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse_node_list(layout, &path.display().to_string(), &text)
}

/// The node cells a configuration asks for. `given` supplies the cells of
/// [`CandidateSet::Given`] (and is ignored otherwise).
pub fn candidates(
    layout: &Layout,
    cfg: &PlannerConfig,
    given: &[CellIdx],
) -> Result<Vec<CellIdx>, PlannerError> {
    match &cfg.candidates {
        CandidateSet::Random { k } => v_rand(layout, *k, cfg.seed),
        CandidateSet::All => check_nodes(layout, &v_all(layout)),
        CandidateSet::File { path } => read_node_file(layout, Path::new(path)),
        CandidateSet::Given => check_nodes(layout, given),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::Maze;

    fn small() -> Layout {
        Maze::Small.layout(true)
    }

    #[test]
    fn v_all_holds_only_standable_cells_and_v_rand_is_seeded() {
        let l = small();
        let all = v_all(&l);
        assert!(
            all.iter().all(|c| is_node_object(
                Object::from_code(l.cells[c.index()]).expect("valid code")
            ))
        );
        let key = l
            .cells
            .iter()
            .position(|&c| c == Object::Key as u8)
            .expect("door-key maze has a key");
        assert!(!all.contains(&CellIdx(key as u32)));
        let a = v_rand(&l, 10, 3).expect("enough cells");
        assert_eq!(a, v_rand(&l, 10, 3).expect("enough cells"));
        assert_ne!(a, v_rand(&l, 10, 4).expect("enough cells"));
        assert_eq!(a.len(), 10);
        assert!(a.windows(2).all(|w| w[0] < w[1]));
        assert!(matches!(
            v_rand(&l, all.len() + 1, 0),
            Err(PlannerError::NotEnoughCells { .. })
        ));
    }

    #[test]
    fn node_lists_parse_as_text_and_json() {
        let l = small();
        let text = "# doorways\n1,1\n\n 2 3 \n";
        let want = vec![
            CellIdx::from_xy(1, 1, l.width),
            CellIdx::from_xy(2, 3, l.width),
        ];
        assert_eq!(parse_node_list(&l, "t", text).expect("text"), want);
        assert_eq!(
            parse_node_list(&l, "j", "[[1,1],[2,3]]").expect("pairs"),
            want
        );
        assert_eq!(
            parse_node_list(&l, "j", r#"{"nodes":[{"x":1,"y":1},{"x":2,"y":3}]}"#)
                .expect("objects"),
            want
        );
    }

    #[test]
    fn node_list_errors_name_the_line_and_the_problem() {
        let l = small();
        let msg = |t: &str| {
            parse_node_list(&l, "nodes.txt", t)
                .expect_err("must be refused")
                .to_string()
        };
        let e = msg("1,1\n2,x\n");
        assert!(
            e.contains("nodes.txt:2") && e.contains("not an integer"),
            "{e}"
        );
        let e = msg("1,1\n1 2 3\n");
        assert!(
            e.contains("nodes.txt:2") && e.contains("two integers"),
            "{e}"
        );
        let e = msg("1,1\n0,0\n");
        assert!(e.contains("nodes.txt:2") && e.contains("wall"), "{e}");
        let e = msg("1,1\n99,1\n");
        assert!(e.contains("nodes.txt:2") && e.contains("outside"), "{e}");
        let e = msg("1,1\n2,2\n1,1\n");
        assert!(e.contains("nodes.txt:3") && e.contains("twice"), "{e}");
        let key = l
            .cells
            .iter()
            .position(|&c| c == Object::Key as u8)
            .expect("key");
        let e = msg(&format!("{},{}\n", key % l.width, key / l.width));
        assert!(e.contains("key"), "{e}");
        assert!(msg("# nothing\n").contains("empty"));
        assert!(msg("[[1,1],[2]]").contains("entry 1"));
        assert!(msg("[[1,1],").contains("invalid JSON"));
        assert!(msg("{\"cells\": []}").contains("\"nodes\""));
        let missing = read_node_file(&l, Path::new("/nonexistent/nodes.txt"))
            .expect_err("no file")
            .to_string();
        assert!(missing.contains("/nonexistent/nodes.txt"), "{missing}");
    }

    #[test]
    fn top_ratio_keeps_the_most_pivotal_fraction_at_least_one() {
        let ranked: Vec<(u32, f32)> = (0..10).map(|c| (c, (c % 5) as f32)).collect();
        // 10 cells at ratio 0.25: ceil(2.5) = 3, most pivotal first, ties
        // to the lower cell.
        assert_eq!(top_ratio(ranked.clone(), 0.25), vec![4, 9, 3]);
        assert_eq!(top_ratio(ranked[..1].to_vec(), 0.2), vec![0]);
        assert_eq!(top_ratio(ranked.clone(), 0.0).len(), 1);
        assert_eq!(top_ratio(ranked, 2.0).len(), 10);
        assert!(top_ratio(Vec::new(), 0.2).is_empty());
    }

    #[test]
    fn raw_cells_become_valid_nodes() {
        let l = small();
        let key = l
            .cells
            .iter()
            .position(|&c| c == Object::Key as u8)
            .expect("key") as u32;
        let a = CellIdx::from_xy(1, 1, l.width).0;
        let b = CellIdx::from_xy(2, 1, l.width).0;
        assert_eq!(
            nodes_from_cells(&l, &[b, key, 0, a, b, 10_000]),
            vec![CellIdx(b), CellIdx(a)]
        );
    }
}
