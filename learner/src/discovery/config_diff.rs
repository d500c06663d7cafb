//! Which setting a resumed run differs in from its checkpoint
//! ([`config_difference`]): the discovery run refuses to resume with other
//! settings, and says which.

use super::DiscoveryConfig;

/// The first field (dotted path) in which a checkpoint's configuration
/// `saved` differs from this run's `now`, budget fields (`max_rounds`,
/// `patience`) aside: "config field gcp.lr is 0.001 in the checkpoint, 0.002 now".
pub fn config_difference(saved: &DiscoveryConfig, now: &DiscoveryConfig) -> Option<String> {
    fn walk(path: &str, a: &serde_json::Value, b: &serde_json::Value) -> Option<String> {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
                keys.sort();
                keys.dedup();
                keys.into_iter().find_map(|k| {
                    let sub = if path.is_empty() {
                        k.clone()
                    } else {
                        format!("{path}.{k}")
                    };
                    if path.is_empty() && (k == "max_rounds" || k == "patience") {
                        return None;
                    }
                    let null = serde_json::Value::Null;
                    walk(&sub, x.get(k).unwrap_or(&null), y.get(k).unwrap_or(&null))
                })
            }
            _ if a == b => None,
            _ => Some(format!(
                "config field {path} is {a} in the checkpoint, {b} now"
            )),
        }
    }
    let (a, b) = (
        serde_json::to_value(saved).ok()?,
        serde_json::to_value(now).ok()?,
    );
    walk("", &a, &b)
}
