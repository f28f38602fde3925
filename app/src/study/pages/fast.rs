//! The `fast` study's chart: issue 10's options (Winograd, the matching index,
//! re-used matches) as style distance against wall time, one line per option,
//! so that "as good at the same budget" and "better at the same time" are read
//! off one picture. The exact default's seed-1 twin, dashed, is the noise floor.

use std::path::Path;

use crate::report::chart::{Chart, Series, palette};
use crate::study::{Record, Row, Study};

/// One chart per style of the `fast` study (none when it did not run); returns
/// `(file stem, caption)` of each.
pub(super) fn fast_charts(out: &Path, rows: &[Row], records: &[Record]) -> anyhow::Result<Vec<(String, String)>> {
    let fast: Vec<(&Row, &Record)> = rows
        .iter()
        .filter(|r| r.study == Study::Fast)
        .filter_map(|row| records.iter().find(|t| t.id == row.trial).map(|t| (row, t)))
        .collect();
    let mut styles: Vec<&str> = fast.iter().map(|(_, r)| r.style.as_str()).collect();
    styles.dedup();
    let mut made = Vec::new();
    for style in styles {
        // Each option's longest row (its twice-the-budget arm) holds every checkpoint.
        let mut options: Vec<(&str, &Row, &Record)> = Vec::new();
        for &(row, rec) in fast.iter().filter(|(_, r)| r.style == style) {
            let name = option_name(&row.label);
            match options.iter_mut().find(|o| o.0 == name) {
                Some(o) if o.1.step >= row.step => {}
                Some(o) => *o = (name, row, rec),
                None => options.push((name, row, rec)),
            }
        }
        let series = options
            .iter()
            .enumerate()
            .map(|(i, (name, row, rec))| Series {
                name: (*name).to_string(),
                points: rec
                    .checkpoints
                    .iter()
                    .filter(|c| c.step <= row.step)
                    .map(|c| (c.seconds, f64::from(c.measures.sliced_wasserstein)))
                    .collect(),
                color: palette(i),
                line: true,
                dashed: name.contains("seed 1"),
                markers: true,
            })
            .collect();
        let stem = format!("fast_sw_vs_time_{style}");
        Chart {
            title: format!("{style}: fewer operations per step, style distance against wall time"),
            x_label: "wall time (s), preparation included".into(),
            y_label: "sliced Wasserstein distance to the style (VGG relu3 units)".into(),
            x_log: false,
            y_log: false,
            series,
            width: 960,
            height: 560,
            note: Some("lower is closer to the style; the dashed line is the exact default with another seed".into()),
        }
        .write(&out.join("charts").join(&stem))?;
        made.push((stem, format!("{style}: the fast options, style distance against wall time")));
    }
    Ok(made)
}

/// `"pca 128/32 @ 160"` → `"pca 128/32"`.
fn option_name(label: &str) -> &str {
    label.rsplit_once(" @ ").map_or(label, |(name, _)| name)
}

#[cfg(test)]
mod tests {
    #[test]
    fn option_names_drop_the_budget() {
        assert_eq!(super::option_name("winograd + pca + reuse 3 @ 160"), "winograd + pca + reuse 3");
        assert_eq!(super::option_name("exact, seed 1 @ 80"), "exact, seed 1");
        assert_eq!(super::option_name("exact"), "exact");
    }
}
