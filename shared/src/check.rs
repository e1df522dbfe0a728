//! One acceptance check of a report (an experiment's, a run's, a benchmark's): a stable
//! identifier, what is checked, the measured value, the limit, and whether it holds.
//!
//! Code, tests and scripts find a check by its `id` (snake case, stable across releases);
//! people read its `name`, which may be reworded.

use serde::{Deserialize, Serialize};

/// How the value must stand to the limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Relation {
    /// value ≤ limit.
    #[serde(rename = "<=")]
    AtMost,
    /// value ≥ limit.
    #[serde(rename = ">=")]
    AtLeast,
}

impl Relation {
    /// `"<="` or `">="`.
    pub fn symbol(self) -> &'static str {
        match self {
            Relation::AtMost => "<=",
            Relation::AtLeast => ">=",
        }
    }

    /// True when `value` stands so to `limit`.
    pub fn holds(self, value: f64, limit: f64) -> bool {
        match self {
            Relation::AtMost => value <= limit,
            Relation::AtLeast => value >= limit,
        }
    }
}

/// What a failed check means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CheckKind {
    /// Holds on any machine: a wrong figure, a lost sample, a leak, a fault not recovered.
    #[default]
    Correctness,
    /// A timing or force figure a loaded or stalled machine can miss (docs/reliability.md).
    Target,
}

/// One acceptance check, measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// Stable identifier (snake case): what code, tests and scripts match on.
    pub id: String,
    /// What is checked, in words.
    pub name: String,
    /// Measured value.
    pub value: f64,
    /// How it must stand to the limit.
    pub relation: Relation,
    /// Limit.
    pub limit: f64,
    /// Correctness or target.
    #[serde(default)]
    pub kind: CheckKind,
    /// Whether it holds.
    pub pass: bool,
}

impl Check {
    /// A correctness check `value ≤ limit`, identified by `id`.
    pub fn at_most(id: impl Into<String>, name: impl Into<String>, value: f64, limit: f64) -> Self {
        Self::new(id, name, value, Relation::AtMost, limit)
    }

    /// A correctness check `value ≥ limit`, identified by `id`.
    pub fn at_least(
        id: impl Into<String>,
        name: impl Into<String>,
        value: f64,
        limit: f64,
    ) -> Self {
        Self::new(id, name, value, Relation::AtLeast, limit)
    }

    fn new(
        id: impl Into<String>,
        name: impl Into<String>,
        value: f64,
        relation: Relation,
        limit: f64,
    ) -> Self {
        let id = id.into();
        debug_assert!(is_snake_case(&id), "check id '{id}' is not snake case");
        Self {
            id,
            name: name.into(),
            value,
            relation,
            limit,
            kind: CheckKind::Correctness,
            pass: relation.holds(value, limit),
        }
    }

    /// The same check as a target.
    pub fn target(self) -> Self {
        Self {
            kind: CheckKind::Target,
            ..self
        }
    }

    /// True for a target.
    pub fn is_target(&self) -> bool {
        self.kind == CheckKind::Target
    }

    /// One line: `[ok] id: name: value <= limit` (`(target)` before a target's id).
    pub fn line(&self) -> String {
        let num = |x: f64| {
            if x.fract() == 0.0 && x.abs() < 1e15 {
                format!("{x:.0}")
            } else {
                format!("{x:.4}")
            }
        };
        format!(
            "[{}] {}{}: {}: {} {} {}",
            if self.pass { "ok" } else { "FAIL" },
            if self.is_target() { "(target) " } else { "" },
            self.id,
            self.name,
            num(self.value),
            self.relation.symbol(),
            num(self.limit),
        )
    }
}

/// True for a snake-case identifier: lowercase letters, digits and single underscores, starting
/// with a letter.
pub fn is_snake_case(id: &str) -> bool {
    id.starts_with(|c: char| c.is_ascii_lowercase())
        && !id.ends_with('_')
        && !id.contains("__")
        && id
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// The check identified by `id`, if any.
pub fn find<'a>(checks: &'a [Check], id: &str) -> Option<&'a Check> {
    checks.iter().find(|c| c.id == id)
}

/// True when every check passes.
pub fn all_pass(checks: &[Check]) -> bool {
    checks.iter().all(|c| c.pass)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_hold_by_their_relation_and_read_back() {
        let a = Check::at_most("x", "an x", 1.0, 1.0);
        let b = Check::at_least("y", "a y", 0.5, 1.0).target();
        assert!(a.pass && !b.pass && b.is_target());
        assert_eq!(a.line(), "[ok] x: an x: 1 <= 1");
        assert_eq!(b.line(), "[FAIL] (target) y: a y: 0.5000 >= 1");
        let json = serde_json::to_string(&b).unwrap();
        assert!(json.contains(r#""relation":">=""#) && json.contains(r#""kind":"target""#));
        assert!(json.contains(r#""id":"y""#));
        assert_eq!(serde_json::from_str::<Check>(&json).unwrap(), b);
        assert!(!all_pass(&[a.clone(), b.clone()]));
        assert!(all_pass(std::slice::from_ref(&a)));
        let both = [a, b];
        assert_eq!(find(&both, "y").map(|c| c.value), Some(0.5));
        assert!(find(&both, "z").is_none());
    }

    /// Identifiers are snake case: what a script can match on without quoting.
    #[test]
    fn identifiers_are_snake_case() {
        for ok in ["a", "safe_after_last_good_ms", "p99_over_p50", "x2"] {
            assert!(is_snake_case(ok), "{ok}");
        }
        for bad in ["", "A", "a-b", "a__b", "_a", "a_", "2a", "a b", "é"] {
            assert!(!is_snake_case(bad), "{bad}");
        }
    }

    /// Each relation holds at the limit and fails just past it, either way.
    #[test]
    fn relations_hold_at_the_limit_and_fail_past_it() {
        assert!(Relation::AtMost.holds(1.0, 1.0) && !Relation::AtMost.holds(1.0 + 1e-12, 1.0));
        assert!(Relation::AtLeast.holds(1.0, 1.0) && !Relation::AtLeast.holds(1.0 - 1e-12, 1.0));
        assert!(!Relation::AtMost.holds(f64::NAN, 1.0) && !Relation::AtLeast.holds(f64::NAN, 1.0));
        assert_eq!(
            (Relation::AtMost.symbol(), Relation::AtLeast.symbol()),
            ("<=", ">=")
        );
        let c = Check::at_most("a", "a", 2.0, 1.0);
        assert!(!c.pass && !c.is_target() && c.kind == CheckKind::Correctness);
        assert_eq!(c.line(), "[FAIL] a: a: 2 <= 1");
        assert_eq!(
            Check::at_least("b", "b", 0.25, 0.5).line(),
            "[FAIL] b: b: 0.2500 >= 0.5000"
        );
        // Whole numbers print as such below 10^15, with decimals from there on.
        let whole = |x: f64| Check::at_most("c", "c", x, x).line();
        assert_eq!(
            whole(999_999_999_999_999.0),
            "[ok] c: c: 999999999999999 <= 999999999999999"
        );
        assert_eq!(
            whole(1e15),
            "[ok] c: c: 1000000000000000.0000 <= 1000000000000000.0000"
        );
    }
}
