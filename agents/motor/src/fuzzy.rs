//! Fuzzy sets for the linguistic rule bases: triangular memberships, rule
//! consequents clipped at the rule's firing strength (Mamdani `min`
//! implication), scaled by the sender's weight, aggregated by **sum**, and
//! defuzzified by the **centroid** over the output universe (sampled at
//! [`SAMPLES`] points).
//!
//! For symmetric triangles that lie inside the universe this is the
//! weighted "centre of sums": each rule pulls towards its triangle's centre
//! with the area of its clipped, weighted set, `w · h · μ · (2 - μ)` for a
//! triangle of half-width `h` clipped at `μ`.

/// Points at which the output universe is sampled.
pub const SAMPLES: usize = 2001;

/// A triangular membership function, symmetric around `center`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    /// Peak (membership 1).
    pub center: f64,
    /// Distance from the peak to where the membership reaches 0.
    pub half_width: f64,
}

impl Triangle {
    /// A triangle peaking at `center`, zero beyond `± half_width`.
    pub fn new(center: f64, half_width: f64) -> Self {
        Triangle { center, half_width: half_width.abs().max(1e-9) }
    }

    /// The membership of `x`, 0 … 1.
    pub fn membership(&self, x: f64) -> f64 {
        (1.0 - (x - self.center).abs() / self.half_width).max(0.0)
    }
}

/// One fired rule: its consequent set, firing strength and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fired {
    /// The consequent's membership function.
    pub set: Triangle,
    /// Firing strength (the command's intensity), 0 … 1.
    pub strength: f64,
    /// The sender's weight, ≥ 0.
    pub weight: f64,
}

/// Defuzzifies the sum of the clipped, weighted consequents over
/// `[lo, hi]` by centroid; `None` when nothing fired with a positive mass.
pub fn centroid(lo: f64, hi: f64, fired: &[Fired]) -> Option<f64> {
    if fired.is_empty() || hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..SAMPLES {
        let x = lo + (hi - lo) * k as f64 / (SAMPLES - 1) as f64;
        let mu: f64 =
            fired.iter().map(|f| f.weight.max(0.0) * f.set.membership(x).min(f.strength.clamp(0.0, 1.0))).sum();
        num += mu * x;
        den += mu;
    }
    (den > 1e-12).then(|| num / den)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn membership_shape() {
        let t = Triangle::new(0.5, 0.25);
        assert_eq!(t.membership(0.5), 1.0);
        assert!((t.membership(0.625) - 0.5).abs() < 1e-12);
        assert_eq!(t.membership(0.8), 0.0);
    }

    #[test]
    fn centroid_is_centre_of_sums() {
        let a = Fired { set: Triangle::new(0.6, 0.3), strength: 1.0, weight: 1.0 };
        let b = Fired { set: Triangle::new(-0.2, 0.2), strength: 0.5, weight: 2.0 };
        let area = |f: &Fired| f.weight * f.set.half_width * f.strength * (2.0 - f.strength);
        let expect = (area(&a) * 0.6 + area(&b) * -0.2) / (area(&a) + area(&b));
        let got = centroid(-1.0, 1.0, &[a, b]).expect("fired");
        assert!((got - expect).abs() < 1e-3, "{got} vs {expect}");
        assert_eq!(centroid(-1.0, 1.0, &[]), None);
        assert_eq!(centroid(-1.0, 1.0, &[Fired { weight: 0.0, ..a }]), None);
    }
}
