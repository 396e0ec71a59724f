//! Configurations stored by earlier versions (a checkpoint's metadata, a model's `model.json`):
//! an option they do not name was trained with the value it had before it existed, not with
//! today's default, so a stored model keeps computing what it was trained to compute.

use super::{TrainConfig, ViewRotation};

impl TrainConfig {
    /// Sets every option that the stored table `stored` (the configuration as written, a JSON
    /// object) does not name and whose default has changed since it was added to the value runs
    /// had before: `view_rotation` = `canonical` (the default until 2026-12-06).
    pub fn pin_options_missing_from(&mut self, stored: &serde_json::Value) {
        let named = |key: &str| stored.get(key).is_some();
        if !named("view_rotation") {
            self.view_rotation = ViewRotation::Canonical;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stored_config_without_the_view_rotation_keeps_the_canonical_one() {
        let mut written = serde_json::to_value(TrainConfig::default()).unwrap();
        written.as_object_mut().unwrap().remove("view_rotation");
        let mut read: TrainConfig = serde_json::from_value(written.clone()).unwrap();
        assert_eq!(read.view_rotation, ViewRotation::Moved, "today's default");
        read.pin_options_missing_from(&written);
        assert_eq!(read.view_rotation, ViewRotation::Canonical);

        let mut named = serde_json::to_value(TrainConfig::default()).unwrap();
        named["view_rotation"] = serde_json::json!("moved");
        let mut kept: TrainConfig = serde_json::from_value(named.clone()).unwrap();
        kept.pin_options_missing_from(&named);
        assert_eq!(kept.view_rotation, ViewRotation::Moved);
    }
}
