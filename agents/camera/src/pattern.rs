//! The test pattern: a red disc moving over a textured, unsaturated
//! background, rendered straight into the ring slot. Deterministic: frame
//! `n` always looks the same (integer arithmetic only), so tests can predict
//! where the red object is.
//!
//! * background: grey-blue diagonal stripes 8 pixels wide with a darker
//!   checker of 40-pixel squares (texture for trackers, saturation below
//!   0.25, hue near 210°, so it never passes a red threshold);
//! * the disc: RGB (220, 30, 35), radius `height / 8`, its centre moving on a
//!   triangle wave, horizontally over 120 frames and vertically over 84, so
//!   that it covers the picture without leaving it.

/// Colour of the red disc.
pub const BLOB_RGB: [u8; 3] = [220, 30, 35];

/// Centre (x, y) and radius of the disc in frame `n` of a `width` x `height` picture.
pub fn blob(n: u64, width: u32, height: u32) -> (i64, i64, i64) {
    let (w, h) = (i64::from(width), i64::from(height));
    let r = (h / 8).max(1);
    // triangle wave from 0 to span and back over `period` frames
    let tri = |period: u64, span: i64| -> i64 {
        let half = period / 2;
        let p = n % period;
        let t = if p < half { p } else { period - p } as i64;
        span * t / half as i64
    };
    let x = r + tri(120, (w - 2 * r - 1).max(0));
    let y = r + tri(84, (h - 2 * r - 1).max(0));
    (x, y, r)
}

/// Renders frame `n` as packed RGB8 into `out` (`width * height * 3` bytes).
pub fn render(n: u64, width: u32, height: u32, out: &mut [u8]) {
    let (cx, cy, r) = blob(n, width, height);
    let w = width as usize;
    for (y, row) in out.chunks_exact_mut(w * 3).take(height as usize).enumerate() {
        let dy = y as i64 - cy;
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let dx = x as i64 - cx;
            let c = if dx * dx + dy * dy <= r * r {
                BLOB_RGB
            } else {
                let stripe = (x + y) / 8 % 2 == 0;
                let dark = (x / 40 + y / 40) % 2 == 0;
                let k = if dark { 20 } else { 0 };
                if stripe { [100 - k, 112 - k, 126 - k] } else { [132 - k, 142 - k, 152 - k] }
            };
            px.copy_from_slice(&c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_moving() {
        let (w, h) = (320u32, 240u32);
        let mut a = vec![0u8; (w * h * 3) as usize];
        let mut b = a.clone();
        render(5, w, h, &mut a);
        render(5, w, h, &mut b);
        assert_eq!(a, b);
        render(6, w, h, &mut b);
        assert_ne!(a, b, "the disc moves");
        assert_ne!(blob(0, w, h), blob(30, w, h));
    }

    #[test]
    fn disc_stays_inside_and_is_where_blob_says() {
        let (w, h) = (320u32, 240u32);
        let mut img = vec![0u8; (w * h * 3) as usize];
        for n in [0u64, 17, 60, 119, 1000] {
            let (x, y, r) = blob(n, w, h);
            assert!(x - r >= 0 && x + r < i64::from(w) && y - r >= 0 && y + r < i64::from(h), "frame {n}");
            render(n, w, h, &mut img);
            let i = (y as usize * w as usize + x as usize) * 3;
            assert_eq!(&img[i..i + 3], &BLOB_RGB);
            let reds = img.chunks_exact(3).filter(|p| *p == BLOB_RGB).count() as f64;
            let area = std::f64::consts::PI * (r * r) as f64;
            assert!((reds - area).abs() < area * 0.1, "{reds} vs {area}");
        }
    }
}
