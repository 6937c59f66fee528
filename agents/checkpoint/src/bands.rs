//! Finding the two-colour tubes in a camera frame: the centres of the two
//! colour bands, their pixel distance `d` (the input of Appendix A), the
//! tube's column (its bearing) and which way up it stands (a checkpoint, or
//! the target upside down).
//!
//! Each pixel is classed by its HSI hue, saturation and intensity as the
//! upper colour, the lower colour or neither (frames are `rgb8` from a
//! camera, or `hsi8` from the image agent). Columns holding both colours
//! are grouped into runs (a gap of one column is bridged); a run with enough
//! pixels of each colour is a tube. The band centres are the mean rows of
//! each colour's pixels in the run, the tube's column the mean column of all
//! of them. A tube whose pixels touch the frame's border is marked
//! `clipped`: a band cut by the border has a biased centre, so its range is
//! not to be trusted.

/// The colours of the bands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BandColors {
    /// Hue of the upper band of a checkpoint, degrees.
    pub upper_hue_deg: f32,
    /// Hue of the lower band, degrees.
    pub lower_hue_deg: f32,
    /// Hue tolerance, degrees.
    pub hue_tol_deg: f32,
    /// Least saturation, 0 … 1.
    pub sat_min: f32,
    /// Least intensity, 0 … 1.
    pub int_min: f32,
}

impl Default for BandColors {
    fn default() -> Self {
        crate::config::TubeSection::default().colors()
    }
}

/// The pixel layout of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pixels {
    /// 3 bytes R, G, B.
    Rgb8,
    /// 3 bytes: hue × 256/360, saturation × 255, intensity × 255 (the image agent's `hsi`).
    Hsi8,
}

/// A tube found in a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tube {
    /// Centre column, pixels from the left edge (continuous: the first
    /// column spans 0 … 1).
    pub col: f32,
    /// Centre row of the band of the upper colour, pixels from the top.
    pub upper_row: f32,
    /// Centre row of the band of the lower colour.
    pub lower_row: f32,
    /// Pixel distance between the two band centres.
    pub d_px: f32,
    /// The upper colour is on top: a checkpoint. Otherwise the target.
    pub upright: bool,
    /// Pixels of the upper and the lower colour.
    pub pixels: (usize, usize),
    /// Some pixel touches the frame's border.
    pub clipped: bool,
}

/// Why a frame cannot be searched.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The buffer is smaller than the geometry says.
    #[error(
        "frame of {width}x{height} needs {need} bytes, it has {got}; connect `frames` to a camera's `frames` (rgb8) or the image agent's `hsi`"
    )]
    TooShort {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Bytes needed.
        need: usize,
        /// Bytes there.
        got: usize,
    },
    /// A zero dimension.
    #[error("frame of {width}x{height}: empty image")]
    Empty {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
}

const NONE: u8 = 0;
const UPPER: u8 = 1;
const LOWER: u8 = 2;

fn hue_dist(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// HSI of an RGB pixel: hue in degrees, saturation and intensity 0 … 1.
pub fn rgb_to_hsi(r: u8, g: u8, b: u8) -> (f32, f32, f32) {
    let (r, g, b) = (f32::from(r), f32::from(g), f32::from(b));
    let i = (r + g + b) / 3.0;
    if i <= 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let s = 1.0 - r.min(g).min(b) / i;
    let num = 0.5 * ((r - g) + (r - b));
    let den = ((r - g) * (r - g) + (r - b) * (g - b)).sqrt();
    let h = if den <= 1e-6 { 0.0 } else { (num / den).clamp(-1.0, 1.0).acos().to_degrees() };
    let h = if b > g { 360.0 - h } else { h };
    (h, s, i / 255.0)
}

impl BandColors {
    fn class(&self, h: f32, s: f32, i: f32) -> u8 {
        if s < self.sat_min || i < self.int_min {
            NONE
        } else if hue_dist(h, self.upper_hue_deg) <= self.hue_tol_deg {
            UPPER
        } else if hue_dist(h, self.lower_hue_deg) <= self.hue_tol_deg {
            LOWER
        } else {
            NONE
        }
    }
}

/// Buffers reused from frame to frame.
#[derive(Debug, Default, Clone)]
pub struct TubeFinder {
    class: Vec<u8>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Column {
    n: [usize; 2],
    row_sum: [f64; 2],
    border: bool,
}

impl TubeFinder {
    /// The tubes in a `width × height` frame of `format`, left to right;
    /// a run needs `min_pixels` of each colour to count.
    pub fn find(
        &mut self,
        px: &[u8],
        format: Pixels,
        width: usize,
        height: usize,
        colors: &BandColors,
        min_pixels: usize,
    ) -> Result<Vec<Tube>, FrameError> {
        if width == 0 || height == 0 {
            return Err(FrameError::Empty { width, height });
        }
        let need = width.checked_mul(height).and_then(|n| n.checked_mul(3)).unwrap_or(usize::MAX);
        if px.len() < need {
            return Err(FrameError::TooShort { width, height, need, got: px.len() });
        }
        self.class.clear();
        self.class.extend(px[..need].chunks_exact(3).map(|p| {
            let (h, s, i) = match format {
                Pixels::Rgb8 => rgb_to_hsi(p[0], p[1], p[2]),
                Pixels::Hsi8 => (f32::from(p[0]) * 360.0 / 256.0, f32::from(p[1]) / 255.0, f32::from(p[2]) / 255.0),
            };
            colors.class(h, s, i)
        }));
        let mut cols = vec![Column::default(); width];
        for y in 0..height {
            for (x, col) in cols.iter_mut().enumerate() {
                let c = self.class[y * width + x];
                if c == NONE {
                    continue;
                }
                let k = usize::from(c - 1);
                col.n[k] += 1;
                col.row_sum[k] += y as f64 + 0.5;
                if y == 0 || y + 1 == height || x == 0 || x + 1 == width {
                    col.border = true;
                }
            }
        }
        let active = |c: &Column| c.n[0] > 0 && c.n[1] > 0;
        let mut tubes = Vec::new();
        let mut x = 0;
        while x < width {
            if !active(&cols[x]) {
                x += 1;
                continue;
            }
            // a run of active columns, bridging single-column gaps
            let start = x;
            let mut end = x;
            let mut k = x + 1;
            while k < width {
                if active(&cols[k]) {
                    end = k;
                    k += 1;
                } else if k + 1 < width && active(&cols[k + 1]) {
                    k += 1;
                } else {
                    break;
                }
            }
            let mut n = [0usize; 2];
            let mut rs = [0f64; 2];
            let (mut cx, mut border) = (0f64, start == 0 || end + 1 == width);
            for (i, c) in cols.iter().enumerate().take(end + 1).skip(start) {
                for j in 0..2 {
                    n[j] += c.n[j];
                    rs[j] += c.row_sum[j];
                }
                cx += (i as f64 + 0.5) * (c.n[0] + c.n[1]) as f64;
                border |= c.border;
            }
            if n[0] >= min_pixels.max(1) && n[1] >= min_pixels.max(1) {
                let upper_row = (rs[0] / n[0] as f64) as f32;
                let lower_row = (rs[1] / n[1] as f64) as f32;
                tubes.push(Tube {
                    col: (cx / (n[0] + n[1]) as f64) as f32,
                    upper_row,
                    lower_row,
                    d_px: (lower_row - upper_row).abs(),
                    upright: upper_row < lower_row,
                    pixels: (n[0], n[1]),
                    clipped: border,
                });
            }
            x = end + 1;
        }
        Ok(tubes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const YELLOW: [u8; 3] = [230, 200, 20];
    const BLUE: [u8; 3] = [20, 70, 210];
    const WALL: [u8; 3] = [175, 175, 170];
    const BOX: [u8; 3] = [140, 100, 60];

    fn frame(w: usize, h: usize, rects: &[(usize, usize, usize, usize, [u8; 3])]) -> Vec<u8> {
        let mut f: Vec<u8> = std::iter::repeat_n(WALL, w * h).flatten().collect();
        for &(x0, y0, x1, y1, c) in rects {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    f[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&c);
                }
            }
        }
        f
    }

    #[test]
    fn colours_of_the_simulator_are_classed() {
        let c = BandColors::default();
        let cls = |p: [u8; 3]| {
            let (h, s, i) = rgb_to_hsi(p[0], p[1], p[2]);
            c.class(h, s, i)
        };
        assert_eq!(cls(YELLOW), UPPER);
        assert_eq!(cls(BLUE), LOWER);
        // shaded (darker) keeps its class
        assert_eq!(cls([115, 100, 10]), UPPER);
        for other in [WALL, BOX, [220, 30, 30], [125, 112, 95], [0, 0, 0]] {
            assert_eq!(cls(other), NONE, "{other:?}");
        }
    }

    #[test]
    fn finds_an_upright_tube_and_its_band_centres() {
        let (w, h) = (320, 240);
        // yellow rows 100..=119, blue rows 120..=139, columns 150..=159
        let f = frame(w, h, &[(150, 100, 159, 119, YELLOW), (150, 120, 159, 139, BLUE), (10, 200, 60, 230, BOX)]);
        let t = TubeFinder::default().find(&f, Pixels::Rgb8, w, h, &BandColors::default(), 20).unwrap();
        assert_eq!(t.len(), 1, "{t:?}");
        let t = t[0];
        assert!(t.upright && !t.clipped);
        assert_eq!((t.upper_row, t.lower_row, t.d_px, t.col), (110.0, 130.0, 20.0, 155.0));
        assert_eq!(t.pixels, (200, 200));
    }

    #[test]
    fn the_target_is_upside_down_and_two_tubes_are_two() {
        let (w, h) = (320, 240);
        let f = frame(
            w,
            h,
            &[
                (20, 90, 29, 109, BLUE),
                (20, 110, 29, 129, YELLOW),
                (200, 100, 207, 114, YELLOW),
                (200, 115, 207, 129, BLUE),
            ],
        );
        let t = TubeFinder::default().find(&f, Pixels::Rgb8, w, h, &BandColors::default(), 20).unwrap();
        assert_eq!(t.len(), 2, "{t:?}");
        assert!(!t[0].upright && t[1].upright);
        assert_eq!(t[0].d_px, 20.0);
        assert_eq!(t[1].d_px, 15.0);
    }

    #[test]
    fn clipped_tubes_are_marked_small_ones_dropped_and_hsi_frames_read() {
        let (w, h) = (320, 240);
        let f = frame(w, h, &[(100, 200, 109, 219, YELLOW), (100, 220, 109, 239, BLUE)]);
        let t = TubeFinder::default().find(&f, Pixels::Rgb8, w, h, &BandColors::default(), 20).unwrap();
        assert!(t[0].clipped);
        let f = frame(w, h, &[(100, 100, 101, 102, YELLOW), (100, 103, 101, 105, BLUE)]);
        assert!(TubeFinder::default().find(&f, Pixels::Rgb8, w, h, &BandColors::default(), 20).unwrap().is_empty());
        // an hsi8 frame: hue 52° and 225°, saturated, bright
        let mut f = vec![0u8; w * h * 3];
        for y in 100..140 {
            for x in 150..160 {
                let hue = if y < 120 { 52.0 } else { 225.0 };
                f[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&[(hue * 256.0 / 360.0) as u8, 220, 150]);
            }
        }
        let t = TubeFinder::default().find(&f, Pixels::Hsi8, w, h, &BandColors::default(), 20).unwrap();
        assert_eq!(t.len(), 1);
        assert_eq!(t[0].d_px, 20.0);
        assert!(TubeFinder::default().find(&f[..10], Pixels::Hsi8, w, h, &BandColors::default(), 20).is_err());
        assert!(TubeFinder::default().find(&[], Pixels::Hsi8, 0, 0, &BandColors::default(), 20).is_err());
    }
}
