//! 2-D geometry for the simulator: vectors, segments, and the ray and
//! distance queries the physics and sensors are built on.

use std::ops::{Add, Mul, Neg, Sub};

/// A point or vector in the plane, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
}

impl Vec2 {
    /// `(x, y)`.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }
    /// The unit vector at `angle` radians from +x.
    pub fn from_angle(angle: f64) -> Self {
        Self::new(angle.cos(), angle.sin())
    }
    /// Dot product.
    pub fn dot(self, o: Self) -> f64 {
        self.x * o.x + self.y * o.y
    }
    /// z of the cross product.
    pub fn cross(self, o: Self) -> f64 {
        self.x * o.y - self.y * o.x
    }
    /// Length.
    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }
    /// Distance to `o`.
    pub fn dist(self, o: Self) -> f64 {
        (self - o).norm()
    }
    /// Angle from +x, radians.
    pub fn angle(self) -> f64 {
        self.y.atan2(self.x)
    }
    /// Whether both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

impl Add for Vec2 {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y)
    }
}
impl Sub for Vec2 {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y)
    }
}
impl Mul<f64> for Vec2 {
    type Output = Self;
    fn mul(self, k: f64) -> Self {
        Self::new(self.x * k, self.y * k)
    }
}
impl Neg for Vec2 {
    type Output = Self;
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y)
    }
}

/// A line segment from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Start.
    pub a: Vec2,
    /// End.
    pub b: Vec2,
}

impl Segment {
    /// The segment `a`–`b`.
    pub const fn new(a: Vec2, b: Vec2) -> Self {
        Self { a, b }
    }
    /// Length, metres.
    pub fn len(&self) -> f64 {
        self.a.dist(self.b)
    }
    /// Whether the ends coincide.
    pub fn is_empty(&self) -> bool {
        self.len() == 0.0
    }
    /// Unit normal (left of a→b).
    pub fn normal(&self) -> Vec2 {
        let d = self.b - self.a;
        let n = d.norm();
        if n == 0.0 {
            return Vec2::new(0.0, 1.0);
        }
        Vec2::new(-d.y / n, d.x / n)
    }
    /// Distance from `p` to the closest point of the segment.
    pub fn distance_to(&self, p: Vec2) -> f64 {
        let d = self.b - self.a;
        let l2 = d.dot(d);
        let t = if l2 == 0.0 { 0.0 } else { ((p - self.a).dot(d) / l2).clamp(0.0, 1.0) };
        p.dist(self.a + d * t)
    }
}

/// Where a ray hits a segment: `(distance along the ray, position along the
/// segment in metres from a)`, if it does, in front of the origin.
pub fn ray_segment(origin: Vec2, dir: Vec2, seg: &Segment) -> Option<(f64, f64)> {
    let e = seg.b - seg.a;
    let denom = dir.cross(e);
    if denom.abs() < 1e-12 {
        return None;
    }
    let w = seg.a - origin;
    let t = w.cross(e) / denom;
    let u = w.cross(dir) / denom;
    (t > 1e-9 && (0.0..=1.0).contains(&u)).then(|| (t, u * e.norm()))
}

/// Distance along a unit ray to a circle's boundary, if the ray hits it in
/// front of the origin (from outside).
pub fn ray_circle(origin: Vec2, dir: Vec2, center: Vec2, radius: f64) -> Option<f64> {
    let oc = origin - center;
    let b = oc.dot(dir);
    let c = oc.dot(oc) - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 1e-9).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_hits() {
        let s = Segment::new(Vec2::new(2.0, -1.0), Vec2::new(2.0, 1.0));
        let (t, u) = ray_segment(Vec2::default(), Vec2::new(1.0, 0.0), &s).expect("hit");
        assert!((t - 2.0).abs() < 1e-12 && (u - 1.0).abs() < 1e-12);
        assert!(ray_segment(Vec2::default(), Vec2::new(-1.0, 0.0), &s).is_none());
        let t = ray_circle(Vec2::default(), Vec2::new(0.0, 1.0), Vec2::new(0.0, 3.0), 0.5);
        assert!((t.expect("hit") - 2.5).abs() < 1e-12);
        assert!((s.distance_to(Vec2::new(0.0, 3.0)) - 8f64.sqrt()).abs() < 1e-12);
    }
}
