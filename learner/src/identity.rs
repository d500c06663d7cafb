//! "Does this checkpoint belong to this run?": a run directory records what
//! it was started with, and a command that resumes it compares that record
//! with its own, field by field. [`differences`] is that comparison, the
//! one every resumable run (`train`, `discover`, the pipeline's learner
//! role, the discovery loop's checkpoint) uses; each caller words the
//! refusal for its own user.

use serde::Serialize;

/// One field in which a saved record differs from this run's.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    /// The field's dotted path (`agent.worker.learning_rate`).
    pub path: String,
    /// Its value in the saved record (JSON; `null` when absent).
    pub saved: serde_json::Value,
    /// Its value now.
    pub now: serde_json::Value,
}

impl std::fmt::Display for Difference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {} there, {} here", self.path, self.saved, self.now)
    }
}

/// Every field (in dotted-path order) in which `saved` and `now` differ,
/// after serialising both to JSON; top-level fields named in `ignore` (a
/// budget that may grow on a resumed run) are skipped. A record that does
/// not serialise differs as a whole (path `""`).
pub fn differences<T: Serialize>(saved: &T, now: &T, ignore: &[&str]) -> Vec<Difference> {
    fn walk(
        path: &str,
        a: &serde_json::Value,
        b: &serde_json::Value,
        ignore: &[&str],
        out: &mut Vec<Difference>,
    ) {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
                keys.sort();
                keys.dedup();
                let null = serde_json::Value::Null;
                for k in keys {
                    if path.is_empty() && ignore.contains(&k.as_str()) {
                        continue;
                    }
                    let sub = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    walk(
                        &sub,
                        x.get(k).unwrap_or(&null),
                        y.get(k).unwrap_or(&null),
                        &[],
                        out,
                    );
                }
            }
            _ if a != b => out.push(Difference {
                path: path.to_string(),
                saved: a.clone(),
                now: b.clone(),
            }),
            _ => {}
        }
    }
    let (a, b) = match (serde_json::to_value(saved), serde_json::to_value(now)) {
        (Ok(a), Ok(b)) => (a, b),
        _ => {
            return vec![Difference {
                path: String::new(),
                saved: serde_json::Value::Null,
                now: serde_json::Value::Null,
            }];
        }
    };
    let mut out = Vec::new();
    walk("", &a, &b, ignore, &mut out);
    out
}

/// [`differences`] as one line: `a.b: 1 there, 2 here; c: ...`.
pub fn describe(diffs: &[Difference]) -> String {
    diffs
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize)]
    struct Inner {
        lr: f64,
        width: usize,
    }

    #[derive(Serialize)]
    struct Record {
        maze: &'static str,
        budget: u64,
        inner: Inner,
    }

    #[test]
    fn every_differing_leaf_is_named_by_its_dotted_path_and_ignored_fields_are_skipped() {
        let saved = Record {
            maze: "small",
            budget: 10,
            inner: Inner {
                lr: 1e-3,
                width: 128,
            },
        };
        let now = Record {
            maze: "medium",
            budget: 20,
            inner: Inner {
                lr: 2e-3,
                width: 128,
            },
        };
        let d = differences(&saved, &now, &["budget"]);
        let paths: Vec<&str> = d.iter().map(|d| d.path.as_str()).collect();
        assert_eq!(paths, ["inner.lr", "maze"]);
        assert_eq!(
            describe(&d),
            "inner.lr: 0.001 there, 0.002 here; maze: \"small\" there, \"medium\" here"
        );
        assert!(differences(&saved, &saved, &[]).is_empty());
        assert_eq!(differences(&saved, &now, &[]).len(), 3);
    }
}
