//! `ablate --seeds`: every row once per seed, and each measure's mean and range over the seeds, so
//! that a difference between two rows can be read against the spread of one row.

use super::{format_measure, push_measure_header, Outcome, Run, COLUMNS};
use anyhow::{Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// One run of the ablation: its table label, its scene, its configuration and the seed it sets
/// (none: the options' own seed).
pub(super) type Job<'a> = (String, PathBuf, &'a Run, Option<u64>);

/// `jobs` (label, scene, configuration) once per seed of `seeds`, a row's seeds next to each other
/// and labelled `<label>/seed-<s>`; without `seeds`, each once with the options' own seed. Refuses
/// an empty list and a seed given twice.
pub(super) fn per_seed<'a>(
    jobs: Vec<(String, PathBuf, &'a Run)>,
    seeds: Option<&[u64]>,
) -> Result<Vec<Job<'a>>> {
    let Some(seeds) = seeds else {
        return Ok(jobs.into_iter().map(|(l, d, r)| (l, d, r, None)).collect());
    };
    anyhow::ensure!(!seeds.is_empty(), "--seeds: no seed given");
    for (k, seed) in seeds.iter().enumerate() {
        anyhow::ensure!(
            !seeds[..k].contains(seed),
            "--seeds: seed {seed} is given twice"
        );
    }
    Ok(jobs
        .into_iter()
        .flat_map(|(label, data, run)| {
            seeds
                .iter()
                .map(move |&s| (format!("{label}/seed-{s}"), data.clone(), run, Some(s)))
        })
        .collect())
}

/// Mean, smallest and largest of some values.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Spread {
    mean: f64,
    min: f64,
    max: f64,
}

impl Spread {
    /// The spread of `values`; none for no values.
    fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        let fold = |f: fn(f64, f64) -> f64, start| values.iter().copied().fold(start, f);
        Some(Self {
            mean: values.iter().sum::<f64>() / values.len() as f64,
            min: fold(f64::min, f64::INFINITY),
            max: fold(f64::max, f64::NEG_INFINITY),
        })
    }
}

/// The row of `label` (`<row>/seed-<s>`) and its seed.
fn row_and_seed(label: &str) -> (&str, Option<u64>) {
    match label.rsplit_once("/seed-") {
        Some((row, seed)) => (row, seed.parse().ok()),
        None => (label, None),
    }
}

/// Appends to `OUT/ablation.md` a table of every row's measures over its seeds (the mean over the
/// seeds whose run finished, and the range) and writes them with each seed's value to
/// `OUT/ablation_over_seeds.json`. `results` are in job order ([`per_seed`]).
pub(super) fn write_over_seeds(out: &Path, results: &[Outcome<'_>]) -> Result<()> {
    let mut md = String::from(
        "\n## Over seeds\n\nEach measure's mean over the seeds whose run finished, and its range \
         (min–max).\n\n| run | finished |",
    );
    push_measure_header(&mut md, "| --- | ---: |");
    let mut json = Vec::new();
    for row in results.chunk_by(|a, b| row_and_seed(&a.0).0 == row_and_seed(&b.0).0) {
        let (line, entry) = summarise_row(row);
        md.push_str(&line);
        json.push(entry);
    }
    let md_path = out.join("ablation.md");
    std::fs::OpenOptions::new()
        .append(true)
        .open(&md_path)
        .and_then(|mut f| f.write_all(md.as_bytes()))
        .with_context(|| format!("appending to {}", md_path.display()))?;
    let json_path = out.join("ablation_over_seeds.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", json_path.display()))?;
    print!("{md}");
    Ok(())
}

/// One row's seeds (`row`, the same row label): its line of the over-seeds table and its
/// `ablation_over_seeds.json` entry.
fn summarise_row(row: &[Outcome<'_>]) -> (String, serde_json::Value) {
    let name = row_and_seed(&row[0].0).0;
    let finished: Vec<(Option<u64>, &serde_json::Value)> = row
        .iter()
        .filter_map(|(label, _, _, m)| Some((row_and_seed(label).1, m.as_ref().ok()?)))
        .collect();
    let mut line = format!("| `{name}` | {}/{} |", finished.len(), row.len());
    let mut measures = serde_json::Map::new();
    for (key, _) in COLUMNS {
        let values: Vec<(Option<u64>, f64)> = finished
            .iter()
            .filter_map(|(seed, m)| Some((*seed, m[key].as_f64()?)))
            .collect();
        let Some(s) = Spread::of(&values.iter().map(|v| v.1).collect::<Vec<_>>()) else {
            line.push_str(" — |");
            continue;
        };
        let f = |v| format_measure(key, v);
        line.push_str(&format!(" {} ({}–{}) |", f(s.mean), f(s.min), f(s.max)));
        let per_seed: Vec<_> = values
            .iter()
            .map(|(seed, v)| serde_json::json!({"seed": seed, "value": v}))
            .collect();
        measures.insert(
            key.to_string(),
            serde_json::json!({"mean": s.mean, "min": s.min, "max": s.max, "per_seed": per_seed}),
        );
    }
    line.push('\n');
    let entry = serde_json::json!({
        "run": name, "finished": finished.len(), "runs": row.len(), "measures": measures,
    });
    (line, entry)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_spread_is_the_mean_and_the_extremes() {
        let s = Spread::of(&[31.5, 31.7, 31.3]).unwrap();
        assert!((s.mean - 31.5).abs() < 1e-12);
        assert_eq!((s.min, s.max), (31.3, 31.7));
        assert_eq!(Spread::of(&[]), None);
    }

    #[test]
    fn labels_name_their_row_and_seed() {
        assert_eq!(
            row_and_seed("slow/one-hot/seed-12"),
            ("slow/one-hot", Some(12))
        );
        assert_eq!(row_and_seed("one-hot"), ("one-hot", None));
    }

    #[test]
    fn each_row_runs_once_per_seed_and_a_repeated_seed_is_refused() {
        let run = &super::super::RUNS[0];
        let jobs = vec![
            ("a".to_string(), PathBuf::from("d"), run),
            ("b".to_string(), PathBuf::from("d"), run),
        ];
        let labels: Vec<(String, Option<u64>)> = per_seed(jobs.clone(), Some(&[0, 3]))
            .unwrap()
            .into_iter()
            .map(|j| (j.0, j.3))
            .collect();
        assert_eq!(
            labels,
            [
                ("a/seed-0".into(), Some(0)),
                ("a/seed-3".into(), Some(3)),
                ("b/seed-0".into(), Some(0)),
                ("b/seed-3".into(), Some(3)),
            ]
        );
        assert_eq!(per_seed(jobs.clone(), None).unwrap()[1].0, "b");
        let Err(err) = per_seed(jobs.clone(), Some(&[1, 2, 1])) else {
            panic!("a repeated seed was accepted");
        };
        assert!(err.to_string().contains("seed 1 is given twice"), "{err}");
        assert!(per_seed(jobs, Some(&[])).is_err());
    }
}
