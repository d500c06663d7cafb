//! Pictures of the maze: ASCII for the terminal, PNG files for reports.
//!
//! [`Canvas`] is a tiny RGB raster with the few primitives the project needs
//! (rectangles, discs, lines, triangles) and an atomic PNG writer; the
//! planner draws the world graph on top of [`draw_grid`]'s maze.

use std::path::Path;

use shm_schemas::EnvMeta;

use crate::SimError;
use crate::layout::Pose;
use crate::object::Object;

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Colour of each object when drawn.
pub fn object_color(o: Object) -> Rgb {
    match o {
        Object::Floor => [236, 236, 232],
        Object::Wall => [64, 64, 72],
        Object::Ball => [40, 110, 230],
        Object::Key => [230, 190, 20],
        Object::DoorOpen => [250, 225, 140],
        Object::DoorClosed => [200, 150, 20],
        Object::DoorLocked => [150, 90, 10],
        Object::Exit => [40, 180, 70],
        Object::Lava => [240, 90, 20],
    }
}

/// Agent colour.
pub const AGENT_COLOR: Rgb = [220, 30, 40];

/// An RGB image in memory.
#[derive(Debug, Clone)]
pub struct Canvas {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major RGB bytes.
    pub rgb: Vec<u8>,
}

impl Canvas {
    /// A canvas filled with `bg`.
    pub fn new(width: usize, height: usize, bg: Rgb) -> Canvas {
        let mut rgb = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            rgb.extend_from_slice(&bg);
        }
        Canvas { width, height, rgb }
    }

    /// Sets one pixel (ignored outside the canvas); `alpha` in [0, 1] blends.
    #[inline]
    pub fn blend(&mut self, x: i64, y: i64, c: Rgb, alpha: f32) {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return;
        }
        let i = (y as usize * self.width + x as usize) * 3;
        for (dst, &src) in self.rgb[i..i + 3].iter_mut().zip(c.iter()) {
            let old = *dst as f32;
            *dst = (old + (src as f32 - old) * alpha).round().clamp(0.0, 255.0) as u8;
        }
    }

    /// Fills the rectangle `[x, x+w) × [y, y+h)`.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb, alpha: f32) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.blend(xx, yy, c, alpha);
            }
        }
    }

    /// Fills a disc of radius `r` centred on `(cx, cy)`.
    pub fn fill_disc(&mut self, cx: f32, cy: f32, r: f32, c: Rgb, alpha: f32) {
        let (x0, x1) = ((cx - r).floor() as i64, (cx + r).ceil() as i64);
        let (y0, y1) = ((cy - r).floor() as i64, (cy + r).ceil() as i64);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                if dx * dx + dy * dy <= r * r {
                    self.blend(x, y, c, alpha);
                }
            }
        }
    }

    /// Draws a line of the given width from `a` to `b`.
    pub fn line(&mut self, a: (f32, f32), b: (f32, f32), width: f32, c: Rgb, alpha: f32) {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let r = (width / 2.0).max(0.5);
        let (x0, x1) = (
            (a.0.min(b.0) - r).floor() as i64,
            (a.0.max(b.0) + r).ceil() as i64,
        );
        let (y0, y1) = (
            (a.1.min(b.1) - r).floor() as i64,
            (a.1.max(b.1) + r).ceil() as i64,
        );
        // Distance-to-segment test over the bounding box: no double blending.
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = (x as f32 + 0.5, y as f32 + 0.5);
                let t = if len == 0.0 {
                    0.0
                } else {
                    (((p.0 - a.0) * (b.0 - a.0) + (p.1 - a.1) * (b.1 - a.1)) / (len * len))
                        .clamp(0.0, 1.0)
                };
                let q = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
                if (p.0 - q.0).powi(2) + (p.1 - q.1).powi(2) <= r * r {
                    self.blend(x, y, c, alpha);
                }
            }
        }
    }

    /// Fills the triangle `(a, b, c)`.
    pub fn fill_triangle(&mut self, p: [(f32, f32); 3], c: Rgb, alpha: f32) {
        let x0 = p.iter().map(|q| q.0).fold(f32::INFINITY, f32::min).floor() as i64;
        let x1 = p
            .iter()
            .map(|q| q.0)
            .fold(f32::NEG_INFINITY, f32::max)
            .ceil() as i64;
        let y0 = p.iter().map(|q| q.1).fold(f32::INFINITY, f32::min).floor() as i64;
        let y1 = p
            .iter()
            .map(|q| q.1)
            .fold(f32::NEG_INFINITY, f32::max)
            .ceil() as i64;
        let edge = |a: (f32, f32), b: (f32, f32), q: (f32, f32)| {
            (b.0 - a.0) * (q.1 - a.1) - (b.1 - a.1) * (q.0 - a.0)
        };
        for y in y0..=y1 {
            for x in x0..=x1 {
                let q = (x as f32 + 0.5, y as f32 + 0.5);
                let (e0, e1, e2) = (
                    edge(p[0], p[1], q),
                    edge(p[1], p[2], q),
                    edge(p[2], p[0], q),
                );
                if (e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0) || (e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0) {
                    self.blend(x, y, c, alpha);
                }
            }
        }
    }

    /// Copies `other` with its top-left corner at `(x, y)`.
    pub fn blit(&mut self, other: &Canvas, x: usize, y: usize) {
        for row in 0..other.height.min(self.height.saturating_sub(y)) {
            let n = other.width.min(self.width.saturating_sub(x)) * 3;
            let dst = ((y + row) * self.width + x) * 3;
            let src = row * other.width * 3;
            self.rgb[dst..dst + n].copy_from_slice(&other.rgb[src..src + n]);
        }
    }

    /// PNG bytes of the canvas.
    pub fn encode_png(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width as u32, self.height as u32);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(|e| e.to_string())?;
            w.write_image_data(&self.rgb).map_err(|e| e.to_string())?;
        }
        Ok(out)
    }

    /// Writes the canvas as a PNG file atomically (temporary file, fsync, rename).
    pub fn save_png(&self, path: &Path) -> Result<(), SimError> {
        let bytes = self.encode_png().map_err(|message| SimError::Png {
            path: path.display().to_string(),
            message,
        })?;
        crate::atomic_file::write_atomic(path, &bytes)
    }
}

/// Draws a grid of cell codes with each cell `px` pixels wide, top-left at `(ox, oy)`.
pub fn draw_grid(canvas: &mut Canvas, cells: &[u8], width: usize, ox: usize, oy: usize, px: usize) {
    for (i, &c) in cells.iter().enumerate() {
        let (x, y) = ((i % width) * px + ox, (i / width) * px + oy);
        let o = Object::from_code(c).unwrap_or(Object::Wall);
        let (x, y, p) = (x as i64, y as i64, px as i64);
        match o {
            Object::Ball => {
                canvas.fill_rect(x, y, p, p, object_color(Object::Floor), 1.0);
                canvas.fill_disc(
                    x as f32 + p as f32 / 2.0,
                    y as f32 + p as f32 / 2.0,
                    p as f32 * 0.32,
                    object_color(o),
                    1.0,
                );
            }
            Object::Key => {
                canvas.fill_rect(x, y, p, p, object_color(Object::Floor), 1.0);
                let s = p as f32;
                canvas.fill_disc(
                    x as f32 + s * 0.35,
                    y as f32 + s * 0.35,
                    s * 0.18,
                    object_color(o),
                    1.0,
                );
                canvas.line(
                    (x as f32 + s * 0.4, y as f32 + s * 0.4),
                    (x as f32 + s * 0.8, y as f32 + s * 0.8),
                    s * 0.12,
                    object_color(o),
                    1.0,
                );
            }
            _ => canvas.fill_rect(x, y, p, p, object_color(o), 1.0),
        }
        if o == Object::DoorLocked || o == Object::DoorClosed {
            let q = (p / 6).max(1);
            canvas.fill_rect(
                x + q,
                y + p / 2 - q / 2,
                p - 2 * q,
                q.max(1),
                [60, 40, 10],
                1.0,
            );
        }
        // Faint grid lines make cells countable.
        if o != Object::Wall {
            canvas.fill_rect(x, y, p, 1, [205, 205, 200], 1.0);
            canvas.fill_rect(x, y, 1, p, [205, 205, 200], 1.0);
        }
    }
}

/// Draws the agent as a triangle pointing in its direction.
pub fn draw_agent(canvas: &mut Canvas, pose: Pose, ox: usize, oy: usize, px: usize) {
    let s = px as f32;
    let (cx, cy) = (
        ox as f32 + (pose.x as f32 + 0.5) * s,
        oy as f32 + (pose.y as f32 + 0.5) * s,
    );
    let (dx, dy) = Pose::DIR_VEC[(pose.dir & 3) as usize];
    let (dx, dy) = (dx as f32, dy as f32);
    let tip = (cx + dx * s * 0.38, cy + dy * s * 0.38);
    let back = (cx - dx * s * 0.32, cy - dy * s * 0.32);
    let side = (-dy * s * 0.3, dx * s * 0.3);
    canvas.fill_triangle(
        [
            tip,
            (back.0 + side.0, back.1 + side.1),
            (back.0 - side.0, back.1 - side.1),
        ],
        AGENT_COLOR,
        1.0,
    );
}

/// A canvas with one environment's grid and agent.
pub fn render_env(cells: &[u8], width: usize, height: usize, meta: &EnvMeta, px: usize) -> Canvas {
    let mut c = Canvas::new(width * px, height * px, [255, 255, 255]);
    draw_grid(&mut c, cells, width, 0, 0, px);
    draw_agent(
        &mut c,
        Pose {
            x: meta.x,
            y: meta.y,
            dir: meta.dir,
        },
        0,
        0,
        px,
    );
    c
}

/// A canvas tiling the first `count` environments of a batch output, `cols` per row.
pub fn render_batch(
    cells: &[u8],
    meta: &[EnvMeta],
    width: usize,
    height: usize,
    count: usize,
    cols: usize,
    px: usize,
) -> Canvas {
    let count = count.min(meta.len()).max(1);
    let cols = cols.clamp(1, count);
    let rows = count.div_ceil(cols);
    let gap = px / 2 + 1;
    let (tw, th) = (width * px + gap, height * px + gap);
    let mut c = Canvas::new(cols * tw + gap, rows * th + gap, [255, 255, 255]);
    let cpe = width * height;
    for i in 0..count {
        let tile = render_env(&cells[i * cpe..(i + 1) * cpe], width, height, &meta[i], px);
        c.blit(&tile, gap + (i % cols) * tw, gap + (i / cols) * th);
    }
    c
}

/// The grid as text in the layout format, the agent drawn as `> v < ^`.
pub fn ascii(cells: &[u8], width: usize, meta: &EnvMeta) -> String {
    let mut s = String::with_capacity(cells.len() + cells.len() / width.max(1));
    for (i, &c) in cells.iter().enumerate() {
        if i % width == meta.x as usize && i / width == meta.y as usize {
            s.push(Pose::DIR_CHAR[(meta.dir & 3) as usize]);
        } else {
            s.push(Object::from_code(c).map_or('?', Object::to_char));
        }
        if i % width == width - 1 {
            s.push('\n');
        }
    }
    s
}
