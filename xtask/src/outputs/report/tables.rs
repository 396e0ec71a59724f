//! The run page's tables: the summary of a run's `metrics.json` and, with several people, each
//! person's figures.

use super::{cell, esc, number};
use std::fmt::Write as _;

/// The summary table of a run's `metrics.json`.
pub(super) fn summary_table(m: &serde_json::Value) -> String {
    let row = |name: &str, prefix: &str| {
        format!(
            "<tr><td>{name}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            cell(number(m, &format!("{prefix}_psnr_full")), 2),
            cell(number(m, &format!("{prefix}_psnr_human_box")), 2),
            cell(number(m, &format!("{prefix}_ssim_full")), 4),
            cell(number(m, &format!("{prefix}_ssim_human_box")), 4),
            cell(number(m, &format!("{prefix}_lpips_full")), 4),
            cell(number(m, &format!("{prefix}_lpips_human_box")), 4),
        )
    };
    let mut s = String::from(
        "<table>\n<tr><th>against the sharp reference</th><th>PSNR full (dB)</th>\
         <th>PSNR box (dB)</th><th>SSIM full</th><th>SSIM box</th><th>LPIPS full</th>\
         <th>LPIPS box</th></tr>\n",
    );
    s += &row("render", "test");
    s += &row("blurred input", "blurred");
    let gap = |k: &str| number(m, k).map(|g| format!("{g:+.2}"));
    let _ = writeln!(
        s,
        "<tr><td>render − blurred input</td><td>{}</td><td>{}</td><td colspan=\"4\"></td></tr>",
        gap("gap_to_blurred_full_db").unwrap_or_else(|| "—".into()),
        gap("gap_to_blurred_human_box_db").unwrap_or_else(|| "—".into()),
    );
    s += "</table>\n<table>\n";
    let mut fact = |name: &str, value: String| {
        let _ = writeln!(s, "<tr><td>{name}</td><td>{}</td></tr>", esc(&value));
    };
    fact("human mask IoU (p > 0.5)", cell(number(m, "mask_iou"), 3));
    fact("test frames", cell(number(m, "test_frames"), 0));
    fact("steps", cell(number(m, "steps"), 0));
    if let Some(t) = number(m, "train_seconds") {
        fact("training time", format!("{:.0} s ({:.1} min)", t, t / 60.0));
    }
    fact(
        "Gaussians (human + scene)",
        format!(
            "{} + {}",
            cell(number(m, "gaussians_human"), 0),
            cell(number(m, "gaussians_scene"), 0)
        ),
    );
    for key in [
        "blur_model",
        "subframes",
        "event_loss",
        "flow_loss",
        "semantic",
        "train_on",
        "pose_correction",
        "preset",
        "data",
    ] {
        if let Some(v) = m.get(key) {
            let shown = v.as_str().map_or_else(|| v.to_string(), str::to_string);
            fact(key, shown);
        }
    }
    s += "</table>\n";
    s += &people_table(m);
    s
}

/// With several people (`metrics.json`'s `people`), each person's own figures beside the colour
/// its mask is drawn in on the strips; empty otherwise.
fn people_table(m: &serde_json::Value) -> String {
    let Some(people) = m.get("people").and_then(serde_json::Value::as_array) else {
        return String::new();
    };
    let mut s = String::from(
        "<table>\n<tr><th>person</th><th>mask IoU</th><th>PSNR box (dB)</th>\
         <th>blurred PSNR box (dB)</th><th>SSIM box</th><th>LPIPS box</th></tr>\n",
    );
    let colours = train::eval::PERSON_COLOURS;
    for (j, p) in people.iter().enumerate() {
        // The strips' linear colour, sRGB-encoded (γ 2.2) for the page.
        let [r, g, b] = colours[j % colours.len()].map(|c| (255.0 * c.powf(1.0 / 2.2)).round());
        let _ = writeln!(
            s,
            "<tr><td><span style=\"color: rgb({r}, {g}, {b})\">■</span> {}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            cell(number(p, "id"), 0),
            cell(number(p, "mask_iou"), 3),
            cell(number(p, "test_psnr_box"), 2),
            cell(number(p, "blurred_psnr_box"), 2),
            cell(number(p, "test_ssim_box"), 4),
            cell(number(p, "test_lpips_box"), 4),
        );
    }
    let _ = writeln!(
        s,
        "<tr><td colspan=\"6\">Gaussians that changed person during training: {}</td></tr>",
        cell(number(m, "person_class_changes"), 0)
    );
    s += "</table>\n";
    s
}

#[cfg(test)]
mod tests {
    use super::people_table;

    #[test]
    fn each_person_has_a_row_in_its_colour_and_one_person_has_no_table() {
        let m = serde_json::json!({
            "people": [
                {"id": 4, "mask_iou": 0.96, "test_psnr_box": 29.8, "blurred_psnr_box": 23.2},
                {"id": 9, "mask_iou": 0.97, "test_psnr_box": 28.9, "blurred_psnr_box": 22.8},
            ],
            "person_class_changes": 0,
        });
        let html = people_table(&m);
        assert_eq!(html.matches("<tr><td><span").count(), 2, "{html}");
        assert!(
            html.contains("■</span> 4</td><td>0.960</td><td>29.80</td>"),
            "{html}"
        );
        assert!(html.contains("changed person during training: 0"), "{html}");
        assert!(people_table(&serde_json::json!({"mask_iou": 0.9})).is_empty());
    }
}
