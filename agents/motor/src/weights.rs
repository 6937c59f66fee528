//! Per-sender weights of the fusion.
//!
//! Written as text (the agent's `weights` parameter, changeable at run time
//! with `nerve param set motor weights safety:2,wall-follow:1`): a
//! comma-separated list of `sender:weight`. Senders not listed get the
//! default weight (parameter `default_weight`, 1.0). A weight is a finite
//! number ≥ 0; 0 silences a sender without disconnecting it.

use std::collections::BTreeMap;

/// Weights by sender name.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Weights {
    map: BTreeMap<String, f64>,
}

impl Weights {
    /// Parses `name:weight,name:weight` (blanks ignored; empty = no entries).
    pub fn parse(text: &str) -> Result<Weights, String> {
        let mut map = BTreeMap::new();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, w) = item
                .split_once(':')
                .or_else(|| item.split_once('='))
                .ok_or_else(|| format!("{item:?}: write SENDER:WEIGHT, e.g. `safety:2,wall-follow:1`"))?;
            let name = name.trim();
            if name.is_empty() {
                return Err(format!("{item:?}: the sender name is empty"));
            }
            let w: f64 = w.trim().parse().map_err(|_| format!("{item:?}: {:?} is not a number", w.trim()))?;
            if !w.is_finite() || w < 0.0 {
                return Err(format!("{item:?}: a weight must be a finite number >= 0"));
            }
            map.insert(name.to_owned(), w);
        }
        Ok(Weights { map })
    }

    /// The weight of `sender`, or `default` when it is not listed.
    pub fn of(&self, sender: &str, default: f64) -> f64 {
        self.map.get(sender).copied().unwrap_or(default)
    }

    /// Sets one sender's weight.
    pub fn set(&mut self, sender: &str, w: f64) {
        self.map.insert(sender.to_owned(), w);
    }
}

impl std::fmt::Display for Weights {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let items: Vec<String> = self.map.iter().map(|(k, v)| format!("{k}:{v}")).collect();
        f.write_str(&items.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_default() {
        let w = Weights::parse(" safety:2, wall-follow = 0.5 ,").expect("valid");
        assert_eq!(w.of("safety", 1.0), 2.0);
        assert_eq!(w.of("wall-follow", 1.0), 0.5);
        assert_eq!(w.of("tracker", 1.0), 1.0);
        assert_eq!(w.to_string(), "safety:2,wall-follow:0.5");
        assert!(Weights::parse("safety").expect_err("no weight").contains("SENDER:WEIGHT"));
        assert!(Weights::parse("a:-1").is_err());
        assert!(Weights::parse("a:NaN").is_err());
        assert_eq!(Weights::parse("").expect("empty"), Weights::default());
    }
}
