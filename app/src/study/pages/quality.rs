//! The folder `gast bench quality` writes: the table of every trial at every
//! checkpoint (CSV and JSON), charts (PNG and SVG), sample renders, and an
//! `index.md` that ties them together with the ablation tables in the paper's
//! layout and the stability study.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use gast_core::eval::Measures;
use gast_core::io::{write_bytes, write_png_rgb};
use gast_core::session::StyleImage;
use gast_core::style::Mode;

use crate::report::chart::{Chart, Series, palette};
use crate::study::{Record, Row, RunSummary, SEED_LABEL, Study, mode_label};

impl Record {
    pub(crate) fn scene_name(&self) -> String {
        let name = Path::new(&self.scene).file_name().map_or(self.scene.clone(), |s| s.to_string_lossy().into_owned());
        name.split('.').next().unwrap_or(&name).trim_end_matches("-sog").to_string()
    }

    pub(crate) fn health(&self) -> String {
        if self.stable {
            "stable".into()
        } else {
            self.issues
                .iter()
                .map(|d| format!("{:?} {:.3} > {:.3}", d.kind, d.value, d.threshold))
                .collect::<Vec<_>>()
                .join("; ")
        }
    }
}

/// Writes everything under `out` (`results.json`, generated styles, then
/// [`rewrite_report`]; the runner wrote each trial's sample render as it
/// finished, [`write_sample`]); returns the index's path.
pub fn write_report(out: &Path, run: &RunSummary, styles: &[(String, StyleImage)]) -> anyhow::Result<PathBuf> {
    for dir in ["charts", "renders", "styles"] {
        gast_core::io::create_folder(out.join(dir))
            .with_context(|| format!("could not create {}", out.join(dir).display()))?;
    }
    write_text(&out.join("results.json"), &serde_json::to_string_pretty(run)?)?;
    for (name, image) in styles {
        if ["noise", "checker", "flat"].contains(&name.as_str()) {
            let rgb: Vec<f32> = image.to_f32();
            write_png_rgb(&out.join(format!("styles/{name}.png")), image.width as u32, image.height as u32, &rgb)?;
        }
    }
    rewrite_report(out, run)
}

/// Writes `r`'s sample sheet (input, result, their depths) to
/// `out/renders/<id>.png`.
pub fn write_sample(out: &Path, r: &Record) -> anyhow::Result<()> {
    let dir = out.join("renders");
    gast_core::io::create_folder(&dir).with_context(|| format!("could not create {}", dir.display()))?;
    let (w, h, rgb) = &r.sample;
    Ok(write_png_rgb(&dir.join(format!("{}.png", r.id)), *w, *h, rgb)?)
}

/// Writes `results.csv`, the charts and `index.md` of `run` under `out`
/// (also used to redraw an earlier run's report from its `results.json`).
pub fn rewrite_report(out: &Path, run: &RunSummary) -> anyhow::Result<PathBuf> {
    gast_core::io::create_folder(out.join("charts"))
        .with_context(|| format!("could not create {}", out.join("charts").display()))?;
    write_text(&out.join("results.csv"), &csv(&run.trials))?;
    let charts = write_charts(out, &run.rows, &run.trials)?;
    let index = out.join("index.md");
    write_text(&index, &index_markdown(run, &charts))?;
    Ok(index)
}

/// Reads the `results.json` of an earlier run.
pub fn read_summary(dir: &Path) -> anyhow::Result<RunSummary> {
    let path = dir.join("results.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("could not read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is not the results.json of `gast bench quality` (expected command, sizes, rows, trials)",
            path.display()
        )
    })
}

fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    write_bytes(path, text.as_bytes())?;
    Ok(())
}

/// Every measure as reported: CSV name, table header, getter, decimals in tables.
const COLUMNS: [(&str, &str, Measure, usize); 13] = [
    ("sliced_wasserstein", "SW ↓", |m| m.sliced_wasserstein, 4),
    ("gram", "Gram ↓", |m| m.gram, 4),
    ("mean_std", "mean–std ↓", |m| m.mean_std, 4),
    ("nn_cosine", "NN-cos ↓", |m| m.nn_cosine, 4),
    ("nn_cosine_depth", "NN depth ↓", |m| m.nn_cosine_depth, 4),
    ("nn_cosine_edge", "NN edge ↓", |m| m.nn_cosine_edge, 4),
    ("nn_cosine_joint", "NN joint ↓", |m| m.nn_cosine_joint, 4),
    ("content", "content ↓", |m| m.content, 4),
    ("consistency_short", "RMSE 5° ↓", |m| m.consistency_short, 4),
    ("consistency_long", "RMSE 37.5° ↓", |m| m.consistency_long, 4),
    ("depth_change", "depth Δ", |m| m.depth_change, 4),
    ("normal_change_degrees", "normal Δ (°)", |m| m.normal_change_degrees, 2),
    ("coverage", "coverage", |m| m.coverage, 3),
];

fn csv(records: &[Record]) -> String {
    let mut s = String::from("trial,scene,style,mode,ratio_geo,lambda_gc,lr_scale,resolution,budget,step,seconds,");
    s.push_str(&COLUMNS.map(|c| c.0).join(","));
    s.push_str(",stable,issues\n");
    for r in records {
        for c in &r.checkpoints {
            let _ = write!(
                s,
                "{},{},{},{},{},{},{},{},{},{},{:.3}",
                r.id,
                r.scene_name(),
                r.style,
                r.mode,
                r.ratio_geo,
                r.lambda_gc,
                r.lr_scale,
                r.resolution,
                r.budget,
                c.step,
                c.seconds
            );
            for (_, _, f, _) in COLUMNS {
                let _ = write!(s, ",{}", f(&c.measures));
            }
            let issues: Vec<String> = r.issues.iter().map(|d| format!("{:?}", d.kind)).collect();
            let _ = writeln!(s, ",{},{}", r.stable, issues.join("+"));
        }
    }
    s
}

/// The rows of `study`, with their records, in grid order.
fn study_rows<'a>(rows: &'a [Row], records: &'a [Record], study: Study) -> Vec<(&'a Row, &'a Record)> {
    rows.iter()
        .filter(|r| r.study == study)
        .filter_map(|row| records.iter().find(|t| t.id == row.trial).map(|t| (row, t)))
        .collect()
}

fn write_charts(out: &Path, rows: &[Row], records: &[Record]) -> anyhow::Result<Vec<(String, String)>> {
    let mut made = Vec::new();
    let modes = study_rows(rows, records, Study::Modes);
    let metrics: [(&str, &str, Measure); 3] = [
        ("sw", "sliced Wasserstein distance to the style (VGG relu3 units)", |m| m.sliced_wasserstein),
        ("nn", "nearest-neighbour cosine distance to the style (0–2)", |m| m.nn_cosine),
        ("nn_joint", "GCFM joint (RGB+depth+edge) nearest-neighbour cosine distance (0–2)", |m| m.nn_cosine_joint),
    ];
    // One chart per style: the styles sit at different distances, and a shared
    // axis would flatten every curve.
    for style in dedup(modes.iter().map(|(_, r)| r.style.clone())) {
        for (key, label, f) in metrics {
            for (x_key, x_label) in [("time", "wall time (s)"), ("iterations", "optimisation steps")] {
                let series: Vec<Series> = modes
                    .iter()
                    .filter(|(_, rec)| rec.style == style)
                    .map(|(row, rec)| Series {
                        name: row.label.clone(),
                        points: rec
                            .checkpoints
                            .iter()
                            .filter(|c| c.step <= row.step)
                            .map(|c| {
                                (if x_key == "time" { c.seconds } else { f64::from(c.step) }, f64::from(f(&c.measures)))
                            })
                            .collect(),
                        color: palette(mode_index(&rec.mode)),
                        line: true,
                        dashed: row.label == SEED_LABEL,
                        markers: true,
                    })
                    .collect();
                let stem = format!("{key}_vs_{x_key}_{style}");
                Chart {
                    title: format!(
                        "{}: {} against {}, by mode",
                        style,
                        label_head(label),
                        if x_key == "time" { "wall time" } else { "iterations" }
                    ),
                    x_label: x_label.into(),
                    y_label: label.into(),
                    x_log: false,
                    y_log: false,
                    series,
                    width: 960,
                    height: 560,
                    note: Some("lower is closer to the style; step 0 is the colour-matched input".into()),
                }
                .write(&out.join("charts").join(&stem))?;
                made.push((stem, format!("{style}: {} against {x_label}, one line per mode", label_head(label))));
            }
        }
    }
    let res = study_rows(rows, records, Study::Resolution);
    if !res.is_empty() {
        let series = res
            .iter()
            .enumerate()
            .map(|(i, (row, rec))| Series {
                name: row.label.clone(),
                points: rec
                    .checkpoints
                    .iter()
                    .filter(|c| c.step <= row.step)
                    .map(|c| (c.seconds, f64::from(c.measures.sliced_wasserstein)))
                    .collect(),
                color: palette(i),
                line: true,
                dashed: false,
                markers: true,
            })
            .collect();
        Chart {
            title: "Working resolution: style distance against wall time".into(),
            x_label: "wall time (s)".into(),
            y_label: metrics[0].1.into(),
            x_log: false,
            y_log: false,
            series,
            width: 960,
            height: 560,
            note: Some("measured on the same 192 px evaluation views whatever the working resolution".into()),
        }
        .write(&out.join("charts/resolution_tradeoff"))?;
        made.push(("resolution_tradeoff".into(), "speed against accuracy across working resolutions".into()));
    }
    let ratio = study_rows(rows, records, Study::Ratio);
    if !ratio.is_empty() {
        let styles: Vec<String> = dedup(ratio.iter().map(|(_, r)| r.style.clone()));
        for (stem, y_label, f) in [
            ("ratio_style", metrics[0].1, SW),
            ("ratio_geometry", "mean change of the depth normals (degrees)", |m: &Measures| m.normal_change_degrees),
        ] {
            let series = styles
                .iter()
                .enumerate()
                .map(|(i, style)| Series {
                    name: style.clone(),
                    points: ratio
                        .iter()
                        .filter(|(_, r)| &r.style == style)
                        .filter_map(|(row, r)| {
                            r.at(row.step).map(|c| (f64::from(r.ratio_geo) * 100.0, f64::from(f(&c.measures))))
                        })
                        .collect(),
                    color: palette(i + 4),
                    line: true,
                    dashed: false,
                    markers: true,
                })
                .collect();
            Chart {
                title: format!("N_g ratio: {}", label_head(y_label)),
                x_label: "geometry steps per cycle, N_g / (N_c + N_g) (%)".into(),
                y_label: y_label.into(),
                x_log: false,
                y_log: false,
                series,
                width: 960,
                height: 560,
                note: None,
            }
            .write(&out.join("charts").join(stem))?;
            made.push((stem.into(), format!("{} against the N_g ratio", label_head(y_label))));
        }
    }
    made.extend(super::fast::fast_charts(out, rows, records)?);
    Ok(made)
}

fn label_head(label: &str) -> &str {
    label.split(" (").next().unwrap_or(label)
}

fn mode_index(mode: &str) -> usize {
    Mode::ALL.iter().position(|m| mode_label(*m) == mode).unwrap_or(0)
}

fn dedup(items: impl Iterator<Item = String>) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for i in items {
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

fn table_header(first: &str) -> String {
    let heads: Vec<&str> = COLUMNS.iter().map(|c| c.1).collect();
    format!(
        "| {first} | {} | time (s) | stable |\n|---|{}---:|---|\n",
        heads.join(" | "),
        "---:|".repeat(COLUMNS.len())
    )
}

fn table_row(label: &str, r: &Record, step: u32) -> String {
    let Some(c) = r.at(step) else { return format!("| {label} | (no measure) |\n") };
    let cells: Vec<String> = COLUMNS.iter().map(|(_, _, f, d)| format!("{:.*}", *d, f(&c.measures))).collect();
    let stable = if r.stable { "yes".to_string() } else { format!("**no**: {}", r.health()) };
    format!("| {label} | {} | {:.1} | {stable} |\n", cells.join(" | "), c.seconds)
}

/// The spread of a measure between the decoupled run and its seed-1 twin
/// (another view order) on `style` at `step`: differences below it are noise.
fn seed_spread(modes: &[(&Row, &Record)], style: &str, step: u32, f: Measure) -> Option<f32> {
    let at = |label: &str| {
        modes
            .iter()
            .find(|(row, r)| row.label == label && r.style == style)
            .and_then(|(_, r)| r.at(step))
            .map(|c| f(&c.measures))
    };
    Some((at("decoupled")? - at(SEED_LABEL)?).abs())
}

/// A claim "`a` < `b`" checked on a measure, against the seed spread (and
/// never finer than 0.1 % of the values, below which nothing here is resolved).
fn claim_less(name: &str, a: f32, b: f32, spread: Option<f32>) -> String {
    let noise = spread.unwrap_or(0.0).max(1e-3 * a.abs().max(b.abs()));
    let verdict = if (a - b).abs() <= noise {
        "within noise"
    } else if a < b {
        "**agrees**"
    } else {
        "**disagrees**"
    };
    match spread {
        Some(n) => format!("{name} {a:.4} vs {b:.4}: {verdict} (seed spread {n:.4})"),
        None => format!("{name} {a:.4} vs {b:.4}: {verdict}"),
    }
}

type Measure = fn(&Measures) -> f32;
const SW: Measure = |m| m.sliced_wasserstein;
const NN: Measure = |m| m.nn_cosine;
const JOINT: Measure = |m| m.nn_cosine_joint;

fn index_markdown(run: &RunSummary, charts: &[(String, String)]) -> String {
    let (sizes, rows, records) = (&run.sizes, run.rows.as_slice(), run.trials.as_slice());
    let mut s = String::new();
    let _ = writeln!(s, "# Quality benchmark\n");
    // What the trials ran, from the trials themselves: a study's own settings
    // (the defaults study's planned 256 px and 100 steps a cycle) override
    // the grid's.
    let span = |values: Vec<u32>, fallback: u32| {
        let (lo, hi) = (values.iter().min().copied(), values.iter().max().copied());
        match (lo, hi) {
            (Some(lo), Some(hi)) if lo != hi => format!("{lo}–{hi}"),
            (Some(lo), _) => lo.to_string(),
            _ => fallback.to_string(),
        }
    };
    let resolution = span(records.iter().map(|r| r.resolution).collect(), sizes.resolution);
    let per_cycle = span(records.iter().map(|r| r.steps_per_cycle).collect(), sizes.steps_per_cycle);
    let _ = writeln!(
        s,
        "`{}` — {} trials in {:.1} min on {} threads. Optimisation at {resolution} px from {} orbit views, {per_cycle} steps per cycle (the paper's 10:90 split, scaled where a cycle is shorter than its 100 steps; the geometry share is kept), measured on a fixed ring of {} px views (see `core/src/eval/measure.rs`). Times are preparation plus optimisation, measuring excluded.\n",
        run.command,
        records.len(),
        run.wall_s / 60.0,
        run.threads,
        sizes.views,
        sizes.eval_resolution
    );
    let _ = writeln!(
        s,
        "Files: [results.csv](results.csv) (one line per trial and checkpoint), [results.json](results.json) (the same with the grid), `renders/` (per trial: colour-matched input, result, and their inverse depths, first evaluation view).\n"
    );
    let mut taken: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    for r in records {
        if let Some(from) = &r.from {
            *taken.entry(from.as_str()).or_default() += 1;
        }
    }
    if !taken.is_empty() {
        let list: Vec<String> = taken.iter().map(|(from, n)| format!("{n} from `{from}`")).collect();
        let _ = writeln!(
            s,
            "Taken from other runs' journals (`--from`, the same computation; their times are those runs'): {}.\n",
            list.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "Columns: **SW** sliced Wasserstein and **Gram** distances between the VGG relu3 features of the renders and of the style; **NN-cos** mean cosine distance of each render feature to its nearest style feature, and **NN depth**, **NN edge** the same for the rendered depth and edge maps against the style's depth and edge maps (GCFM's three modalities, each on its own; depth and edges show structure rather than colour), and **NN joint** GCFM's own criterion on the concatenated features; **content** feature distance to the colour-matched render, relative; **RMSE** colour disagreement after warping one view into another by rendered depth, at a 5° and a 37.5° baseline; **depth Δ** relative inverse-depth change and **normal Δ** mean change of depth normals against the input (how much the geometry moved); **stable** whether any degeneration detector fired.\n"
    );
    let _ = writeln!(s, "## Charts\n");
    for (stem, caption) in charts {
        let _ = writeln!(s, "**{caption}** ([SVG](charts/{stem}.svg))\n\n![{caption}](charts/{stem}.png)\n");
    }

    let _ = writeln!(
        s,
        "## Ablations in the paper's layout\n\nThe paper's claims checked below are those of its abstract and its chosen defaults (decoupled optimisation \"alleviates potential interference between color and geometry updates, leading to stable and consistent\" geometry transfer; N_g = 90 % and λ_GC = 2 as defaults). Its numeric tables were not available here, so only orderings are compared, never values.\n"
    );
    let modes = study_rows(rows, records, Study::Modes);
    for style in dedup(modes.iter().map(|(_, r)| r.style.clone())) {
        let of = |m: Mode| modes.iter().find(|(_, r)| r.style == style && r.mode == mode_label(m));
        let _ = writeln!(s, "### Optimisation strategy, style {style}\n");
        s.push_str(&table_header("method"));
        for (m, name) in [
            (Mode::GeometryOnly, "only geometry"),
            (Mode::ColorOnly, "only colour"),
            (Mode::Joint, "joint"),
            (Mode::Decoupled, "decoupled (ours)"),
        ] {
            if let Some((row, r)) = of(m) {
                s.push_str(&table_row(name, r, row.step));
            }
        }
        let step = of(Mode::Decoupled).map_or(0, |(row, _)| row.step);
        if let Some((_, r)) = modes.iter().find(|(row, r)| row.label == SEED_LABEL && r.style == style) {
            s.push_str(&table_row("decoupled, other view order (seed 1)", r, step));
        }
        let m = |mode: Mode| of(mode).and_then(|(row, r)| r.at(row.step)).map(|c| c.measures);
        let spread = |f: Measure| seed_spread(&modes, &style, step, f);
        if let (Some(d), Some(j), Some(c), Some(g)) =
            (m(Mode::Decoupled), m(Mode::Joint), m(Mode::ColorOnly), m(Mode::GeometryOnly))
        {
            let _ = writeln!(
                s,
                "\n- Decoupled closer to the style than joint: {}; {}; {}",
                claim_less("NN joint", d.nn_cosine_joint, j.nn_cosine_joint, spread(JOINT)),
                claim_less("NN-cos", d.nn_cosine, j.nn_cosine, spread(NN)),
                claim_less("SW", d.sliced_wasserstein, j.sliced_wasserstein, spread(SW))
            );
            let _ = writeln!(
                s,
                "- Decoupled at least as consistent across views as joint: {}",
                claim_less("RMSE 37.5°", d.consistency_long, j.consistency_long, spread(|m| m.consistency_long))
            );
            let _ = writeln!(
                s,
                "- Decoupled gives the scene's depth more of the style's structure than only colour: {}",
                claim_less("NN depth", d.nn_cosine_depth, c.nn_cosine_depth, spread(|m| m.nn_cosine_depth))
            );
            let held = c.normal_change_degrees == 0.0 && d.normal_change_degrees > 0.0;
            let _ = writeln!(
                s,
                "- Only colour transfers no structure (normal Δ exactly 0) while decoupled does: {} ({:.2}° vs {:.2}°)",
                if held { "**agrees**" } else { "**disagrees**" },
                c.normal_change_degrees,
                d.normal_change_degrees
            );
            let _ = writeln!(
                s,
                "- Only geometry stays further from the style than decoupled: {}; {}; {}\n",
                claim_less("NN joint", d.nn_cosine_joint, g.nn_cosine_joint, spread(JOINT)),
                claim_less("NN-cos", d.nn_cosine, g.nn_cosine, spread(NN)),
                claim_less("SW", d.sliced_wasserstein, g.sliced_wasserstein, spread(SW))
            );
        }
    }
    let ratio = study_rows(rows, records, Study::Ratio);
    for style in dedup(ratio.iter().map(|(_, r)| r.style.clone())) {
        let _ = writeln!(s, "### N_g ratio, style {style}\n");
        s.push_str(&table_header("N_g (%)"));
        let mut at90 = None;
        let mut others = Vec::new();
        let mut step = 0;
        for (row, r) in ratio.iter().filter(|(_, r)| r.style == style) {
            s.push_str(&table_row(&row.label, r, row.step));
            step = row.step;
            if let Some(c) = r.at(row.step) {
                if row.label == "90" {
                    at90 = Some(c.measures);
                } else if (0.3..0.9).contains(&r.ratio_geo) {
                    others.push((row.label.clone(), c.measures));
                }
            }
        }
        if let Some(m90) = at90 {
            s.push('\n');
            for (label, m) in &others {
                let _ = writeln!(
                    s,
                    "- The paper's 90 % closer to the style than {label} %: {}; {}; {}",
                    claim_less(
                        "NN joint",
                        m90.nn_cosine_joint,
                        m.nn_cosine_joint,
                        seed_spread(&modes, &style, step, JOINT)
                    ),
                    claim_less("NN-cos", m90.nn_cosine, m.nn_cosine, seed_spread(&modes, &style, step, NN)),
                    claim_less(
                        "SW",
                        m90.sliced_wasserstein,
                        m.sliced_wasserstein,
                        seed_spread(&modes, &style, step, SW)
                    )
                );
            }
            s.push('\n');
        }
    }
    let lam = study_rows(rows, records, Study::LambdaGc);
    for style in dedup(lam.iter().map(|(_, r)| r.style.clone())) {
        let _ = writeln!(s, "### λ_GC, style {style}\n");
        s.push_str(&table_header("λ_GC"));
        let mut by_weight = Vec::new();
        let mut step = 0;
        for (row, r) in lam.iter().filter(|(_, r)| r.style == style) {
            s.push_str(&table_row(&row.label, r, row.step));
            step = row.step;
            if let Some(c) = r.at(row.step) {
                by_weight.push((row.label.clone(), c.measures));
            }
        }
        if let (Some((l0, m0)), Some((l1, m1))) = (by_weight.first(), by_weight.last()) {
            let _ = writeln!(
                s,
                "\n- λ_GC = {l1} closer to the style than λ_GC = {l0}: {}; {}; {}\n",
                claim_less(
                    "NN joint",
                    m1.nn_cosine_joint,
                    m0.nn_cosine_joint,
                    seed_spread(&modes, &style, step, JOINT)
                ),
                claim_less("NN-cos", m1.nn_cosine, m0.nn_cosine, seed_spread(&modes, &style, step, NN)),
                claim_less("SW", m1.sliced_wasserstein, m0.sliced_wasserstein, seed_spread(&modes, &style, step, SW))
            );
        }
    }
    let res = study_rows(rows, records, Study::Resolution);
    if !res.is_empty() {
        let _ = writeln!(s, "## Working resolution\n");
        s.push_str(&table_header("resolution"));
        for (row, r) in &res {
            s.push_str(&table_row(&row.label, r, row.step));
        }
        s.push('\n');
    }

    let fast = study_rows(rows, records, Study::Fast);
    if !fast.is_empty() {
        let _ = writeln!(
            s,
            "## Fewer operations per step\n\nEach option at the ablation budget and at twice it: read the style distances at equal steps, and at equal time through the time column (preparation included). `exact, seed 1` is the noise floor.\n"
        );
        s.push_str(&table_header("setting @ steps"));
        for (row, r) in &fast {
            s.push_str(&table_row(&row.label, r, row.step));
        }
        s.push('\n');
    }

    let _ = writeln!(s, "## Stability\n");
    let stress = study_rows(rows, records, Study::Stress);
    if !stress.is_empty() {
        let _ = writeln!(
            s,
            "Settings pushed until they fail, all on the first curve style unless named; the detectors are those of `core/src/eval/stability.rs` with default thresholds.\n"
        );
        s.push_str(&table_header("setting"));
        for (row, r) in &stress {
            let label = if r.steps < r.budget {
                format!("{} (stopped at step {}: loss not finite)", row.label, r.steps)
            } else {
                row.label.clone()
            };
            s.push_str(&table_row(&label, r, row.step));
        }
        s.push('\n');
    }
    let pairs = study_rows(rows, records, Study::Pairs);
    if !pairs.is_empty() {
        let healthy = pairs.iter().filter(|(_, r)| r.stable).count();
        let _ = writeln!(
            s,
            "Decoupled default on every scene × style pair: **{healthy} of {} stable**. Cells: NN-cos at the end (of the colour-matched input), then NN depth at the end (of the input); ✓ stable, ✗ a detector fired.\n",
            pairs.len()
        );
        let scenes = dedup(pairs.iter().map(|(_, r)| r.scene_name()));
        let styles = dedup(pairs.iter().map(|(_, r)| r.style.clone()));
        let _ = writeln!(s, "| scene | {} |", styles.join(" | "));
        let _ = writeln!(s, "|---|{}", "---|".repeat(styles.len()));
        for scene in &scenes {
            let _ = write!(s, "| {scene} |");
            for style in &styles {
                let cell = pairs.iter().find(|(_, r)| &r.scene_name() == scene && &r.style == style).map_or(
                    "".into(),
                    |(row, r)| {
                        let end = r.at(row.step).map(|c| c.measures).unwrap_or_default();
                        let start = r.at(0).map(|c| c.measures).unwrap_or_default();
                        format!(
                            "{:.4} ({:.4}), {:.4} ({:.4}) {}",
                            end.nn_cosine,
                            start.nn_cosine,
                            end.nn_cosine_depth,
                            start.nn_cosine_depth,
                            if r.stable { "✓" } else { "✗" }
                        )
                    },
                );
                let _ = write!(s, " {cell} |");
            }
            s.push('\n');
        }
        for (_, r) in pairs.iter().filter(|(_, r)| !r.stable) {
            let _ = writeln!(s, "\n- {} × {}: {}", r.scene_name(), r.style, r.health());
        }
        s.push('\n');
    }

    let _ = writeln!(
        s,
        "## Sample renders\n\nEach: colour-matched input, result, input inverse depth, result inverse depth (first evaluation view, near = bright).\n"
    );
    for r in records {
        let _ = writeln!(
            s,
            "**{}** — {} × {}, {}, {} steps, {}\n\n![{}](renders/{}.png)\n",
            r.id,
            r.scene_name(),
            r.style,
            r.mode,
            r.steps,
            r.health(),
            r.id,
            r.id
        );
    }
    s
}
