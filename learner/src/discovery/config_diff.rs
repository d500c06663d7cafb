//! Which setting a resumed run differs in from its checkpoint
//! ([`config_difference`]): the discovery run refuses to resume with other
//! settings, and says which.

use super::DiscoveryConfig;

/// The first field (dotted path) in which a checkpoint's configuration
/// `saved` differs from this run's `now`, budget fields (`max_rounds`,
/// `patience`) aside: "config field gcp.lr is 0.001 in the checkpoint, 0.002 now".
pub fn config_difference(saved: &DiscoveryConfig, now: &DiscoveryConfig) -> Option<String> {
    crate::identity::differences(saved, now, &["max_rounds", "patience"])
        .into_iter()
        .next()
        .map(|d| {
            format!(
                "config field {} is {} in the checkpoint, {} now",
                d.path, d.saved, d.now
            )
        })
}
