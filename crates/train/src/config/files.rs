//! Configuration files: a TOML (`.toml`) or JSON (anything else) table of settings (snake_case
//! keys) read over a base configuration.

use super::TrainConfig;
use crate::TrainError;
use std::path::Path;

impl TrainConfig {
    /// Reads a TOML (`.toml`) or JSON (anything else) file; fields it omits keep `base`'s values.
    pub fn load_over(path: &Path, base: &Self) -> Result<Self, TrainError> {
        // Merge: serialise the base, overlay the file's keys, deserialise the result (unknown keys
        // are rejected by `deny_unknown_fields`).
        let mut merged =
            serde_json::to_value(base).map_err(|e| TrainError::Config(format!("config: {e}")))?;
        let o = Self::read_table(path)?;
        let Some(m) = merged.as_object_mut() else {
            return Err(TrainError::Config("config: not a table".into()));
        };
        for (k, v) in o {
            m.insert(k, v);
        }
        let config: Self = serde_json::from_value(merged)
            .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
        config.validate()?;
        Ok(config)
    }

    /// The settings a TOML (`.toml`) or JSON (anything else) config file names (snake_case keys).
    pub fn keys_in_file(path: &Path) -> Result<Vec<String>, TrainError> {
        Ok(Self::read_table(path)?.keys().cloned().collect())
    }

    /// The top-level table of a config file.
    fn read_table(path: &Path) -> Result<serde_json::Map<String, serde_json::Value>, TrainError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
        let table: serde_json::Value = if path.extension().is_some_and(|e| e == "toml") {
            let v: toml::Value = toml::from_str(&text)
                .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?;
            serde_json::to_value(v).map_err(|e| TrainError::Config(format!("config: {e}")))?
        } else {
            serde_json::from_str(&text)
                .map_err(|e| TrainError::Config(format!("config {}: {e}", path.display())))?
        };
        match table {
            serde_json::Value::Object(o) => Ok(o),
            _ => Err(TrainError::Config(format!(
                "config {}: the top level must be a table of settings",
                path.display()
            ))),
        }
    }
}
