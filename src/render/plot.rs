//! Small line plots written as PNG, for `lantern validate` and the
//! benchmarks' RMSE-against-time curves: axes with ticks, a log or linear
//! x axis, a linear or log y axis, one polyline with markers per series, and
//! a legend, lettered in a built-in 3×5 pixel font (drawn at 2× scale) so
//! that no font file is needed.

use std::path::Path;

use anyhow::{Context, Result};

/// One series of a plot.
#[derive(Clone, Debug)]
pub struct Series {
    name: String,
    colour: [f32; 3],
    points: Vec<(f32, f32)>,
}

impl Series {
    /// A named series of `(x, y)` points in a linear RGB colour.
    pub fn new(name: &str, colour: [f32; 3], points: Vec<(f32, f32)>) -> Self {
        Self {
            name: name.to_owned(),
            colour,
            points,
        }
    }
}

/// A plot under construction.
#[derive(Clone, Debug)]
pub struct Plot {
    title: String,
    x_label: String,
    y_label: String,
    log_x: bool,
    log_y: bool,
    series: Vec<Series>,
}

const W: u32 = 640;
const H: u32 = 420;
const LEFT: i32 = 70;
const RIGHT: i32 = 20;
const TOP: i32 = 40;
const BOTTOM: i32 = 50;
const SCALE: i32 = 2;

impl Plot {
    /// An empty plot; `log_x` puts the x axis on a log scale.
    pub fn new(title: &str, x_label: &str, y_label: &str, log_x: bool) -> Self {
        Self {
            title: title.to_owned(),
            x_label: x_label.to_owned(),
            y_label: y_label.to_owned(),
            log_x,
            log_y: false,
            series: Vec::new(),
        }
    }

    /// Puts the y axis on a log scale.
    pub fn log_y(mut self, on: bool) -> Self {
        self.log_y = on;
        self
    }

    /// Adds a series.
    pub fn add(&mut self, s: Series) {
        self.series.push(s);
    }

    /// Renders the plot to an RGB image.
    pub fn render(&self) -> image::RgbImage {
        let mut img = image::RgbImage::from_pixel(W, H, image::Rgb([24, 24, 28]));
        let fx = |x: f32| if self.log_x { x.max(1e-30).log10() } else { x };
        let fy = |y: f32| if self.log_y { y.max(1e-30).log10() } else { y };
        let pts = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .filter(|(x, y)| (!self.log_x || *x > 0.0) && (!self.log_y || *y > 0.0))
        };
        let (mut x0, mut x1) = (f32::INFINITY, f32::NEG_INFINITY);
        let (mut y0, mut y1) = (f32::INFINITY, f32::NEG_INFINITY);
        for &(x, y) in pts() {
            x0 = x0.min(fx(x));
            x1 = x1.max(fx(x));
            y0 = y0.min(fy(y));
            y1 = y1.max(fy(y));
        }
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if !self.log_y {
            y0 = y0.min(0.0);
        }
        if x1 - x0 < 1e-12 {
            x0 -= 0.5;
            x1 += 0.5;
        }
        if y1 - y0 < 1e-12 {
            y1 = y0 + 1.0;
        }
        let pad = 0.05 * (x1 - x0);
        let (x0, x1) = (x0 - pad, x1 + pad);
        let y1 = y1 + 0.08 * (y1 - y0);
        let pw = W as i32 - LEFT - RIGHT;
        let ph = H as i32 - TOP - BOTTOM;
        let px = |x: f32| LEFT + ((fx(x) - x0) / (x1 - x0) * pw as f32).round() as i32;
        let py = |y: f32| TOP + ph - ((fy(y) - y0) / (y1 - y0) * ph as f32).round() as i32;
        let grey = [90, 90, 96];
        let white = [220, 220, 220];
        // Axes and ticks.
        line(&mut img, LEFT, TOP, LEFT, TOP + ph, white);
        line(&mut img, LEFT, TOP + ph, LEFT + pw, TOP + ph, white);
        let mut xs: Vec<f32> = pts().map(|p| p.0).collect();
        xs.sort_by(f32::total_cmp);
        xs.dedup();
        if xs.len() > 12 {
            // Too many points to label each (curves against time): five
            // evenly spaced ticks instead, as on the y axis.
            xs = (0..=4)
                .map(|k| {
                    let v = x0 + pad + (x1 - x0 - 2.0 * pad) * k as f32 / 4.0;
                    if self.log_x {
                        10f32.powf(v)
                    } else {
                        v
                    }
                })
                .collect();
        }
        for &x in &xs {
            let tx = px(x);
            line(&mut img, tx, TOP + ph, tx, TOP + ph + 4, white);
            let label = short(x);
            text(
                &mut img,
                tx - text_width(&label) / 2,
                TOP + ph + 8,
                &label,
                white,
            );
        }
        for k in 0..=4 {
            let v = y0 + (y1 - y0) * k as f32 / 4.0;
            let y = if self.log_y { 10f32.powf(v) } else { v };
            let ty = py(y);
            line(&mut img, LEFT - 4, ty, LEFT, ty, white);
            if k > 0 {
                line(&mut img, LEFT + 1, ty, LEFT + pw, ty, grey);
            }
            let label = short(y);
            text(
                &mut img,
                LEFT - 8 - text_width(&label),
                ty - 5,
                &label,
                white,
            );
        }
        text(&mut img, LEFT, 10, &self.title, white);
        let xl = &self.x_label;
        text(
            &mut img,
            LEFT + pw / 2 - text_width(xl) / 2,
            H as i32 - 18,
            xl,
            white,
        );
        text(&mut img, 6, TOP - 16, &self.y_label, white);
        // Series and legend.
        for (n, s) in self.series.iter().enumerate() {
            let c = [
                (s.colour[0].clamp(0.0, 1.0) * 255.0) as u8,
                (s.colour[1].clamp(0.0, 1.0) * 255.0) as u8,
                (s.colour[2].clamp(0.0, 1.0) * 255.0) as u8,
            ];
            let mut last: Option<(i32, i32)> = None;
            for &(x, y) in &s.points {
                if !(x.is_finite() && y.is_finite())
                    || (self.log_x && x <= 0.0)
                    || (self.log_y && y <= 0.0)
                {
                    continue;
                }
                let p = (px(x), py(y));
                if let Some(q) = last {
                    line(&mut img, q.0, q.1, p.0, p.1, c);
                }
                for d in -2..=2 {
                    line(&mut img, p.0 - 2, p.1 + d, p.0 + 2, p.1 + d, c);
                }
                last = Some(p);
            }
            let ly = TOP + 6 + 14 * n as i32;
            let lx = LEFT + pw - 150;
            line(&mut img, lx, ly + 4, lx + 18, ly + 4, c);
            text(&mut img, lx + 24, ly, &s.name, c);
        }
        img
    }

    /// Writes the plot as a PNG file (whole or not at all).
    pub fn save(&self, path: &Path) -> Result<()> {
        let img = self.render();
        super::export::write_png_bytes(
            path,
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .context("cannot write the plot")
    }
}

/// A compact number label: up to three significant digits.
fn short(v: f32) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

fn put(img: &mut image::RgbImage, x: i32, y: i32, c: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, image::Rgb(c));
    }
}

/// Bresenham's line.
fn line(img: &mut image::RgbImage, x0: i32, y0: i32, x1: i32, y1: i32, c: [u8; 3]) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        put(img, x, y, c);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

/// The 3×5 glyph of `ch` as 15 bits, row by row from the top, most
/// significant bit first (unknown characters are blank).
fn glyph(ch: char) -> u16 {
    let rows: [u8; 5] = match ch.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '*' => [0, 5, 2, 5, 0],
        '%' => [5, 1, 2, 4, 5],
        '|' => [2, 2, 2, 2, 2],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '/' => [1, 1, 2, 4, 4],
        '=' => [0, 7, 0, 7, 0],
        '²' => [6, 2, 4, 6, 0],
        _ => [0; 5],
    };
    rows.iter().fold(0u16, |acc, &r| (acc << 3) | r as u16)
}

fn text_width(s: &str) -> i32 {
    s.chars().count() as i32 * 4 * SCALE
}

/// Draws `s` with its top-left corner at `(x, y)`.
fn text(img: &mut image::RgbImage, x: i32, y: i32, s: &str, c: [u8; 3]) {
    for (n, ch) in s.chars().enumerate() {
        let bits = glyph(ch);
        let ox = x + n as i32 * 4 * SCALE;
        for row in 0..5 {
            for col in 0..3 {
                if bits >> (14 - (row * 3 + col)) & 1 == 1 {
                    for dy in 0..SCALE {
                        for dx in 0..SCALE {
                            put(img, ox + col * SCALE + dx, y + row * SCALE + dy, c);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_draws_series_in_their_colours() {
        let mut p = Plot::new("test", "x", "y", true);
        p.add(Series::new(
            "a",
            [1.0, 0.0, 0.0],
            vec![(1.0, 1.0), (10.0, 3.0), (100.0, 2.0)],
        ));
        let img = p.render();
        let red = img.pixels().filter(|px| px.0 == [255, 0, 0]).count();
        assert!(red > 200, "{red} red pixels");
        // Every glyph used by the labels is defined (non-blank).
        for ch in "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.-+*%=".chars() {
            assert_ne!(glyph(ch), 0, "{ch}");
        }
    }
}
