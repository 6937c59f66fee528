//! Run-time parameters: declared by the agent with a type and a default,
//! read by the task through a [`Param`] handle, changed with
//! `nerve param set NAME KEY VALUE`. The message checker parses and checks a
//! new value with the parameter's type and answers at once; the task sees
//! the new value at its next read.
//!
//! An agent may also report **figures**: read-only values it computes itself
//! (the bridge's peers and per-topic counters, say). They are read with
//! `nerve param get` like parameters, refused by `nerve param set`, and
//! travel in the agent's statistics (`nerve ps --json`, field `figures`).

use shm_schemas::control::router_to_agent::ParamInfo;
use std::collections::BTreeMap;
use std::fmt::Display;
use std::str::FromStr;
use std::sync::{Arc, Mutex};

/// A typed parameter handle.
#[derive(Debug)]
pub struct Param<T> {
    value: Arc<Mutex<T>>,
}

impl<T> Clone for Param<T> {
    fn clone(&self) -> Self {
        Param { value: self.value.clone() }
    }
}

impl<T: Clone> Param<T> {
    /// The current value.
    pub fn get(&self) -> T {
        self.value.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Looks at the current value without copying it (a string parameter
    /// read every cycle, say, to see whether it changed).
    pub fn with<R>(&self, f: impl FnOnce(&T) -> R) -> R {
        f(&self.value.lock().unwrap_or_else(|p| p.into_inner()))
    }

    /// Changes the value from inside the agent.
    pub fn set(&self, v: T) {
        *self.value.lock().unwrap_or_else(|p| p.into_inner()) = v;
    }
}

/// A check on a new parameter value; the error says what is allowed.
pub type ParamCheck<T> = Box<dyn Fn(&T) -> Result<(), String> + Send + Sync>;

/// A check for `Setup::param_checked`: a finite number greater than 0
/// (distances, speeds, periods).
pub fn positive<T: Copy + Into<f64>>(v: &T) -> Result<(), String> {
    let x: f64 = (*v).into();
    if x.is_finite() && x > 0.0 { Ok(()) } else { Err("must be a number > 0".into()) }
}

/// A check for `Setup::param_checked`: a finite number in `(0, hi]`; the
/// refusal names the parameter, the range and the unit.
pub fn in_range_above_zero(key: &str, v: f32, hi: f32, unit: &str) -> Result<(), String> {
    if v.is_finite() && v > 0.0 && v <= hi {
        Ok(())
    } else {
        Err(format!("{key} is in (0, {hi}] {unit}").trim_end().to_owned())
    }
}

/// A check for `Setup::param_checked`: a whole number in `range`; the
/// refusal names the parameter, the range and the unit.
pub fn in_range(key: &str, v: u64, range: &std::ops::RangeInclusive<u64>, unit: &str) -> Result<(), String> {
    if range.contains(&v) {
        Ok(())
    } else {
        Err(format!("{key} is in [{}, {}] {unit}", range.start(), range.end()).trim_end().to_owned())
    }
}

/// Where checked parameters are declared: the agent's
/// [`crate::Setup`], or a bare [`ParamTable`] in a test, so that an agent's
/// test sees exactly the checks the agent declares.
pub trait Declare {
    /// Declares `key` with `default`, refusing values `check` refuses.
    fn checked<T>(&mut self, key: &str, default: T, check: fn(&T) -> Result<(), String>) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display;
}

impl Declare for ParamTable {
    fn checked<T>(&mut self, key: &str, default: T, check: fn(&T) -> Result<(), String>) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display,
    {
        self.declare(key, default, Some(Box::new(check)))
    }
}

trait DynParam: Send + Sync {
    fn get(&self) -> String;
    fn set(&self, s: &str) -> Result<(), String>;
    fn type_name(&self) -> &'static str;
    fn default(&self) -> &str;
    fn bounds(&self) -> Option<&str>;
}

struct Slot<T> {
    value: Arc<Mutex<T>>,
    check: Option<ParamCheck<T>>,
    default: String,
    /// What the check says when it refuses an out-of-range value.
    bounds: Option<String>,
}

/// Values a check is tried with, once, at declaration, to learn what it
/// allows: a check's refusal says what values must be ("gain is in (0, 5]").
/// Each is parsed with the parameter's type; those that do not parse are
/// skipped.
const BOUND_PROBES: [&str; 6] = ["-1", "0", "1e300", "18446744073709551615", "-9223372036854775808", "NaN"];

fn probe_bounds<T: FromStr>(check: &ParamCheck<T>) -> Option<String> {
    BOUND_PROBES.iter().filter_map(|p| p.parse::<T>().ok()).find_map(|v| check(&v).err())
}

impl<T> DynParam for Slot<T>
where
    T: FromStr + Display + Send + 'static,
    T::Err: Display,
{
    fn get(&self) -> String {
        self.value.lock().unwrap_or_else(|p| p.into_inner()).to_string()
    }

    fn set(&self, s: &str) -> Result<(), String> {
        let v: T = s.trim().parse().map_err(|e: T::Err| format!("{s:?} is not a valid {}: {e}", self.type_name()))?;
        if let Some(check) = &self.check {
            check(&v)?;
        }
        *self.value.lock().unwrap_or_else(|p| p.into_inner()) = v;
        Ok(())
    }

    fn type_name(&self) -> &'static str {
        short_type_name::<T>()
    }

    fn default(&self) -> &str {
        &self.default
    }

    fn bounds(&self) -> Option<&str> {
        self.bounds.as_deref()
    }
}

fn short_type_name<T>() -> &'static str {
    let full = std::any::type_name::<T>();
    full.rsplit("::").next().unwrap_or(full)
}

/// A source of figures: called by the message checker when they are read.
pub type FigureSource = Box<dyn Fn() -> Vec<(String, String)> + Send + Sync>;

/// The agent's parameters, by name, and its read-only figures.
#[derive(Default)]
pub struct ParamTable {
    params: BTreeMap<String, Box<dyn DynParam>>,
    figures: Option<FigureSource>,
}

impl std::fmt::Debug for ParamTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.params.iter().map(|(k, v)| (k, v.get()))).finish()
    }
}

impl ParamTable {
    /// Declares a parameter; `check` may refuse values (return a message saying what is allowed).
    pub fn declare<T>(&mut self, key: &str, default: T, check: Option<ParamCheck<T>>) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display,
    {
        let bounds = check.as_ref().and_then(probe_bounds);
        let slot = Slot { default: default.to_string(), value: Arc::new(Mutex::new(default)), check, bounds };
        let value = slot.value.clone();
        self.params.insert(key.into(), Box::new(slot));
        Param { value }
    }

    /// Installs the source of the agent's read-only figures (one per agent;
    /// a second call replaces the first).
    pub fn set_figures(&mut self, source: FigureSource) {
        self.figures = Some(source);
    }

    /// The agent's figures as (name, value), sorted by name; empty when it reports none.
    pub fn figures(&self) -> Vec<(String, String)> {
        let mut v = self.figures.as_ref().map(|f| f()).unwrap_or_default();
        v.sort();
        v
    }

    fn figure(&self, key: &str) -> Option<String> {
        self.figures.as_ref()?().into_iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// The value of parameter or figure `key` as text.
    pub fn get(&self, key: &str) -> Result<String, String> {
        match self.params.get(key) {
            Some(p) => Ok(p.get()),
            None => self.figure(key).ok_or_else(|| self.unknown(key)),
        }
    }

    /// Sets `key` from text, checking it against the parameter's type; a figure is refused.
    pub fn set(&self, key: &str, value: &str) -> Result<(), String> {
        match self.params.get(key) {
            Some(p) => p.set(value),
            None if self.figure(key).is_some() => {
                Err(format!("{key:?} is a read-only figure that the agent reports; it cannot be set"))
            }
            None => Err(self.unknown(key)),
        }
    }

    /// Every parameter as (name, value).
    pub fn snapshot(&self) -> Vec<(String, String)> {
        self.params.iter().map(|(k, v)| (k.clone(), v.get())).collect()
    }

    /// Every parameter, then every figure, with type, default and bounds
    /// (`nerve param list`).
    pub fn list(&self) -> Vec<ParamInfo> {
        let params = self.params.iter().map(|(k, p)| ParamInfo {
            key: k.clone(),
            type_name: p.type_name().into(),
            value: p.get(),
            default: p.default().into(),
            bounds: p.bounds().map(str::to_owned),
            read_only: false,
        });
        let figures = self.figures().into_iter().map(|(key, value)| ParamInfo {
            key,
            type_name: "figure".into(),
            value,
            default: String::new(),
            bounds: None,
            read_only: true,
        });
        params.chain(figures).collect()
    }

    fn unknown(&self, key: &str) -> String {
        let known: Vec<String> = self.params.iter().map(|(k, v)| format!("{k} ({})", v.type_name())).collect();
        format!(
            "no parameter {key:?}; this agent's parameters: {}",
            if known.is_empty() { "none".into() } else { known.join(", ") }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positive_takes_finite_numbers_above_zero() {
        assert!(positive(&0.5f32).is_ok() && positive(&2.0f64).is_ok());
        for bad in [0.0f64, -1.0, f64::NAN, f64::INFINITY] {
            assert_eq!(positive(&bad), Err("must be a number > 0".to_owned()), "{bad}");
        }
    }

    #[test]
    fn typed_set_and_get() {
        let mut t = ParamTable::default();
        let gain = t.declare(
            "gain",
            1.5f64,
            Some(Box::new(|v: &f64| if *v >= 0.0 { Ok(()) } else { Err("gain must be >= 0".into()) })),
        );
        assert_eq!(t.get("gain").as_deref(), Ok("1.5"));
        t.set("gain", "2.25").expect("valid");
        assert_eq!(gain.get(), 2.25);
        assert!(t.set("gain", "fast").expect_err("not a number").contains("not a valid f64"));
        assert!(t.set("gain", "-1").expect_err("checked").contains(">= 0"));
        assert!(t.get("speed").expect_err("unknown").contains("gain (f64)"));
    }

    #[test]
    fn the_list_has_types_defaults_bounds_and_figures() {
        let mut t = ParamTable::default();
        t.checked("range_m", 2.0f32, |v| in_range_above_zero("range_m", *v, 5.0, "m"));
        t.checked("count", 3u64, |v| in_range("count", *v, &(1..=10), ""));
        t.checked("speed", 0.5f64, positive);
        let label = t.declare("label", String::from("a"), None);
        label.set("b".into());
        t.set_figures(Box::new(|| vec![("peers".into(), "2".into())]));
        let l = t.list();
        let by = |k: &str| l.iter().find(|p| p.key == k).unwrap_or_else(|| panic!("{k} in {l:?}"));
        assert_eq!(by("range_m").bounds.as_deref(), Some("range_m is in (0, 5] m"));
        assert_eq!(by("range_m").type_name, "f32");
        assert_eq!(by("count").bounds.as_deref(), Some("count is in [1, 10]"));
        assert_eq!(by("speed").bounds.as_deref(), Some("must be a number > 0"));
        let label = by("label");
        assert_eq!((label.value.as_str(), label.default.as_str(), label.bounds.as_ref()), ("b", "a", None));
        let peers = by("peers");
        assert!(peers.read_only && peers.type_name == "figure" && peers.value == "2");
        assert_eq!(l.last().map(|p| p.key.as_str()), Some("peers"), "figures come after parameters");
    }

    #[test]
    fn figures_are_read_but_never_set() {
        let mut t = ParamTable::default();
        t.declare("gain", 1u32, None);
        let n = Arc::new(std::sync::atomic::AtomicU64::new(3));
        let src = n.clone();
        t.set_figures(Box::new(move || {
            vec![
                ("z.count".into(), src.load(std::sync::atomic::Ordering::Relaxed).to_string()),
                ("a".into(), "x".into()),
            ]
        }));
        assert_eq!(t.get("z.count").as_deref(), Ok("3"));
        n.store(7, std::sync::atomic::Ordering::Relaxed);
        assert_eq!(t.get("z.count").as_deref(), Ok("7"), "figures are read live");
        assert!(t.set("z.count", "1").expect_err("read-only").contains("read-only"));
        assert_eq!(t.figures(), vec![("a".to_string(), "x".to_string()), ("z.count".to_string(), "7".to_string())]);
        assert_eq!(t.snapshot(), vec![("gain".to_string(), "1".to_string())], "figures are not parameters");
    }
}
