//! The checks of a scene with several people (format version 3): the scene's `people` (stable
//! ids, unique with the first person's `body.id`, each with its betas), every frame's `people`
//! (one pose per listed person, in the scene's order) and its `person_ids` image.

use super::*;

/// What the frames' checks need of the scene's people.
pub(super) struct PeopleSpec {
    /// The other people's ids, in the scene's order (empty: one person).
    pub others: Vec<u64>,
    /// Whether the scene's version allows several people.
    pub allowed: bool,
}

impl Checker<'_> {
    /// `body.id` and the scene's `people` list; the other people's ids in order.
    pub(super) fn people(&mut self, scene: &Map<String, Value>, allowed: bool) -> PeopleSpec {
        let first = scene
            .get("body")
            .and_then(|b| b.get("id"))
            .and_then(|id| self.uint(id, "body.id", u64::from(u32::MAX)));
        if first.is_some() && !allowed {
            self.bad("body.id", needs_version());
        }
        let mut ids: HashSet<u64> = HashSet::new();
        ids.insert(first.unwrap_or(0));
        let mut others = Vec::new();
        let Some(list) = scene.get("people") else {
            return PeopleSpec { others, allowed };
        };
        if !allowed {
            self.bad("people", needs_version());
        }
        let Some(entries) = list.as_array() else {
            self.bad(
                "people",
                format!("expected an array, found {}", describe(list)),
            );
            return PeopleSpec { others, allowed };
        };
        for (k, entry) in entries.iter().enumerate() {
            let p = format!("people[{k}]");
            let Some(m) = self.obj(entry, &p, &["id", "betas"], &[]) else {
                continue;
            };
            if let Some(betas) = m.get("betas") {
                self.floats(betas, &format!("{p}.betas"), None);
            }
            let Some(id) = m
                .get("id")
                .and_then(|id| self.uint(id, &format!("{p}.id"), u64::from(u32::MAX)))
            else {
                continue;
            };
            if !ids.insert(id) {
                self.bad(
                    &format!("{p}.id"),
                    format!(
                        "{id} is already another person's id (ids are unique, body.id included)"
                    ),
                );
            }
            others.push(id);
        }
        PeopleSpec { others, allowed }
    }

    /// Frame `p`'s (JSON path) `people` poses and `person_ids` image against the scene's people.
    pub(super) fn frame_people(
        &mut self,
        frame: &Map<String, Value>,
        p: &str,
        spec: &PeopleSpec,
        size: Option<(u32, u32)>,
    ) {
        if let Some(x) = frame.get("person_ids") {
            let path = format!("{p}.person_ids");
            if spec.allowed {
                self.png(x, &path, PngKind::Mask, size);
            } else {
                self.bad(&path, needs_version());
            }
        }
        let Some(list) = frame.get("people") else {
            if !spec.others.is_empty() {
                self.bad(
                    p,
                    format!(
                        "missing required key \"people\" (the scene lists {} other people)",
                        spec.others.len()
                    ),
                );
            }
            return;
        };
        let path = format!("{p}.people");
        if !spec.allowed {
            self.bad(&path, needs_version());
            return;
        }
        let Some(entries) = list.as_array() else {
            self.bad(
                &path,
                format!("expected an array, found {}", describe(list)),
            );
            return;
        };
        if entries.len() != spec.others.len() {
            self.bad(
                &path,
                format!(
                    "{} entries, the scene's people list has {} (every frame poses every person)",
                    entries.len(),
                    spec.others.len()
                ),
            );
        }
        for (k, entry) in entries.iter().enumerate() {
            let ep = format!("{path}[{k}]");
            let Some(m) = self.obj(entry, &ep, &["id", "pose", "transl"], &[]) else {
                continue;
            };
            let id = m
                .get("id")
                .and_then(|id| self.uint(id, &format!("{ep}.id"), u64::from(u32::MAX)));
            if let (Some(id), Some(&want)) = (id, spec.others.get(k)) {
                if id != want {
                    self.bad(
                        &format!("{ep}.id"),
                        format!("{id}, but entry {k} of the scene's people is person {want} (same order)"),
                    );
                }
            }
            if let Some(pose) = m.get("pose") {
                self.pose(pose, &format!("{ep}.pose"));
            }
            if let Some(t) = m.get("transl") {
                self.floats(t, &format!("{ep}.transl"), Some(3));
            }
        }
    }

    /// An SMPL pose: [`NUM_JOINTS`] axis-angle triples.
    pub(super) fn pose(&mut self, pose: &Value, path: &str) {
        match pose.as_array() {
            Some(rows) if rows.len() == NUM_JOINTS => {
                for (j, r) in rows.iter().enumerate() {
                    self.floats(r, &format!("{path}[{j}]"), Some(3));
                }
            }
            _ => self.bad(
                path,
                format!(
                    "expected {NUM_JOINTS} axis-angle triples, found {}",
                    describe(pose)
                ),
            ),
        }
    }
}

/// The refusal of a field of several people in a scene of an earlier version.
fn needs_version() -> String {
    format!("several people need format_version {FORMAT_VERSION_PEOPLE}")
}
