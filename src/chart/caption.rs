//! Captions for the pictures: a title above and a legend below, each
//! legend mark drawn as the picture draws it ([`captioned`]).

use plotters::prelude::*;
use sim::Object;
use sim::render::{Canvas, Rgb, draw_grid, object_color};

use super::register_font;

/// Side in pixels of the cell a legend mark is drawn on.
pub const LEGEND_CELL: usize = 24;
/// The narrowest captioned picture: a smaller picture is centred on a
/// canvas this wide, so that its title and legend have room.
pub const MIN_CAPTIONED_WIDTH: usize = 480;
/// Title sizes tried in turn: the first that sets the title in at most two
/// lines is used (the last wraps onto as many as it needs).
const CAPTION_TITLE_PX: [u32; 3] = [18, 16, 14];
const CAPTION_TEXT_PX: u32 = 14;
const CAPTION_PAD: usize = 10;
/// A legend mark's box: two cells wide, one cell tall.
const MARK_W: usize = 2 * LEGEND_CELL;
/// Room for a legend column: its mark, a gap and about 36 characters.
const LEGEND_COLUMN_MIN: usize = 360;
const INK: RGBColor = RGBColor(30, 30, 30);

/// How a legend entry's mark is drawn: as the picture draws it, with the
/// same primitives and colours, on a cell of [`LEGEND_CELL`] pixels of
/// floor. Sizes are fractions of a cell.
#[derive(Debug, Clone)]
pub enum Mark {
    /// A square inset by `inset` of a cell on every side, `fill` blended
    /// at `alpha`.
    Square {
        /// Colour.
        fill: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Inset from the cell's sides, as a fraction of the cell.
        inset: f32,
    },
    /// A disc of `radius` in `fill` at `alpha`, over a disc a quarter
    /// wider in `outline` when there is one.
    Disc {
        /// Colour.
        fill: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Radius, as a fraction of the cell.
        radius: f32,
        /// The colour of a ring around the disc.
        outline: Option<Rgb>,
    },
    /// A line across two cells, `width` of a cell wide, in `colour` at
    /// `alpha`; with `arrow`, an arrow head at its right end.
    Line {
        /// Colour.
        colour: Rgb,
        /// Opacity in [0, 1].
        alpha: f32,
        /// Width, as a fraction of the cell.
        width: f32,
        /// An arrow head at the right end.
        arrow: bool,
    },
    /// A shade from `low` (left) to `high` (right), two cells long.
    Ramp {
        /// Colour at the left end.
        low: Rgb,
        /// Colour at the right end.
        high: Rgb,
    },
    /// A sample the picture's own drawing code made (a grid cell, a mark
    /// of several parts), shown as it is, centred in the mark's box.
    Sample(Canvas),
}

/// One row of a picture's legend: a mark and what it means.
#[derive(Debug, Clone)]
pub struct LegendEntry {
    /// The mark, drawn as the picture draws it.
    pub mark: Mark,
    /// What it means.
    pub label: String,
}

impl LegendEntry {
    /// An entry.
    pub fn new(mark: Mark, label: impl Into<String>) -> LegendEntry {
        LegendEntry {
            mark,
            label: label.into(),
        }
    }
}

/// One cell of object code `code` as [`draw_grid`] draws it, at
/// [`LEGEND_CELL`] pixels: a legend sample.
pub fn cell_sample(code: u8) -> Canvas {
    let mut c = Canvas::new(LEGEND_CELL, LEGEND_CELL, [255, 255, 255]);
    draw_grid(&mut c, &[code], 1, 0, 0, LEGEND_CELL);
    c
}

/// Legend entries for the objects a grid of `cells` holds (one per kind,
/// each drawn as [`draw_grid`] draws it), leaving out the kinds in `skip`
/// (those the picture explains itself).
pub fn object_entries(cells: &[u8], skip: &[Object]) -> Vec<LegendEntry> {
    Object::ALL
        .into_iter()
        .filter(|o| !skip.contains(o) && cells.contains(&(*o as u8)))
        .map(|o| {
            let label = match o {
                Object::Floor => "floor",
                Object::Wall => "wall",
                Object::Ball => "ball",
                Object::Key => "key",
                Object::DoorOpen => "open door",
                Object::DoorClosed => "closed door",
                Object::DoorLocked => "locked door (the key opens it)",
                Object::Exit => "exit",
                Object::Lava => "lava",
            };
            LegendEntry::new(Mark::Sample(cell_sample(o as u8)), label)
        })
        .collect()
}

/// The colour `c` blended at `alpha` over `bg`, as [`Canvas::blend`] leaves
/// it.
pub fn blended(bg: Rgb, c: Rgb, alpha: f32) -> Rgb {
    [0, 1, 2].map(|i| {
        let old = bg[i] as f32;
        (old + (c[i] as f32 - old) * alpha)
            .round()
            .clamp(0.0, 255.0) as u8
    })
}

/// Characters of the shipped monospace font at `size` px that fit in `px`
/// pixels (its advance is 0.602 em; 0.62 leaves a margin).
fn chars_fitting(px: usize, size: u32) -> usize {
    ((px as f32) / (0.62 * size as f32)).floor().max(1.0) as usize
}

/// Width in pixels of `n` characters at `size` px.
fn text_width(n: usize, size: u32) -> usize {
    (n as f32 * 0.602 * size as f32).ceil() as usize
}

/// `text` in lines of at most `max` characters, broken between words (a
/// word longer than a line is broken inside).
fn wrap(text: &str, max: usize) -> Vec<String> {
    let max = max.max(1);
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > max {
            if !line.is_empty() {
                lines.push(std::mem::take(&mut line));
            }
            lines.push(word.drain(..max).collect());
        }
        let word: String = word.into_iter().collect();
        let len = line.chars().count();
        if len > 0 && len + 1 + word.chars().count() > max {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// The size of a mark's drawing: its box (a sample may be larger).
fn mark_size(m: &Mark) -> (usize, usize) {
    match m {
        Mark::Sample(c) => (c.width.max(MARK_W), c.height.max(LEGEND_CELL)),
        _ => (MARK_W, LEGEND_CELL),
    }
}

/// Draws mark `m` in the box whose top-left corner is `(x, y)`.
fn draw_mark(c: &mut Canvas, m: &Mark, x: usize, y: usize) {
    let cell = LEGEND_CELL as f32;
    let floor = object_color(Object::Floor);
    let (xi, yi) = (x as i64, y as i64);
    let p = LEGEND_CELL as i64;
    // A one-cell mark sits on a floor cell in the middle of the box.
    let (cx0, cy0) = (xi + (MARK_W as i64 - p) / 2, yi);
    match m {
        Mark::Square { fill, alpha, inset } => {
            c.fill_rect(cx0, cy0, p, p, floor, 1.0);
            let d = (inset * cell).round() as i64;
            c.fill_rect(cx0 + d, cy0 + d, p - 2 * d, p - 2 * d, *fill, *alpha);
        }
        Mark::Disc {
            fill,
            alpha,
            radius,
            outline,
        } => {
            c.fill_rect(cx0, cy0, p, p, floor, 1.0);
            let (mx, my) = (cx0 as f32 + cell / 2.0, cy0 as f32 + cell / 2.0);
            if let Some(o) = outline {
                c.fill_disc(mx, my, radius * cell * 1.25, *o, 1.0);
            }
            c.fill_disc(mx, my, radius * cell, *fill, *alpha);
        }
        Mark::Line {
            colour,
            alpha,
            width,
            arrow,
        } => {
            c.fill_rect(xi, yi, MARK_W as i64, p, floor, 1.0);
            let my = y as f32 + cell / 2.0;
            let (a, b) = ((x as f32 + 3.0, my), ((x + MARK_W) as f32 - 3.0, my));
            c.line(a, b, (width * cell).max(1.0), *colour, *alpha);
            if *arrow {
                let base = b.0 - cell * 0.3;
                c.fill_triangle(
                    [b, (base, my - cell * 0.14), (base, my + cell * 0.14)],
                    *colour,
                    0.9,
                );
            }
        }
        Mark::Ramp { low, high } => {
            let w = MARK_W as i64;
            for k in 0..w {
                let t = k as f32 / (w - 1) as f32;
                let col = [0, 1, 2]
                    .map(|i| (low[i] as f32 + (high[i] as f32 - low[i] as f32) * t).round() as u8);
                c.fill_rect(xi + k, yi + 2, 1, p - 4, col, 1.0);
            }
        }
        Mark::Sample(s) => {
            let (bw, _) = mark_size(m);
            c.blit(s, x + (bw - s.width) / 2, y);
        }
    }
}

/// `picture` with a title above it and a legend below: a new canvas at
/// least [`MIN_CAPTIONED_WIDTH`] wide with the picture centred. The title
/// is wrapped (and set smaller when long) so it is never cut; the legend
/// has one entry per row, in as many columns as the width holds, each row
/// the mark as the picture draws it and its label (wrapped too).
pub fn captioned(picture: &Canvas, title: &str, legend: &[LegendEntry]) -> Canvas {
    register_font();
    let w = picture.width.max(MIN_CAPTIONED_WIDTH);
    let inner = w - 2 * CAPTION_PAD;

    // The title: the largest size that takes at most two lines.
    let (title_px, title_lines) = CAPTION_TITLE_PX
        .iter()
        .map(|&px| (px, wrap(title, chars_fitting(inner, px))))
        .find(|(_, l)| l.len() <= 2)
        .unwrap_or_else(|| {
            let px = CAPTION_TITLE_PX[CAPTION_TITLE_PX.len() - 1];
            (px, wrap(title, chars_fitting(inner, px)))
        });
    let title_line_h = title_px as usize + 6;
    let title_h = CAPTION_PAD + title_lines.len() * title_line_h + CAPTION_PAD / 2;
    let pic = ((w - picture.width) / 2, title_h + 1 + CAPTION_PAD / 2);

    // The legend, column-major.
    let cols = (inner / LEGEND_COLUMN_MIN)
        .clamp(1, 3)
        .min(legend.len().max(1));
    let col_w = inner / cols;
    let text_line_h = CAPTION_TEXT_PX as usize + 4;
    let entries: Vec<(Vec<String>, (usize, usize))> = legend
        .iter()
        .map(|e| {
            let (mw, mh) = mark_size(&e.mark);
            let room = col_w.saturating_sub(mw + 8 + 4);
            (
                wrap(&e.label, chars_fitting(room, CAPTION_TEXT_PX)),
                (mw, mh),
            )
        })
        .collect();
    let rows = entries.len().div_ceil(cols);
    let row_h: Vec<usize> = (0..rows)
        .map(|r| {
            (0..cols)
                .filter_map(|k| entries.get(k * rows + r))
                .map(|(lines, (_, mh))| (*mh).max(lines.len() * text_line_h))
                .max()
                .unwrap_or(0)
                + 6
        })
        .collect();
    let legend_y = pic.1 + picture.height + CAPTION_PAD;
    let h = legend_y + row_h.iter().sum::<usize>() + CAPTION_PAD;

    let mut c = Canvas::new(w, h, [255, 255, 255]);
    c.fill_rect(
        CAPTION_PAD as i64,
        title_h as i64,
        inner as i64,
        1,
        [215, 215, 215],
        1.0,
    );
    c.blit(picture, pic.0, pic.1);
    // Where each entry's mark and label go.
    let mut places = Vec::with_capacity(entries.len());
    for (i, (lines, (mw, mh))) in entries.iter().enumerate() {
        let (col, row) = (i / rows.max(1), i % rows.max(1));
        let x = CAPTION_PAD + col * col_w;
        let y = legend_y + row_h[..row].iter().sum::<usize>();
        let content = (*mh).max(lines.len() * text_line_h);
        draw_mark(&mut c, &legend[i].mark, x, y + (content - mh) / 2);
        let text_y = y + (content - lines.len() * text_line_h) / 2 + 2;
        places.push((x + mw + 8, text_y));
    }
    if let Err(e) = caption_text(
        &mut c,
        (title_px, &title_lines, title_line_h),
        &entries,
        &places,
        text_line_h,
    ) {
        unreachable!("invariant: drawing text into a canvas of the right size: {e}");
    }
    c
}

fn caption_text<'c>(
    canvas: &'c mut Canvas,
    (title_px, title_lines, title_line_h): (u32, &[String], usize),
    entries: &[(Vec<String>, (usize, usize))],
    places: &[(usize, usize)],
    text_line_h: usize,
) -> Result<(), Box<dyn std::error::Error + 'c>> {
    let (w, h) = (canvas.width as u32, canvas.height as u32);
    let root = BitMapBackend::with_buffer(&mut canvas.rgb, (w, h)).into_drawing_area();
    for (k, line) in title_lines.iter().enumerate() {
        let lw = text_width(line.chars().count(), title_px);
        let x = (w as usize).saturating_sub(lw) / 2;
        root.draw(&Text::new(
            line.clone(),
            (x as i32, (CAPTION_PAD + k * title_line_h) as i32),
            ("sans-serif", title_px).into_font().color(&INK),
        ))?;
    }
    for ((lines, _), &(x, y)) in entries.iter().zip(places) {
        for (k, line) in lines.iter().enumerate() {
            root.draw(&Text::new(
                line.clone(),
                (x as i32, (y + k * text_line_h) as i32),
                ("sans-serif", CAPTION_TEXT_PX).into_font().color(&INK),
            ))?;
        }
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The row at which `picture` sits at column `x` of `c`, if anywhere.
    fn find_picture(c: &Canvas, picture: &Canvas, x: usize) -> Option<usize> {
        let row = |cv: &Canvas, y: usize, x0: usize| {
            cv.rgb[(y * cv.width + x0) * 3..(y * cv.width + x0 + picture.width) * 3].to_vec()
        };
        (0..=c.height.saturating_sub(picture.height))
            .find(|&y| (0..picture.height).all(|r| row(c, y + r, x) == row(picture, r, 0)))
    }

    /// Pixels that are not white in rows `y0..y1` and columns `x0..x1`.
    fn ink(c: &Canvas, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| c.rgb[(y * c.width + x) * 3..(y * c.width + x) * 3 + 3] != [255; 3])
            .count()
    }

    /// Dark (text) pixels in rows `y0..y1` and columns `x0..x1`.
    fn dark(c: &Canvas, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                c.rgb[(y * c.width + x) * 3..(y * c.width + x) * 3 + 3]
                    .iter()
                    .all(|&v| v < 128)
            })
            .count()
    }

    /// A picture of three stripes (no row looks like another's neighbour).
    fn stripes(w: usize, h: usize) -> Canvas {
        let mut p = Canvas::new(w, h, [200, 40, 40]);
        p.fill_rect(
            0,
            (h / 3) as i64,
            w as i64,
            (h / 3) as i64,
            [40, 200, 40],
            1.0,
        );
        p.fill_rect(
            0,
            (2 * h / 3) as i64,
            w as i64,
            h as i64,
            [40, 40, 200],
            1.0,
        );
        p
    }

    #[test]
    fn a_captioned_picture_has_a_title_above_and_its_legend_below() {
        let picture = stripes(200, 90);
        let disc = [250, 120, 0];
        let c = captioned(
            &picture,
            "a title",
            &[
                LegendEntry::new(
                    Mark::Disc {
                        fill: disc,
                        alpha: 1.0,
                        radius: 0.3,
                        outline: None,
                    },
                    "an orange disc",
                ),
                LegendEntry::new(
                    Mark::Line {
                        colour: [0, 0, 0],
                        alpha: 1.0,
                        width: 0.1,
                        arrow: true,
                    },
                    "a line",
                ),
            ],
        );
        assert_eq!(c.width, MIN_CAPTIONED_WIDTH, "widened so the text fits");
        let x = (c.width - picture.width) / 2;
        let y = find_picture(&c, &picture, x).expect("the picture, whole and centred");
        assert!(y > 0 && c.height > y + picture.height, "{} {}", y, c.height);
        assert!(
            dark(&c, (0, c.width), (0, y.saturating_sub(2))) > 20,
            "the title strip holds text"
        );
        // The legend: the disc in its colour, and the labels' ink.
        let below = (y + picture.height, c.height);
        let discs = (below.0..below.1)
            .flat_map(|yy| (0..c.width).map(move |xx| (xx, yy)))
            .filter(|&(xx, yy)| c.rgb[(yy * c.width + xx) * 3..(yy * c.width + xx) * 3 + 3] == disc)
            .count();
        assert!(discs > 20, "the disc mark is drawn: {discs} px");
        assert!(
            dark(&c, (CAPTION_PAD + MARK_W + 8, c.width), below) > 20,
            "the labels are written"
        );
    }

    #[test]
    fn a_long_title_and_label_wrap_instead_of_being_cut() {
        let picture = stripes(120, 60);
        let label =
            "a legend label long enough to need more than one line in its column ".repeat(2);
        let short = captioned(&picture, "short", &[]);
        let long_title = "a very long title of a picture, ".repeat(8);
        let long = captioned(
            &picture,
            &long_title,
            &[LegendEntry::new(
                Mark::Ramp {
                    low: [255, 255, 255],
                    high: [0, 0, 0],
                },
                label,
            )],
        );
        let y_short = find_picture(&short, &picture, (short.width - 120) / 2).unwrap();
        let y_long = find_picture(&long, &picture, (long.width - 120) / 2).unwrap();
        assert!(
            y_long > y_short + 20,
            "the long title takes more lines: {y_long} vs {y_short}"
        );
        // Nothing reaches the right margin: no text is cut at the edge.
        let margin = (long.width - 4, long.width);
        assert_eq!(
            ink(&long, margin, (0, long.height)),
            0,
            "text ran off the right edge"
        );
        let legend_h = long.height - y_long - picture.height;
        assert!(
            legend_h > 2 * (CAPTION_TEXT_PX as usize + 4),
            "the label wrapped: {legend_h} px"
        );
        assert_eq!(wrap("ab cd ef", 5), ["ab cd", "ef"]);
        assert_eq!(wrap("abcdefgh", 3), ["abc", "def", "gh"]);
    }
}
