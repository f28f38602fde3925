//! `gast bench quality --quick` end to end on the shared guitar and two styles:
//! every trial measured, the tables, charts, renders and index written and
//! linked, and the invariants of the ablation modes visible in the numbers.

use std::path::{Path, PathBuf};
use std::process::Command;

use gast_tests::{shared_dir, shared_file};
use serde_json::Value;

fn number(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

#[test]
fn quick_quality_benchmark_writes_a_complete_linked_report() {
    if shared_file("data/scenes/guitar.compressed.ply").is_none()
        || shared_file("data/weights/vgg19-conv3.safetensors").is_none()
    {
        return;
    }
    let out: PathBuf = std::env::temp_dir().join(format!("gast-quality-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    // `gast bench quality --quick --out OUT`, which must succeed: its stdout.
    let run_quick = |what: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_gast"))
            .args(["bench", "quality", "--quick", "--out"])
            .arg(&out)
            .env("GAST_SHARED", shared_dir())
            .output()
            .expect("run gast");
        let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(o.status.success(), "{what} failed:\n{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
        stdout
    };
    run_quick("bench quality");

    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("results.json")).expect("json");
    let trials = json["trials"].as_array().expect("trials");
    let rows = json["rows"].as_array().expect("rows");
    assert!(trials.len() >= 20, "{} trials", trials.len());
    let mut checkpoints = 0;
    for t in trials {
        let id = t["id"].as_str().expect("id");
        let cps = t["checkpoints"].as_array().expect("checkpoints");
        checkpoints += cps.len();
        assert_eq!(cps[0]["step"], 0, "{id}: the colour-matched input is measured first");
        assert_eq!(number(&cps[cps.len() - 1], "step"), number(t, "steps"), "{id}: the final scene is measured");
        for c in cps {
            for (k, v) in c["measures"].as_object().expect("measures") {
                let v = v.as_f64().unwrap_or(f64::NAN);
                assert!(v.is_finite() && v >= 0.0, "{id}: {k} = {v}");
            }
        }
        assert!(out.join(format!("renders/{id}.png")).exists(), "{id}: no sample render");
    }
    for r in rows {
        let trial = r["trial"].as_str().expect("row trial");
        let t = trials.iter().find(|t| t["id"] == trial).unwrap_or_else(|| panic!("row {r} names no trial"));
        assert!(t["checkpoints"].as_array().expect("cps").iter().any(|c| c["step"] == r["step"]), "row {r}");
    }

    // What each mode may change shows in the numbers: colour-only steps leave
    // the geometry exactly as it was; geometry-bearing modes move it.
    let mode_final = |mode: &str| {
        let t = trials
            .iter()
            .find(|t| t["id"].as_str().is_some_and(|id| id.contains("-modes-")) && t["mode"] == mode)
            .unwrap_or_else(|| panic!("no {mode} trial"));
        t["checkpoints"].as_array().and_then(|c| c.last()).expect("final")["measures"].clone()
    };
    let colour = mode_final("colour-only");
    let colour_input = trials
        .iter()
        .find(|t| t["id"].as_str().is_some_and(|id| id.contains("-modes-")) && t["mode"] == "colour-only")
        .map(|t| t["checkpoints"][0]["measures"].clone())
        .expect("colour-only input");
    assert_eq!(number(&colour, "nn_cosine_depth"), number(&colour_input, "nn_cosine_depth"), "depth untouched");
    assert_eq!(number(&colour, "depth_change"), 0.0);
    assert_eq!(number(&colour, "normal_change_degrees"), 0.0);
    for mode in ["decoupled", "joint", "geometry-only"] {
        assert!(number(&mode_final(mode), "depth_change") > 0.0, "{mode} moved no geometry");
    }
    // The decoupled default is stable on every scene × style pair.
    for t in trials.iter().filter(|t| t["id"].as_str().is_some_and(|id| id.contains("-pairs-"))) {
        assert_eq!(t["stable"], true, "{t}");
    }

    let csv = std::fs::read_to_string(out.join("results.csv")).expect("results.csv");
    assert_eq!(csv.lines().count(), checkpoints + 1, "one CSV line per trial and checkpoint plus the header");
    assert!(csv.lines().next().is_some_and(|h| h.contains("sliced_wasserstein") && h.contains("stable")));

    for stem in [
        "sw_vs_time_wave",
        "sw_vs_iterations_wave",
        "nn_vs_time_wave",
        "nn_vs_iterations_wave",
        "nn_joint_vs_iterations_wave",
        "resolution_tradeoff",
        "ratio_style",
        "ratio_geometry",
    ] {
        let png = image::open(out.join(format!("charts/{stem}.png"))).expect("chart png").to_rgb8();
        let first = png.get_pixel(0, 0);
        assert!(png.pixels().any(|p| p != first), "{stem}.png is blank");
        let svg = std::fs::read_to_string(out.join(format!("charts/{stem}.svg"))).expect("chart svg");
        assert!(svg.starts_with("<svg") || svg.starts_with("<?xml"), "{stem}.svg");
        assert!(svg.contains("</svg>"));
    }
    let sw_time = std::fs::read_to_string(out.join("charts/sw_vs_time_wave.svg")).expect("svg");
    for name in ["decoupled", "joint", "colour-only", "geometry-only", "wall time (s)"] {
        assert!(sw_time.contains(name), "the time chart lacks {name}");
    }

    let index = std::fs::read_to_string(out.join("index.md")).expect("index.md");
    // The header gives the resolutions the trials ran, not the grid's default alone.
    let res: Vec<u64> = trials.iter().map(|t| t["resolution"].as_u64().expect("resolution")).collect();
    let (lo, hi) = (res.iter().min().expect("a trial"), res.iter().max().expect("a trial"));
    let ran = if lo == hi { format!("Optimisation at {lo} px") } else { format!("Optimisation at {lo}–{hi} px") };
    assert!(index.contains(&ran), "index.md does not say {ran}");
    for heading in ["Optimisation strategy", "N_g ratio", "λ_GC", "Stability", "Sample renders"] {
        assert!(index.contains(heading), "index.md lacks {heading}");
    }
    for link in links(&index) {
        assert!(out.join(&link).exists(), "index.md links {link}, which is absent");
    }

    // The report can be redrawn from results.json alone.
    std::fs::remove_file(out.join("index.md")).expect("remove index");
    let o = Command::new(env!("CARGO_BIN_EXE_gast"))
        .args(["bench", "quality", "--report"])
        .arg(&out)
        .output()
        .expect("run gast");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read_to_string(out.join("index.md")).expect("redrawn index"), index);

    // A stopped run resumes: with its shortest trial taken out of the journal
    // (as if the run had stopped in it), the same command runs that trial
    // alone and reports every trial again, the rerun one with the same measures.
    let journal = std::fs::read_to_string(out.join("trials.jsonl")).expect("trials.jsonl");
    let lines: Vec<&str> = journal.lines().collect();
    assert_eq!(lines.len(), trials.len() + 1, "the grid's line, then one line a trial");
    let (cut, _) = (lines.iter().enumerate().skip(1))
        .min_by_key(|(_, l)| {
            serde_json::from_str::<Value>(l).map_or(u64::MAX, |t| t["steps"].as_u64().unwrap_or(u64::MAX))
        })
        .expect("a trial");
    let kept: String = lines.iter().enumerate().filter(|(k, _)| *k != cut).map(|(_, l)| format!("{l}\n")).collect();
    std::fs::write(out.join("trials.jsonl"), kept).expect("journal without one trial");
    let before: Value = serde_json::from_str(lines[cut]).expect("the cut trial");
    let stdout = run_quick("the resumed run");
    let resumed = format!("resuming: {} of {} trials already finished", trials.len() - 1, trials.len());
    assert!(stdout.contains("quality benchmark: 1 trials") && stdout.contains(&resumed), "{stdout}");
    let again: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).expect("results.json")).expect("json");
    let again = again["trials"].as_array().expect("trials");
    assert_eq!(again.len(), trials.len(), "every trial is reported after resuming");
    let after = again.iter().find(|t| t["id"] == before["id"]).expect("the rerun trial");
    let measures = |t: &Value| -> Vec<(u64, String, f64)> {
        let mut all = Vec::new();
        for c in t["checkpoints"].as_array().expect("checkpoints") {
            for (k, v) in c["measures"].as_object().expect("measures") {
                all.push((c["step"].as_u64().expect("step"), k.clone(), v.as_f64().unwrap_or(f64::NAN)));
            }
        }
        all
    };
    assert_eq!(measures(&before).len(), measures(after).len());
    for ((step, k, a), (_, _, b)) in measures(&before).into_iter().zip(measures(after)) {
        assert!((a - b).abs() <= 1e-4 * a.abs().max(1e-3), "{}: {k} at step {step}: {a} then {b}", before["id"]);
    }
    assert!(out.join(format!("renders/{}.png", before["id"].as_str().expect("id"))).exists());
    let _ = std::fs::remove_dir_all(&out);
}

/// Relative targets of the Markdown links and images of `md`.
fn links(md: &str) -> Vec<String> {
    md.split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .filter(|l| !l.contains("://"))
        .map(|l| Path::new(l).to_string_lossy().into_owned())
        .collect()
}
