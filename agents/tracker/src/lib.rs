//! The image tracker of the thesis (section 4.2.2.3) as a library: find the
//! largest red area of a binary mask and its centre ([`largest_blob`]),
//! then steer the head and the foot toward it ([`steer`]).
//!
//! **Blob.** The mask is `gray8`, row-major, a pixel is set when ≥ 128. The
//! blobs are its 4-connected components (a scan-line flood fill with an
//! explicit stack: no recursion, no allocation per pixel once the buffers
//! have grown to the image size); the largest wins, ties to the first met
//! in raster order. Its centre is the mean of its pixels.
//!
//! **Control** ("if the centre of the object is far from the centre of the
//! image, the robot moves its head and the foot to locate the object to the
//! centre; if the area is small, the robot will try to come closer"):
//!
//! * the target's offset from the image centre, `ex, ey` in -1 … 1 (right
//!   and down positive), is an angle `ex × hfov/2`, `ey × vfov/2`;
//! * the **head** moves a fraction `k_head` of that angle per frame (pan
//!   positive left, tilt positive up), within the head's limits;
//! * the target's **bearing** from the body is `pan - ex × hfov/2`; the
//!   **foot** turns toward it, `ω = k_turn × bearing`, so that the body
//!   follows the head and the head comes back to the middle;
//! * the **speed** is `v_max × (1 - size / close_size)` while the target is
//!   smaller than `close_size` (a fraction of the image), reduced while the
//!   target is off to the side; 0 once it is close — the tracker stops the
//!   robot in front of the target (and keeps turning to face it);
//! * **close** has hysteresis: a target becomes close at `close_size` and
//!   stays close until it shrinks under `release × close_size` (it steps
//!   back), so that the state does not flicker at the threshold while the
//!   robot stands in front of it. With the H1 camera (60° wide, 1 m high)
//!   and the red jersey of the worlds (radius 0.24 m, 0.4 m tall) a size of
//!   0.15 is about 1.2 m centre to centre, 0.12 about 1.4 m.

use shm_schemas::payloads::TargetState;

/// A blob of set pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    /// Pixels in the blob.
    pub area: usize,
    /// Centre, x (pixels from the left).
    pub cx: f32,
    /// Centre, y (pixels from the top).
    pub cy: f32,
    /// Bounding box: left, top, right, bottom (inclusive).
    pub bbox: (usize, usize, usize, usize),
}

/// Buffers reused from frame to frame.
#[derive(Debug, Default, Clone)]
pub struct BlobFinder {
    seen: Vec<bool>,
    stack: Vec<(usize, usize)>,
}

/// Why a mask cannot be searched.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MaskError {
    /// The buffer is smaller than the geometry says.
    #[error(
        "mask of {width}x{height} needs {need} bytes, the frame has {got}; is the input a gray8 mask (the image agent's `red`)?"
    )]
    TooShort {
        /// width
        width: usize,
        /// height
        height: usize,
        /// bytes needed
        need: usize,
        /// bytes there
        got: usize,
    },
    /// A zero dimension.
    #[error("mask of {width}x{height}: empty image")]
    Empty {
        /// width
        width: usize,
        /// height
        height: usize,
    },
}

impl BlobFinder {
    /// The largest 4-connected blob of `mask` (`width × height` bytes, set ≥ 128).
    pub fn largest_blob(&mut self, mask: &[u8], width: usize, height: usize) -> Result<Option<Blob>, MaskError> {
        if width == 0 || height == 0 {
            return Err(MaskError::Empty { width, height });
        }
        let need = width * height;
        if mask.len() < need {
            return Err(MaskError::TooShort { width, height, need, got: mask.len() });
        }
        let set = |i: usize| mask[i] >= 128;
        self.seen.clear();
        self.seen.resize(need, false);
        let mut best: Option<Blob> = None;
        for start in 0..need {
            if self.seen[start] || !set(start) {
                continue;
            }
            // flood fill from `start`
            let (mut area, mut sx, mut sy) = (0usize, 0u64, 0u64);
            let (mut l, mut t, mut r, mut b) = (usize::MAX, usize::MAX, 0usize, 0usize);
            self.seen[start] = true;
            self.stack.clear();
            self.stack.push((start % width, start / width));
            while let Some((x, y)) = self.stack.pop() {
                area += 1;
                sx += x as u64;
                sy += y as u64;
                (l, t, r, b) = (l.min(x), t.min(y), r.max(x), b.max(y));
                let mut visit = |nx: usize, ny: usize, stack: &mut Vec<(usize, usize)>| {
                    let i = ny * width + nx;
                    if !self.seen[i] && set(i) {
                        self.seen[i] = true;
                        stack.push((nx, ny));
                    }
                };
                if x > 0 {
                    visit(x - 1, y, &mut self.stack);
                }
                if x + 1 < width {
                    visit(x + 1, y, &mut self.stack);
                }
                if y > 0 {
                    visit(x, y - 1, &mut self.stack);
                }
                if y + 1 < height {
                    visit(x, y + 1, &mut self.stack);
                }
            }
            if best.is_none_or(|bb| area > bb.area) {
                best =
                    Some(Blob { area, cx: sx as f32 / area as f32, cy: sy as f32 / area as f32, bbox: (l, t, r, b) });
            }
        }
        Ok(best)
    }
}

/// The tracker's settings (its run-time parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Blobs smaller than this many pixels are noise.
    pub min_area: usize,
    /// Target size (fraction of the image) at which it is close: stop.
    pub close_size: f32,
    /// A close target stays close until its size falls under `release × close_size`.
    pub release: f32,
    /// Speed toward a far target, m/s.
    pub v_max: f32,
    /// Head gain: fraction of the offset angle corrected per frame.
    pub k_head: f32,
    /// Foot gain: ω per radian of bearing, 1/s.
    pub k_turn: f32,
    /// Largest turn rate, rad/s.
    pub omega_max: f32,
    /// Camera's horizontal field of view, rad.
    pub hfov: f32,
    /// Camera's vertical field of view, rad.
    pub vfov: f32,
    /// Head pan limit, rad (±).
    pub pan_max: f32,
    /// Head tilt limit, rad (±).
    pub tilt_max: f32,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            min_area: 30,
            close_size: 0.15,
            release: 0.8,
            v_max: 0.3,
            k_head: 0.5,
            k_turn: 1.2,
            omega_max: 1.0,
            hfov: 60f32.to_radians(),
            vfov: 45f32.to_radians(),
            pan_max: 100f32.to_radians(),
            tilt_max: 30f32.to_radians(),
        }
    }
}

/// What to do for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steer {
    /// What the tracker sees.
    pub state: TargetState,
    /// Target area, fraction of the image.
    pub size: f32,
    /// Target bearing from the body, rad, positive left.
    pub bearing: f32,
    /// Head set-point: pan, rad.
    pub pan: f32,
    /// Head set-point: tilt, rad.
    pub tilt: f32,
    /// Forward speed, m/s.
    pub v: f32,
    /// Turn rate, rad/s.
    pub omega: f32,
}

/// Steers toward `blob` (if any) in a `width × height` image, the head being
/// at `(pan, tilt)`; `was_close` says whether the target was close at the
/// previous frame (the hysteresis of `close`).
pub fn steer(
    blob: Option<&Blob>,
    width: usize,
    height: usize,
    pan: f32,
    tilt: f32,
    was_close: bool,
    s: &Settings,
) -> Steer {
    let Some(b) = blob.filter(|b| b.area >= s.min_area.max(1)) else {
        return Steer { state: TargetState::None, size: 0.0, bearing: 0.0, pan, tilt, v: 0.0, omega: 0.0 };
    };
    let (w, h) = (width.max(1) as f32, height.max(1) as f32);
    let ex = ((b.cx + 0.5) - w / 2.0) / (w / 2.0);
    let ey = ((b.cy + 0.5) - h / 2.0) / (h / 2.0);
    let ax = ex * s.hfov / 2.0;
    let ay = ey * s.vfov / 2.0;
    let size = b.area as f32 / (w * h);
    let bearing = pan - ax;
    let new_pan = (pan - s.k_head * ax).clamp(-s.pan_max, s.pan_max);
    let new_tilt = (tilt - s.k_head * ay).clamp(-s.tilt_max, s.tilt_max);
    let omega = (s.k_turn * bearing).clamp(-s.omega_max, s.omega_max);
    let close = size >= s.close_size || (was_close && size >= s.release.clamp(0.0, 1.0) * s.close_size);
    let v = if close {
        0.0
    } else {
        let facing = (1.0 - bearing.abs() / 0.8).clamp(0.0, 1.0);
        s.v_max * (1.0 - size / s.close_size) * facing
    };
    Steer {
        state: if close { TargetState::Close } else { TargetState::Seen },
        size,
        bearing,
        pan: new_pan,
        tilt: new_tilt,
        v,
        omega,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(w: usize, h: usize, rects: &[(usize, usize, usize, usize)]) -> Vec<u8> {
        let mut m = vec![0u8; w * h];
        for &(x0, y0, x1, y1) in rects {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    m[y * w + x] = 255;
                }
            }
        }
        m
    }

    #[test]
    fn finds_the_largest_blob_and_its_centre() {
        let (w, h) = (320, 240);
        // a small blob, a large one, and noise; 4-connectivity keeps the diagonal pixel apart
        let mut m = mask(w, h, &[(10, 10, 19, 19), (200, 100, 239, 139), (300, 5, 300, 5)]);
        m[(140) * w + 240] = 255; // touches the large blob only by a corner
        let mut f = BlobFinder::default();
        let b = f.largest_blob(&m, w, h).expect("valid").expect("a blob");
        assert_eq!(b.area, 40 * 40);
        assert_eq!((b.cx, b.cy), (219.5, 119.5));
        assert_eq!(b.bbox, (200, 100, 239, 139));
        // an L-shaped blob is one blob
        let m = mask(w, h, &[(0, 0, 49, 4), (0, 0, 4, 49)]);
        assert_eq!(f.largest_blob(&m, w, h).expect("valid").map(|b| b.area), Some(50 * 5 * 2 - 25));
        // nothing set
        assert_eq!(f.largest_blob(&vec![0; w * h], w, h).expect("valid"), None);
        // grey values below 128 are not set
        assert_eq!(f.largest_blob(&vec![127; w * h], w, h).expect("valid"), None);
        assert!(f.largest_blob(&[0; 10], w, h).is_err());
        assert!(f.largest_blob(&[], 0, 0).is_err());
    }

    #[test]
    fn whole_image_blob_does_not_overflow_the_stack() {
        let (w, h) = (320, 240);
        let mut f = BlobFinder::default();
        let b = f.largest_blob(&vec![255; w * h], w, h).expect("valid").expect("blob");
        assert_eq!(b.area, w * h);
    }

    #[test]
    fn steers_head_then_foot_comes_closer_and_stops_when_close() {
        let s = Settings::default();
        let blob = |cx: f32, area: usize| Blob { area, cx, cy: 119.5, bbox: (0, 0, 0, 0) };
        // target to the right, small: head pans right, foot turns right, goes forward
        let st = steer(Some(&blob(279.5, 400)), 320, 240, 0.0, 0.0, false, &s);
        assert_eq!(st.state, TargetState::Seen);
        assert!(st.pan < 0.0 && st.omega < 0.0 && st.bearing < 0.0, "{st:?}");
        assert!(st.v > 0.0 && st.v < s.v_max, "{st:?}");
        assert!(st.tilt.abs() < 1e-6);
        // centred in the image but the head looks left: the body turns left to follow the head
        let st = steer(Some(&blob(159.5, 400)), 320, 240, 0.5, 0.0, false, &s);
        assert!((st.bearing - 0.5).abs() < 1e-6 && st.omega > 0.0 && (st.pan - 0.5).abs() < 1e-6);
        // straight ahead and large: close, stop
        let st = steer(Some(&blob(159.5, 320 * 240 / 5)), 320, 240, 0.0, 0.0, false, &s);
        assert_eq!((st.state, st.v), (TargetState::Close, 0.0));
        // noise and nothing: no target, no motion, head stays
        let st = steer(Some(&blob(10.0, 5)), 320, 240, 0.2, 0.1, true, &s);
        assert_eq!((st.state, st.v, st.omega, st.pan, st.tilt), (TargetState::None, 0.0, 0.0, 0.2, 0.1));
        // head limits hold
        let st = steer(Some(&blob(0.0, 400)), 320, 240, s.pan_max, 0.0, false, &s);
        assert!(st.pan <= s.pan_max);
    }

    #[test]
    fn close_holds_until_the_target_steps_back() {
        let s = Settings::default();
        let px = |frac: f32| (frac * 320.0 * 240.0) as usize;
        let blob = |area: usize| Blob { area, cx: 159.5, cy: 119.5, bbox: (0, 0, 0, 0) };
        // just under close_size: seen, and barely moving
        let st = steer(Some(&blob(px(0.14))), 320, 240, 0.0, 0.0, false, &s);
        assert_eq!(st.state, TargetState::Seen);
        assert!(st.v > 0.0 && st.v < 0.1 * s.v_max, "{st:?}");
        // the same size after it was close: still close, no motion forward
        let st = steer(Some(&blob(px(0.14))), 320, 240, 0.0, 0.0, true, &s);
        assert_eq!((st.state, st.v), (TargetState::Close, 0.0));
        // it stepped back under release × close_size: seen again, the robot follows
        let st = steer(Some(&blob(px(0.11))), 320, 240, 0.0, 0.0, true, &s);
        assert_eq!(st.state, TargetState::Seen);
        assert!(st.v > 0.0, "{st:?}");
    }
}
