//! The `POSES.json` entries `render-pose --poses` renders and `import frames` reads poses from:
//! `{"pose": 72 axis-angle values or 24 [x, y, z] triples, "transl": [x, y, z], "latent_frame": N}`
//! (`latent_frame` optional), checked.

use anyhow::{bail, Context, Result};

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseEntry {
    pose: PoseValues,
    transl: [f32; 3],
    #[serde(default)]
    latent_frame: Option<u32>,
}

/// A pose as 72 axis-angle values, or as the 24 triples of the scene format.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum PoseValues {
    Flat(Vec<f32>),
    Triples(Vec<[f32; 3]>),
}

impl PoseValues {
    fn into_flat(self) -> Vec<f32> {
        match self {
            PoseValues::Flat(v) => v,
            PoseValues::Triples(t) => t.into_iter().flatten().collect(),
        }
    }
}

/// Reads one entry of `POSES.json`: its 72 pose values and translation, checked.
pub fn read_entry(v: serde_json::Value) -> Result<(Vec<f32>, [f32; 3], Option<u32>)> {
    let e: PoseEntry = serde_json::from_value(v).context(
        "expected {\"pose\": 72 numbers or 24 [x, y, z] triples, \"transl\": [x, y, z], \
         \"latent_frame\": N (optional)}",
    )?;
    let pose = e.pose.into_flat();
    if pose.len() != 72 || pose.iter().chain(&e.transl).any(|x| !x.is_finite()) {
        bail!(
            "`pose` must hold 72 finite axis-angle values (or 24 triples) and `transl` 3 finite \
             values; found {} pose values",
            pose.len()
        );
    }
    Ok((pose, e.transl, e.latent_frame))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::read_entry;

    #[test]
    fn a_pose_reads_as_72_values_or_as_the_scene_formats_24_triples() {
        let flat: Vec<f32> = (0..72).map(|k| k as f32 * 0.01).collect();
        let triples: Vec<[f32; 3]> = flat.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let a = read_entry(serde_json::json!({"pose": flat, "transl": [0.0, 1.0, 0.0]})).unwrap();
        let b =
            read_entry(serde_json::json!({"pose": triples, "transl": [0.0, 1.0, 0.0]})).unwrap();
        assert_eq!(a.0, b.0);
        assert_eq!(a.0, flat);
        let short =
            read_entry(serde_json::json!({"pose": [[0.0, 0.0, 0.0]], "transl": [0.0, 0.0, 0.0]}));
        let e = format!("{:#}", short.unwrap_err());
        assert!(e.contains("72") && e.contains("found 3"), "{e}");
        let wrong = read_entry(serde_json::json!({"pose": "x", "transl": [0.0, 0.0, 0.0]}));
        assert!(format!("{:#}", wrong.unwrap_err()).contains("24 [x, y, z] triples"));
    }
}
