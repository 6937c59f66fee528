//! RGB → HSI, and the red mask.
//!
//! HSI as in Gonzalez & Woods (the model the thesis' image agents use):
//!
//! * intensity `I = (R + G + B) / 3`;
//! * saturation `S = 1 − min(R, G, B) / I` (0 for black);
//! * hue `θ = acos(½((R−G) + (R−B)) / √((R−G)² + (R−B)(G−B)))`,
//!   `H = θ` if `B ≤ G`, else `360° − θ` (0 for greys, where it is undefined).
//!
//! Stored as `hsi8` (see `shm_schemas::ring::PixelFormat::Hsi8`): hue byte
//! `round(H · 256 / 360) mod 256`, saturation and intensity bytes
//! `round(255 · S)`, `round(255 · I / 255)`. `nerve mem dump` converts such
//! frames back to RGB for viewing.
//!
//! A pixel is **red** when its hue lies in `[hue_lo, hue_hi]` going through
//! 0° when `hue_lo > hue_hi` (default 350° to 10°), its saturation is at
//! least `sat_min` and its intensity at least `int_min` (fractions; dark and
//! washed-out pixels have unreliable hue).

/// The red-mask thresholds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RedThresholds {
    /// Lowest hue, degrees (350 by default).
    pub hue_lo: f32,
    /// Highest hue, degrees (10 by default); below `hue_lo` means the range wraps through 0°.
    pub hue_hi: f32,
    /// Least saturation, 0 to 1.
    pub sat_min: f32,
    /// Least intensity, 0 to 1.
    pub int_min: f32,
}

impl Default for RedThresholds {
    fn default() -> Self {
        RedThresholds { hue_lo: 350.0, hue_hi: 10.0, sat_min: 0.35, int_min: 0.08 }
    }
}

impl RedThresholds {
    /// Whether a pixel of hue `h` (degrees), saturation `s` and intensity `i` (0 to 1) is red.
    pub fn is_red(&self, h: f32, s: f32, i: f32) -> bool {
        let hue_ok = if self.hue_lo <= self.hue_hi {
            h >= self.hue_lo && h <= self.hue_hi
        } else {
            h >= self.hue_lo || h <= self.hue_hi
        };
        hue_ok && s >= self.sat_min && i >= self.int_min
    }
}

/// Hue (degrees, 0 to <360), saturation and intensity (0 to 1) of an RGB pixel.
pub fn rgb_to_hsi(r: u8, g: u8, b: u8) -> (f32, f32, f32) {
    let (rf, gf, bf) = (f32::from(r), f32::from(g), f32::from(b));
    let sum = rf + gf + bf;
    let i = sum / (3.0 * 255.0);
    if sum == 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let min = rf.min(gf).min(bf);
    let s = 1.0 - 3.0 * min / sum;
    let num = 0.5 * ((rf - gf) + (rf - bf));
    let den = ((rf - gf) * (rf - gf) + (rf - bf) * (gf - bf)).sqrt();
    if den == 0.0 {
        return (0.0, s.max(0.0), i); // grey: hue undefined
    }
    let theta = (num / den).clamp(-1.0, 1.0).acos().to_degrees();
    let h = if bf <= gf { theta } else { 360.0 - theta };
    (if h >= 360.0 { h - 360.0 } else { h }, s.clamp(0.0, 1.0), i)
}

/// The stored bytes of an HSI pixel.
pub fn hsi_bytes(h: f32, s: f32, i: f32) -> [u8; 3] {
    let hb = ((h * 256.0 / 360.0).round() as u32 % 256) as u8;
    [hb, (s * 255.0).round().clamp(0.0, 255.0) as u8, (i * 255.0).round().clamp(0.0, 255.0) as u8]
}

/// Converts packed RGB8 `rgb` into packed HSI8 `hsi` and the GRAY8 red mask
/// `mask` (255 red, 0 not) in one pass; returns the number of red pixels.
/// `hsi` and `mask` are resized to fit.
pub fn convert(rgb: &[u8], thr: &RedThresholds, hsi: &mut Vec<u8>, mask: &mut Vec<u8>) -> usize {
    let n = rgb.len() / 3;
    hsi.resize(n * 3, 0);
    mask.resize(n, 0);
    let mut red = 0;
    for ((px, out), m) in rgb.chunks_exact(3).zip(hsi.chunks_exact_mut(3)).zip(mask.iter_mut()) {
        let (h, s, i) = rgb_to_hsi(px[0], px[1], px[2]);
        out.copy_from_slice(&hsi_bytes(h, s, i));
        let is = thr.is_red(h, s, i);
        *m = if is { 255 } else { 0 };
        red += usize::from(is);
    }
    red
}

/// The largest 4-connected region of a mask: (area in pixels, centre x, centre y).
pub fn largest_blob(mask: &[u8], width: usize, height: usize) -> Option<(usize, f64, f64)> {
    if width == 0 || mask.len() < width * height {
        return None;
    }
    let mut seen = vec![false; width * height];
    let mut stack = Vec::new();
    let mut best: Option<(usize, f64, f64)> = None;
    for start in 0..width * height {
        if mask[start] == 0 || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut area, mut sx, mut sy) = (0usize, 0u64, 0u64);
        while let Some(p) = stack.pop() {
            let (x, y) = (p % width, p / width);
            area += 1;
            sx += x as u64;
            sy += y as u64;
            let mut visit = |q: usize| {
                if mask[q] != 0 && !seen[q] {
                    seen[q] = true;
                    stack.push(q);
                }
            };
            if x > 0 {
                visit(p - 1);
            }
            if x + 1 < width {
                visit(p + 1);
            }
            if y > 0 {
                visit(p - width);
            }
            if y + 1 < height {
                visit(p + width);
            }
        }
        if best.is_none_or(|(a, _, _)| area > a) {
            best = Some((area, sx as f64 / area as f64, sy as f64 / area as f64));
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn primaries_and_greys() {
        let (h, s, i) = rgb_to_hsi(255, 0, 0);
        assert!(close(h, 0.0, 0.01) && close(s, 1.0, 1e-6) && close(i, 1.0 / 3.0, 1e-6), "{h} {s} {i}");
        let (h, s, _) = rgb_to_hsi(0, 255, 0);
        assert!(close(h, 120.0, 0.01) && close(s, 1.0, 1e-6), "{h}");
        let (h, _, _) = rgb_to_hsi(0, 0, 255);
        assert!(close(h, 240.0, 0.01), "{h}");
        let (h, _, _) = rgb_to_hsi(255, 255, 0);
        assert!(close(h, 60.0, 0.01), "{h}");
        let (h, _, _) = rgb_to_hsi(255, 0, 255);
        assert!(close(h, 300.0, 0.01), "{h}");
        // greys: no saturation, intensity the level
        assert_eq!(rgb_to_hsi(0, 0, 0), (0.0, 0.0, 0.0));
        let (h, s, i) = rgb_to_hsi(128, 128, 128);
        assert!(h == 0.0 && close(s, 0.0, 1e-6) && close(i, 128.0 / 255.0, 1e-6));
        // a slightly bluish red lies just below 360°, a slightly greenish one just above 0°
        let (h, _, _) = rgb_to_hsi(220, 30, 40);
        assert!(h > 350.0 && h < 360.0, "{h}");
        let (h, _, _) = rgb_to_hsi(220, 40, 30);
        assert!(h > 0.0 && h < 10.0, "{h}");
    }

    #[test]
    fn bytes_round_trip_through_the_dump_conversion() {
        assert_eq!(hsi_bytes(0.0, 1.0, 1.0 / 3.0), [0, 255, 85]);
        assert_eq!(hsi_bytes(359.9, 0.0, 0.0)[0], 0, "hue wraps");
        assert_eq!(hsi_bytes(180.0, 0.5, 0.5), [128, 128, 128]);
        // what `nerve mem dump` shows for an HSI frame is the original colour
        for rgb in [[220u8, 30, 35], [30, 200, 60], [90, 100, 110], [250, 250, 250]] {
            let (h, s, i) = rgb_to_hsi(rgb[0], rgb[1], rgb[2]);
            let back = agent_sdk::memory::stm::hsi8_to_rgb8(&hsi_bytes(h, s, i));
            for c in 0..3 {
                assert!((i32::from(back[c]) - i32::from(rgb[c])).abs() <= 6, "{rgb:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn red_thresholds() {
        let t = RedThresholds::default();
        assert!(t.is_red(355.0, 0.8, 0.3));
        assert!(t.is_red(5.0, 0.8, 0.3));
        assert!(t.is_red(350.0, 0.35, 0.08), "bounds are inclusive");
        assert!(!t.is_red(20.0, 0.8, 0.3), "orange");
        assert!(!t.is_red(340.0, 0.8, 0.3), "magenta");
        assert!(!t.is_red(0.0, 0.2, 0.3), "washed out");
        assert!(!t.is_red(0.0, 0.8, 0.05), "too dark");
        // a range that does not wrap
        let t = RedThresholds { hue_lo: 100.0, hue_hi: 140.0, ..t };
        assert!(t.is_red(120.0, 0.8, 0.3) && !t.is_red(5.0, 0.8, 0.3));
    }

    #[test]
    fn mask_of_a_picture() {
        // 4x1: red, grey, dark red, green
        let rgb = [220, 30, 35, 128, 128, 128, 12, 1, 1, 20, 200, 40];
        let (mut hsi, mut mask) = (Vec::new(), Vec::new());
        let red = convert(&rgb, &RedThresholds::default(), &mut hsi, &mut mask);
        assert_eq!(mask, [255, 0, 0, 0]);
        assert_eq!(red, 1);
        assert_eq!(hsi.len(), 12);
    }

    #[test]
    fn largest_blob_centre() {
        let (w, h) = (8, 6);
        let mut m = vec![0u8; w * h];
        m[0] = 255; // a single pixel
        for y in 2..5 {
            for x in 3..7 {
                m[y * w + x] = 255; // 4x3 block centred on (4.5, 3)
            }
        }
        assert_eq!(largest_blob(&m, w, h), Some((12, 4.5, 3.0)));
        assert_eq!(largest_blob(&vec![0; w * h], w, h), None);
    }
}
