//! ASCII maze layouts: parsing, validation and the embedded mazes.
//!
//! One character per cell:
//!
//! | char | cell |
//! |---|---|
//! | `#` | wall |
//! | `.` | floor |
//! | `E` | exit |
//! | `K` | key |
//! | `D` | locked door |
//! | `C` | closed (unlocked) door |
//! | `O` | open door |
//! | `B` | ball |
//! | `L` | lava |
//! | `>` `v` `<` `^` | the agent's start, facing right, down, left, up (floor underneath) |
//!
//! A layout must be rectangular, enclosed by walls, hold exactly one agent
//! and at least one exit, and the exit must be reachable from the start
//! (doors count as passable, lava does not). Errors name the line and column
//! (both 1-based).

use std::fmt;
use std::path::Path;

use crate::object::Object;

/// Agent pose: position and facing. `x` is the column from the left, `y` the
/// row from the top; `dir` is 0 right, 1 down, 2 left, 3 up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// Column from the left.
    pub x: u16,
    /// Row from the top.
    pub y: u16,
    /// 0 right, 1 down, 2 left, 3 up.
    pub dir: u8,
}

impl Pose {
    /// Unit step `(dx, dy)` of each direction.
    pub const DIR_VEC: [(i32, i32); 4] = [(1, 0), (0, 1), (-1, 0), (0, -1)];
    /// Agent character for each direction.
    pub const DIR_CHAR: [char; 4] = ['>', 'v', '<', '^'];
}

/// What is wrong with a layout.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum LayoutErrorKind {
    /// The layout has no rows.
    Empty,
    /// A row's length differs from the first row's.
    RaggedRow {
        /// Length of the first row.
        expected: usize,
        /// Length of this row.
        found: usize,
    },
    /// A character that is not part of the format.
    UnknownChar(char),
    /// A second agent character.
    TwoAgents {
        /// Line of the first agent.
        first_line: usize,
        /// Column of the first agent.
        first_col: usize,
    },
    /// No agent character at all.
    NoAgent,
    /// No `E` cell.
    NoExit,
    /// A border cell that is not a wall.
    NotEnclosed(char),
    /// No exit can be reached from the agent's start.
    UnreachableExit,
    /// The layout is larger than the simulator supports.
    TooLarge {
        /// Width found.
        width: usize,
        /// Height found.
        height: usize,
    },
}

/// A layout error with its position (1-based line and column; 0 when the
/// error concerns the whole layout).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayoutError {
    /// Where the layout came from (file name or maze name).
    pub source: String,
    /// 1-based line, 0 if not tied to a line.
    pub line: usize,
    /// 1-based column, 0 if not tied to a column.
    pub col: usize,
    /// What is wrong.
    pub kind: LayoutErrorKind,
}

impl fmt::Display for LayoutError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use LayoutErrorKind::*;
        if self.line > 0 {
            write!(f, "{}:{}:{}: ", self.source, self.line, self.col)?;
        } else {
            write!(f, "{}: ", self.source)?;
        }
        match &self.kind {
            Empty => write!(f, "the layout is empty"),
            RaggedRow { expected, found } => write!(
                f,
                "ragged row: line {} has {found} cells but the first row has {expected}",
                self.line
            ),
            UnknownChar(c) => write!(
                f,
                "unknown character {c:?} at line {}, column {} (allowed: # . E K D C O B L > v < ^)",
                self.line, self.col
            ),
            TwoAgents {
                first_line,
                first_col,
            } => write!(
                f,
                "a second agent at line {}, column {}; the first is at line {first_line}, column {first_col}",
                self.line, self.col
            ),
            NoAgent => write!(f, "no agent start (one of > v < ^)"),
            NoExit => write!(f, "no exit 'E'"),
            NotEnclosed(c) => write!(
                f,
                "the border must be wall '#', found {c:?} at line {}, column {}",
                self.line, self.col
            ),
            UnreachableExit => write!(
                f,
                "the exit at line {}, column {} cannot be reached from the agent's start",
                self.line, self.col
            ),
            TooLarge { width, height } => write!(
                f,
                "the layout is {width}x{height}; at most {MAX_SIDE}x{MAX_SIDE} cells are supported"
            ),
        }
    }
}

impl std::error::Error for LayoutError {}

/// Largest width or height a layout may have (positions are `u16`, and the
/// shared-memory schemas size their buffers by it).
pub const MAX_SIDE: usize = 64;

/// Largest layout file read (bytes): far above any [`MAX_SIDE`]-square
/// layout, even with CRLF line ends and trailing blank lines. A longer file
/// (or an endless one such as `/dev/zero`) is refused after reading this
/// much, not read whole.
pub const MAX_LAYOUT_FILE_BYTES: u64 = 64 * 1024;

/// A parsed, validated maze layout: the initial grid and the agent's start.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    /// Name (maze name or file name).
    pub name: String,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Row-major cell codes (`Object as u8`), the agent's cell is floor.
    pub cells: Vec<u8>,
    /// The agent's start pose.
    pub start: Pose,
}

impl Layout {
    /// Parses and validates a layout. `source` names it in error messages.
    pub fn parse(source: &str, text: &str) -> Result<Layout, LayoutError> {
        let err = |line: usize, col: usize, kind| LayoutError {
            source: source.to_string(),
            line,
            col,
            kind,
        };
        // Trailing blank lines are tolerated; a blank line inside is a ragged row.
        let lines: Vec<&str> = text.trim_end_matches(['\n', '\r', ' ']).lines().collect();
        if lines.is_empty() || lines[0].trim_end_matches('\r').is_empty() {
            return Err(err(0, 0, LayoutErrorKind::Empty));
        }
        let width = lines[0].trim_end_matches('\r').chars().count();
        let height = lines.len();
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(err(0, 0, LayoutErrorKind::TooLarge { width, height }));
        }
        let mut cells = Vec::with_capacity(width * height);
        let mut start: Option<(Pose, usize, usize)> = None;
        for (y, raw) in lines.iter().enumerate() {
            let row = raw.trim_end_matches('\r');
            let n = row.chars().count();
            if n != width {
                return Err(err(
                    y + 1,
                    n.min(width) + 1,
                    LayoutErrorKind::RaggedRow {
                        expected: width,
                        found: n,
                    },
                ));
            }
            for (x, c) in row.chars().enumerate() {
                if let Some(dir) = Pose::DIR_CHAR.iter().position(|&d| d == c) {
                    if let Some((_, fl, fc)) = start {
                        return Err(err(
                            y + 1,
                            x + 1,
                            LayoutErrorKind::TwoAgents {
                                first_line: fl,
                                first_col: fc,
                            },
                        ));
                    }
                    let pose = Pose {
                        x: x as u16,
                        y: y as u16,
                        dir: dir as u8,
                    };
                    start = Some((pose, y + 1, x + 1));
                    cells.push(Object::Floor as u8);
                } else if let Some(o) = Object::from_char(c) {
                    cells.push(o as u8);
                } else {
                    return Err(err(y + 1, x + 1, LayoutErrorKind::UnknownChar(c)));
                }
            }
        }
        // The border first: everything else assumes an enclosed grid.
        for y in 0..height {
            for x in 0..width {
                let border = x == 0 || y == 0 || x == width - 1 || y == height - 1;
                if !border {
                    continue;
                }
                let is_agent = start.is_some_and(|(p, ..)| p.x as usize == x && p.y as usize == y);
                let code = cells[y * width + x];
                if is_agent || code != Object::Wall as u8 {
                    let c = if is_agent {
                        lines[y].chars().nth(x).unwrap_or('?')
                    } else {
                        Object::from_code(code).map_or('?', Object::to_char)
                    };
                    return Err(err(y + 1, x + 1, LayoutErrorKind::NotEnclosed(c)));
                }
            }
        }
        let Some((start, ..)) = start else {
            return Err(err(0, 0, LayoutErrorKind::NoAgent));
        };
        let exits: Vec<usize> = (0..cells.len())
            .filter(|&i| cells[i] == Object::Exit as u8)
            .collect();
        if exits.is_empty() {
            return Err(err(0, 0, LayoutErrorKind::NoExit));
        }
        let layout = Layout {
            name: source.to_string(),
            width,
            height,
            cells,
            start,
        };
        let reach = layout.reachable_from(layout.cell_index(start.x as usize, start.y as usize));
        if let Some(&e) = exits.iter().find(|&&e| !reach[e]) {
            return Err(err(
                e / width + 1,
                e % width + 1,
                LayoutErrorKind::UnreachableExit,
            ));
        }
        Ok(layout)
    }

    /// Reads and parses a layout file.
    pub fn from_file(path: &Path) -> Result<Layout, crate::SimError> {
        use std::io::Read as _;
        let io = |e: std::io::Error| crate::SimError::Io {
            path: path.display().to_string(),
            source: e,
        };
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_LAYOUT_FILE_BYTES + 1).read_to_end(&mut bytes))
            .map_err(io)?;
        if bytes.len() as u64 > MAX_LAYOUT_FILE_BYTES {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "longer than {MAX_LAYOUT_FILE_BYTES} bytes: not a layout (at most \
                     {MAX_SIDE}x{MAX_SIDE} cells)"
                ),
            )));
        }
        let text = String::from_utf8(bytes).map_err(|_| {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "stream did not contain valid UTF-8",
            ))
        })?;
        Ok(Layout::parse(&path.display().to_string(), &text)?)
    }

    /// Row-major index of cell `(x, y)`.
    #[inline]
    pub fn cell_index(&self, x: usize, y: usize) -> usize {
        y * self.width + x
    }

    /// Object at `(x, y)` in the initial grid.
    pub fn object(&self, x: usize, y: usize) -> Object {
        Object::from_code(self.cells[self.cell_index(x, y)])
            .expect("invariant: layouts hold valid codes")
    }

    /// Cells reachable from `from` by 4-neighbour moves through anything but
    /// walls and lava (doors count as passable: keys are assumed reachable).
    pub fn reachable_from(&self, from: usize) -> Vec<bool> {
        let mut seen = vec![false; self.cells.len()];
        let mut stack = vec![from];
        seen[from] = true;
        while let Some(i) = stack.pop() {
            for (dx, dy) in Pose::DIR_VEC {
                let x = (i % self.width) as i32 + dx;
                let y = (i / self.width) as i32 + dy;
                if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
                    continue;
                }
                let j = y as usize * self.width + x as usize;
                let c = self.cells[j];
                if !seen[j] && c != Object::Wall as u8 && c != Object::Lava as u8 {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        seen
    }

    /// Indices of the cells an agent can ever stand on (walls excluded,
    /// reachable from the start): the state space `V_all` of the paper.
    pub fn free_cells(&self) -> Vec<u32> {
        let reach =
            self.reachable_from(self.cell_index(self.start.x as usize, self.start.y as usize));
        (0..self.cells.len())
            .filter(|&i| reach[i] && self.cells[i] != Object::Wall as u8)
            .map(|i| i as u32)
            .collect()
    }

    /// The maze's structure without a task's state: every door open, keys
    /// and balls taken away (floor). One world graph per maze serves every
    /// task on it (Shang et al. 2019, section 4.3, "Execution"): its nodes
    /// and edges are found on this layout, so a route through a door
    /// exists, and a route is refused at run time only while a cell on it
    /// is blocked (a closed door, a key lying there).
    pub fn structural(&self) -> Layout {
        let cells = self
            .cells
            .iter()
            .map(|&c| match Object::from_code(c) {
                Some(o) if o.is_door() => Object::DoorOpen as u8,
                Some(Object::Key | Object::Ball) => Object::Floor as u8,
                _ => c,
            })
            .collect();
        Layout {
            name: self.name.clone(),
            width: self.width,
            height: self.height,
            cells,
            start: self.start,
        }
    }

    /// Cells holding a task's objects the agent acts on (keys, doors that
    /// are not open), in cell order.
    pub fn object_cells(&self) -> Vec<u32> {
        (0..self.cells.len())
            .filter(|&i| Object::from_code(self.cells[i]).is_some_and(Object::is_acted_on))
            .map(|i| i as u32)
            .collect()
    }

    /// The layout as text, in the file format (agent drawn at its start).
    pub fn to_text(&self) -> String {
        let mut s = String::with_capacity((self.width + 1) * self.height);
        for y in 0..self.height {
            for x in 0..self.width {
                if x == self.start.x as usize && y == self.start.y as usize {
                    s.push(Pose::DIR_CHAR[self.start.dir as usize]);
                } else {
                    s.push(self.object(x, y).to_char());
                }
            }
            s.push('\n');
        }
        s
    }
}

/// The three embedded mazes of the paper's experiments (section 5): small,
/// medium and large. The small maze is the top-left part of the medium one;
/// the large one has a different composition (halls, long corridors).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Maze {
    /// 13×13, four rooms.
    Small,
    /// 25×19, the small maze plus rooms and corridors.
    Medium,
    /// 31×25, halls and long corridors.
    Large,
}

impl Maze {
    /// All mazes, small to large.
    pub const ALL: [Maze; 3] = [Maze::Small, Maze::Medium, Maze::Large];

    /// The maze's name.
    pub fn name(self) -> &'static str {
        match self {
            Maze::Small => "small",
            Maze::Medium => "medium",
            Maze::Large => "large",
        }
    }

    /// The layout text: the Door-Key variant (a locked door guarding the
    /// exit and a key elsewhere) when `door_key` is set.
    pub fn text(self, door_key: bool) -> &'static str {
        match (self, door_key) {
            (Maze::Small, false) => include_str!("../mazes/small.txt"),
            (Maze::Small, true) => include_str!("../mazes/small-doorkey.txt"),
            (Maze::Medium, false) => include_str!("../mazes/medium.txt"),
            (Maze::Medium, true) => include_str!("../mazes/medium-doorkey.txt"),
            (Maze::Large, false) => include_str!("../mazes/large.txt"),
            (Maze::Large, true) => include_str!("../mazes/large-doorkey.txt"),
        }
    }

    /// The parsed layout.
    pub fn layout(self, door_key: bool) -> Layout {
        let name = if door_key {
            format!("{}-doorkey", self.name())
        } else {
            self.name().to_string()
        };
        Layout::parse(&name, self.text(door_key)).expect("invariant: embedded mazes are valid")
    }
}

impl std::str::FromStr for Maze {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "small" => Ok(Maze::Small),
            "medium" => Ok(Maze::Medium),
            "large" => Ok(Maze::Large),
            _ => Err(format!(
                "unknown maze {s:?}: expected small, medium or large"
            )),
        }
    }
}

impl fmt::Display for Maze {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kind(text: &str) -> (usize, usize, LayoutErrorKind) {
        let e = Layout::parse("t", text).expect_err("must be refused");
        (e.line, e.col, e.kind)
    }

    #[test]
    fn the_structural_layout_opens_doors_and_clears_keys_and_keeps_walls() {
        let dk = Maze::Small.layout(true);
        let s = dk.structural();
        let (door, key) = (dk.cell_index(6, 9), dk.cell_index(9, 2));
        assert_eq!(dk.object_cells(), vec![key as u32, door as u32]);
        assert_eq!(s.cells[door], Object::DoorOpen as u8);
        assert_eq!(s.cells[key], Object::Floor as u8);
        assert!(s.object_cells().is_empty());
        // The Door-Key variant's own walls stay: the structure of *its* maze.
        let walls = |l: &Layout| l.cells.iter().filter(|&&c| c == Object::Wall as u8).count();
        assert_eq!(walls(&s), walls(&dk));
        assert_eq!(s.structural(), s);
    }

    #[test]
    fn embedded_mazes_parse_and_small_is_part_of_medium() {
        for m in Maze::ALL {
            for dk in [false, true] {
                let l = m.layout(dk);
                assert!(l.free_cells().len() > 20, "{m} {dk}");
            }
        }
        let small = Maze::Small.layout(false);
        let medium = Maze::Medium.layout(false);
        // The small maze's rooms (all but its outer right and bottom walls and
        // its exit) reappear in the medium maze's top-left corner.
        let mut same = 0;
        let mut total = 0;
        for y in 1..small.height - 1 {
            for x in 1..small.width - 1 {
                total += 1;
                let s = small.cells[small.cell_index(x, y)];
                let m = medium.cells[medium.cell_index(x, y)];
                same += usize::from(s == m || s == Object::Exit as u8);
            }
        }
        assert_eq!(same, total);
        assert_ne!(Maze::Large.layout(false).width, medium.width);
    }

    #[test]
    fn door_key_variants_lock_the_exit_behind_a_door() {
        for m in Maze::ALL {
            let l = m.layout(true);
            let doors = l
                .cells
                .iter()
                .filter(|&&c| c == Object::DoorLocked as u8)
                .count();
            let keys = l.cells.iter().filter(|&&c| c == Object::Key as u8).count();
            assert_eq!((doors, keys), (1, 1), "{m}");
            // Treating the locked door as a wall, the exit is cut off.
            let mut blocked = l.clone();
            for c in blocked.cells.iter_mut() {
                if *c == Object::DoorLocked as u8 {
                    *c = Object::Wall as u8;
                }
            }
            let reach =
                blocked.reachable_from(blocked.cell_index(l.start.x as usize, l.start.y as usize));
            let exit = l
                .cells
                .iter()
                .position(|&c| c == Object::Exit as u8)
                .unwrap();
            assert!(!reach[exit], "{m}: exit reachable without the door");
            let key = l
                .cells
                .iter()
                .position(|&c| c == Object::Key as u8)
                .unwrap();
            assert!(reach[key], "{m}: key not reachable from the start");
        }
    }

    #[test]
    fn malformed_layouts_name_line_and_column() {
        assert_eq!(kind("#####\n#>.E#\n####\n").0, 3);
        let (l, c, k) = kind("#####\n#>xE#\n#####\n");
        assert_eq!((l, c, k), (2, 3, LayoutErrorKind::UnknownChar('x')));
        let (l, c, k) = kind("######\n#>.<E#\n######\n");
        assert_eq!((l, c), (2, 4));
        assert!(matches!(
            k,
            LayoutErrorKind::TwoAgents {
                first_line: 2,
                first_col: 2
            }
        ));
        assert_eq!(kind("#####\n#>..#\n#####\n").2, LayoutErrorKind::NoExit);
        assert_eq!(
            kind("#####\n#...E\n#####\n"),
            (2, 5, LayoutErrorKind::NotEnclosed('E'))
        );
        assert_eq!(
            kind("#####\n>..E#\n#####\n"),
            (2, 1, LayoutErrorKind::NotEnclosed('>'))
        );
        assert_eq!(kind("#####\n#.#E#\n#####\n").2, LayoutErrorKind::NoAgent);
        assert_eq!(
            kind("######\n#>#.E#\n######\n"),
            (2, 5, LayoutErrorKind::UnreachableExit)
        );
        assert_eq!(
            kind("#######\n#>.L.E#\n#######\n"),
            (2, 6, LayoutErrorKind::UnreachableExit)
        );
        assert_eq!(kind("").2, LayoutErrorKind::Empty);
        let e = Layout::parse("maze.txt", "#####\n#>xE#\n#####\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("maze.txt:2:3") && e.contains("line 2, column 3"),
            "{e}"
        );
    }

    #[test]
    fn doors_do_not_block_reachability_and_text_round_trips() {
        let l = Layout::parse("t", "#######\n#>.D.E#\n#######\n").unwrap();
        assert_eq!(Layout::parse("t", &l.to_text()).unwrap(), l);
        assert_eq!(l.free_cells().len(), 5);
    }
}
