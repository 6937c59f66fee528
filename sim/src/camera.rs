//! The webcam: a column ray-caster rendering 320x240 RGB frames.
//!
//! For each image column one ray is cast from the camera (robot centre,
//! `camera_height` above the floor) at the column's angle, rotated by the
//! head's pan. Every surface the ray crosses (walls, box sides, checkpoint
//! tubes and their stands, coloured objects) is drawn far-to-near over the
//! rows its height covers, so a low box in front of a wall hides only the
//! wall's lower part. Walls are grey with panel seams every 0.6 m and a dark
//! skirting board; the floor is a 0.5 m checker; the ceiling a flat light
//! grey. Colours are shaded by distance and angle only (uniformly over the
//! channels), so a red object stays red. Tilt shifts the horizon (a
//! small-angle approximation). Pixels are written row-major, top row first,
//! 3 bytes R, G, B, straight into the caller's buffer, which may be a
//! shared-memory slot.
//!
//! Every robot has its camera ([`RobotRef::render_camera`]); it sees the
//! other robots as cylinders in their body colour, never itself.
//!
//! A checkpoint tube is two stacked colour bands of equal height; the
//! renderer projects each band with the pinhole model (focal length
//! `f = (width / 2) / tan(hfov / 2)` pixels, about 277 for 60°) onto whole
//! rows, so the pixel distance between the band centres is `f·D / Z` (`D`
//! the distance between the band centres, `Z` the depth of the tube's
//! front surface) to within a pixel.

use crate::geom::Vec2;
use crate::sim::{RobotId, RobotRef, SimError, Simulation, ray_hit};

/// Frame width, pixels.
pub const CAMERA_WIDTH: usize = 320;
/// Frame height, pixels.
pub const CAMERA_HEIGHT: usize = 240;
/// Bytes of one RGB frame.
pub const CAMERA_FRAME_BYTES: usize = CAMERA_WIDTH * CAMERA_HEIGHT * 3;

const CEILING: [u8; 3] = [205, 205, 210];
const FLOOR_A: [u8; 3] = [125, 112, 95];
const FLOOR_B: [u8; 3] = [105, 94, 80];

fn shade(c: [u8; 3], k: f64) -> [u8; 3] {
    let k = k.clamp(0.0, 1.0);
    [(f64::from(c[0]) * k).round() as u8, (f64::from(c[1]) * k).round() as u8, (f64::from(c[2]) * k).round() as u8]
}

/// Focal length of a camera with horizontal field of view `hfov` (radians)
/// in pixels of the simulator's frames.
pub fn focal_length_px(hfov: f64) -> f64 {
    (CAMERA_WIDTH as f64 / 2.0) / (hfov / 2.0).tan()
}

impl Simulation {
    /// Renders what the first robot's camera sees now into `out` (exactly
    /// [`CAMERA_FRAME_BYTES`] bytes, RGB24, top row first).
    pub fn render_camera(&self, out: &mut [u8]) -> Result<(), SimError> {
        self.robot(RobotId::FIRST).render_camera(out)
    }
}

impl RobotRef<'_> {
    /// Renders what this robot's camera sees now into `out` (exactly
    /// [`CAMERA_FRAME_BYTES`] bytes, RGB24, top row first).
    pub fn render_camera(&self, out: &mut [u8]) -> Result<(), SimError> {
        if out.len() != CAMERA_FRAME_BYTES {
            return Err(SimError::CameraBuffer {
                expected: CAMERA_FRAME_BYTES,
                got: out.len(),
                width: CAMERA_WIDTH,
                height: CAMERA_HEIGHT,
            });
        }
        let (w, h) = (CAMERA_WIDTH as f64, CAMERA_HEIGHT as f64);
        let r = self.r();
        let cam = Vec2::new(r.pose.x, r.pose.y);
        let cam_h = r.model.camera_height;
        let yaw = r.pose.theta + r.head.0;
        let f = focal_length_px(r.model.camera_hfov);
        let horizon = h / 2.0 + f * r.head.1.tan();
        let surfaces = self.sim.surfaces(Some(self.i));
        let mut hits = Vec::with_capacity(surfaces.len());

        for col in 0..CAMERA_WIDTH {
            let alpha = ((w / 2.0 - (col as f64 + 0.5)) / f).atan();
            let cos_a = alpha.cos();
            let dir = Vec2::from_angle(yaw + alpha);
            let put = |row: usize, c: [u8; 3], out: &mut [u8]| {
                let i = (row * CAMERA_WIDTH + col) * 3;
                out[i..i + 3].copy_from_slice(&c);
            };

            // Background: ceiling above the horizon, checkered floor below.
            for row in 0..CAMERA_HEIGHT {
                let yr = row as f64 + 0.5;
                let c = if yr <= horizon {
                    shade(CEILING, 0.85 + 0.15 * (yr / horizon.max(1.0)))
                } else {
                    let dp = cam_h * f / (yr - horizon);
                    let p = cam + dir * (dp / cos_a);
                    let tile = ((p.x / 0.5).floor() + (p.y / 0.5).floor()) as i64 & 1;
                    let base = if tile == 0 { FLOOR_A } else { FLOOR_B };
                    shade(base, 1.0 / (1.0 + 0.05 * dp))
                };
                put(row, c, out);
            }

            // Surfaces, far to near.
            hits.clear();
            hits.extend(surfaces.iter().filter_map(|s| ray_hit(cam, dir, &s.shape).map(|hit| (hit, s))));
            hits.sort_by(|a, b| b.0.dist.total_cmp(&a.0.dist));
            for (hit, s) in &hits {
                let dp = (hit.dist * cos_a).max(1e-3);
                let top = horizon - f * (s.z[1] - cam_h) / dp;
                let bottom = horizon - f * (s.z[0] - cam_h) / dp;
                let r0 = top.max(0.0).round() as usize;
                let r1 = (bottom.min(h).round().max(0.0) as usize).min(CAMERA_HEIGHT);
                let light = (0.55 + 0.45 * dir.dot(hit.normal).abs()) / (1.0 + 0.08 * hit.dist);
                for row in r0..r1 {
                    let mut k = light;
                    if s.textured {
                        let z = cam_h + (horizon - (row as f64 + 0.5)) * dp / f;
                        if (hit.u / 0.6).fract() < 0.03 {
                            k *= 0.7; // panel seam
                        }
                        if z < 0.1 {
                            k *= 0.5; // skirting board
                        }
                    }
                    put(row, shade(s.color, k), out);
                }
            }
        }
        Ok(())
    }
}
