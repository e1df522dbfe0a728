//! One acceptance check of a report (an experiment's, a run's, a benchmark's): what is
//! checked, the measured value, the limit, and whether it holds.

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
    /// What is checked.
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
    /// A correctness check `value ≤ limit`.
    pub fn at_most(name: impl Into<String>, value: f64, limit: f64) -> Self {
        Self::new(name, value, Relation::AtMost, limit)
    }

    /// A correctness check `value ≥ limit`.
    pub fn at_least(name: impl Into<String>, value: f64, limit: f64) -> Self {
        Self::new(name, value, Relation::AtLeast, limit)
    }

    fn new(name: impl Into<String>, value: f64, relation: Relation, limit: f64) -> Self {
        Self {
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

    /// One line: `[ok] name: value <= limit` (`(target)` before a target's name).
    pub fn line(&self) -> String {
        let num = |x: f64| {
            if x.fract() == 0.0 && x.abs() < 1e15 {
                format!("{x:.0}")
            } else {
                format!("{x:.4}")
            }
        };
        format!(
            "[{}] {}{}: {} {} {}",
            if self.pass { "ok" } else { "FAIL" },
            if self.is_target() { "(target) " } else { "" },
            self.name,
            num(self.value),
            self.relation.symbol(),
            num(self.limit),
        )
    }
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
        let a = Check::at_most("x", 1.0, 1.0);
        let b = Check::at_least("y", 0.5, 1.0).target();
        assert!(a.pass && !b.pass && b.is_target());
        assert_eq!(a.line(), "[ok] x: 1 <= 1");
        assert_eq!(b.line(), "[FAIL] (target) y: 0.5000 >= 1");
        let json = serde_json::to_string(&b).unwrap();
        assert!(json.contains(r#""relation":">=""#) && json.contains(r#""kind":"target""#));
        assert_eq!(serde_json::from_str::<Check>(&json).unwrap(), b);
        assert!(!all_pass(&[a, b]));
    }
}
