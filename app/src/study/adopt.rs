//! Finished trials taken from other runs' journals (`gast bench quality
//! --from DIR`). A trial of this grid is taken from another run's
//! `trials.jsonl` when that run computed it the same way: the other grid's
//! sizes and studies equal this one's but for the scenes (a run of one scene
//! joins a run of three), the styles (a run of a few styles, or of one pair,
//! joins a run of nine: a trial computes its own style alone) and
//! `defaults_patch` (a candidate recipe's run takes the arms the patch leaves
//! alone: paper and its seed twin). A trial is known by its scene and its id
//! without the leading number (the number counts trials over the whole grid,
//! so it moves with the scenes and styles; the id names the arm and the
//! style); the taken record gets this grid's id and names the journal it
//! came from.

use std::collections::BTreeSet;
use std::path::Path;

use serde_json::Value;

use super::grid::Grid;
use super::journal::read;
use super::{DEFAULTS_NEW, Record, Study};

/// The keys of the sizes in which another grid may differ from this one.
const MAY_DIFFER: [&str; 3] = ["scenes", "styles", "defaults_patch"];

/// The records of `dir`'s journal that compute trials of `grid` (keyed
/// `key`, as [`super::journal::Journal::open`] takes it) not in `done`,
/// renamed to this grid's ids, with `from` set to the journal's path, each
/// beside its id in that run. An error names the journal and the sizes that
/// differ when its grid computes trials some other way.
pub fn take(
    key: &Value,
    grid: &Grid,
    scenes: &[String],
    dir: &Path,
    done: &BTreeSet<String>,
) -> anyhow::Result<Vec<(String, Record)>> {
    let (path, other, records) = read(dir)?;
    let differ = differences(key, &other);
    let bad: Vec<&String> = differ.iter().filter(|k| !MAY_DIFFER.contains(&k.as_str())).collect();
    if !bad.is_empty() {
        anyhow::bail!(
            "{}: its grid differs from this command's in {}; only the scenes, styles and defaults_patch may \
             differ for its trials to be taken",
            path.display(),
            bad.iter().map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ")
        );
    }
    // The patch changes the defaults study's candidate arm, and that arm alone.
    let patched: BTreeSet<&str> = if differ.iter().any(|k| k == "defaults_patch") {
        grid.rows
            .iter()
            .filter(|r| r.study == Study::Defaults && r.label == DEFAULTS_NEW)
            .map(|r| r.trial.as_str())
            .collect()
    } else {
        BTreeSet::new()
    };
    let from = path.display().to_string();
    let mut taken = Vec::new();
    let mut have = done.clone();
    for r in records {
        let Some(t) = grid
            .trials
            .iter()
            .find(|t| scenes.get(t.scene) == Some(&r.scene) && unnumbered(&t.id) == unnumbered(&r.id))
        else {
            continue;
        };
        if have.contains(&t.id) || patched.contains(t.id.as_str()) {
            continue;
        }
        have.insert(t.id.clone());
        taken.push((r.id.clone(), Record { id: t.id.clone(), from: Some(from.clone()), ..r }));
    }
    Ok(taken)
}

/// `id` without its leading number (`012-defaults-paper-stone` → `defaults-paper-stone`).
fn unnumbered(id: &str) -> &str {
    match id.split_once('-') {
        Some((n, rest)) if !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()) => rest,
        _ => id,
    }
}

/// The keys of `sizes` in which two grid keys differ, and `studies` when those do.
fn differences(a: &Value, b: &Value) -> Vec<String> {
    let empty = serde_json::Map::new();
    let sizes = |v: &Value| v.get("sizes").and_then(Value::as_object).unwrap_or(&empty).clone();
    let (sa, sb) = (sizes(a), sizes(b));
    let keys: BTreeSet<&String> = sa.keys().chain(sb.keys()).collect();
    let absent = Value::Null;
    let mut out: Vec<String> =
        keys.into_iter().filter(|k| sa.get(*k).unwrap_or(&absent) != sb.get(*k).unwrap_or(&absent)).cloned().collect();
    if a.get("studies") != b.get("studies") {
        out.push("studies".into());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::grid::build_grid;
    use crate::study::journal::Journal;
    use crate::study::{Sizes, test_record};
    use gast_core::eval::Measures;
    use serde_json::json;

    fn folder(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("gast-adopt-{name}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).expect("temp folder");
        dir
    }

    fn key(sizes: &Sizes) -> Value {
        json!({ "sizes": sizes, "studies": [Study::Defaults] })
    }

    /// A finished record of `grid`'s trial `id` on `scene`, its SW after
    /// `sw` so that the test can tell the records apart.
    fn finished(id: &str, scene: &str, sw: f32) -> Record {
        let m = |v| Measures { sliced_wasserstein: v, ..Measures::default() };
        Record { scene: scene.into(), ..test_record(id, "block2", m(5.0), m(sw)) }
    }

    /// Writes a journal of `records` for `sizes` into `dir`.
    fn journal(dir: &Path, sizes: &Sizes, records: &[Record]) {
        let (mut j, _) = Journal::open(dir, &key(sizes)).expect("journal");
        for r in records {
            j.push(r).expect("push");
        }
    }

    fn sizes(scenes: &[&str]) -> Sizes {
        Sizes {
            scenes: scenes.iter().map(|s| (*s).to_string()).collect(),
            styles: vec!["data/styles/block2.jpg".into(), "data/styles/wave.jpg".into()],
            ..Sizes::full()
        }
    }

    #[test]
    fn a_run_of_one_scene_gives_its_trials_to_the_grid_of_three_under_their_new_ids() {
        let (guitar, biker) = ("data/scenes/guitar.compressed.ply", "data/scenes/biker.compressed.ply");
        let one = sizes(&[biker]);
        let three = sizes(&[guitar, biker, "data/scenes/playbot-sog"]);
        let g1 = build_grid(&one, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let g3 = build_grid(&three, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let dir = folder("scenes");
        let records: Vec<Record> =
            g1.trials.iter().enumerate().map(|(k, t)| finished(&t.id, biker, 1.0 + k as f32)).collect();
        journal(&dir, &one, &records);
        let taken = take(&key(&three), &g3, &three.scenes, &dir, &BTreeSet::new()).expect("taken");
        // Every one of biker's trials, none of the other scenes'.
        assert_eq!(taken.len(), g1.trials.len());
        for ((other_id, r), t1) in taken.iter().zip(&g1.trials) {
            assert_eq!(other_id, &t1.id);
            let t3 = g3.trials.iter().find(|t| t.id == r.id).expect("a trial of the three-scene grid");
            assert_eq!((three.scenes[t3.scene].as_str(), unnumbered(&t3.id)), (biker, unnumbered(&t1.id)));
            assert_ne!(t3.id, t1.id, "the ids count over the three scenes");
            assert!(r.from.as_deref().is_some_and(|f| f.ends_with("trials.jsonl")), "{:?}", r.from);
        }
        // Measures travel with their trial.
        let first = g3.trials.iter().find(|t| t.scene == 1 && unnumbered(&t.id) == unnumbered(&g1.trials[0].id));
        let (_, r) = taken.iter().find(|(_, r)| r.id == first.expect("biker's first trial").id).expect("taken");
        assert_eq!(r.checkpoints.last().expect("checkpoint").measures.sliced_wasserstein, 1.0);
        // What this run has already finished is left alone.
        let done: BTreeSet<String> = taken.iter().take(2).map(|(_, r)| r.id.clone()).collect();
        let again = take(&key(&three), &g3, &three.scenes, &dir, &done).expect("taken");
        assert_eq!(again.len(), g1.trials.len() - 2);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_candidate_recipe_takes_paper_and_its_twin_but_not_the_defaults_arm() {
        let biker = "data/scenes/biker.compressed.ply";
        let plain = sizes(&[biker]);
        let patched = Sizes { defaults_patch: json!({ "weights": { "palette": 100 } }), ..plain.clone() };
        let g = build_grid(&plain, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let gp = build_grid(&patched, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let dir = folder("patch");
        journal(&dir, &plain, &g.trials.iter().map(|t| finished(&t.id, biker, 2.0)).collect::<Vec<_>>());
        let taken = take(&key(&patched), &gp, &patched.scenes, &dir, &BTreeSet::new()).expect("taken");
        let label = |id: &str| gp.rows.iter().find(|r| r.trial == id).map(|r| r.label.clone()).expect("row");
        let labels: BTreeSet<String> = taken.iter().map(|(_, r)| label(&r.id)).collect();
        assert!(!labels.contains(DEFAULTS_NEW), "{labels:?}");
        let arms = gp.rows.iter().filter(|r| r.label != DEFAULTS_NEW).count();
        assert_eq!(taken.len(), arms, "paper's arms and the seed twin: {labels:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_run_of_fewer_styles_gives_the_trials_of_its_styles() {
        let guitar = "data/scenes/guitar.compressed.ply";
        let nine = sizes(&[guitar]);
        // A run of wave alone: its seed twin is on wave, the nine's on block2 (their first styles).
        let one = Sizes { styles: vec!["data/styles/wave.jpg".into()], ..nine.clone() };
        let g1 = build_grid(&one, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let g9 = build_grid(&nine, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let dir = folder("styles");
        journal(&dir, &one, &g1.trials.iter().map(|t| finished(&t.id, guitar, 3.0)).collect::<Vec<_>>());
        let taken = take(&key(&nine), &g9, &nine.scenes, &dir, &BTreeSet::new()).expect("taken");
        let ids: BTreeSet<&str> = taken.iter().map(|(_, r)| unnumbered(&r.id)).collect();
        let wave: BTreeSet<&str> =
            g9.trials.iter().map(|t| unnumbered(&t.id)).filter(|id| id.ends_with("-wave")).collect();
        assert!(!wave.is_empty());
        assert_eq!(ids, wave, "wave's trials of the nine, not wave's seed twin");
        assert!(g1.trials.len() > taken.len(), "the one-style run's twin has no place among the nine's trials");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_grid_that_computes_otherwise_is_refused_with_what_differs() {
        let biker = "data/scenes/biker.compressed.ply";
        let here = sizes(&[biker]);
        let other = Sizes { eval_resolution: here.eval_resolution + 64, ..here.clone() };
        let g = build_grid(&here, Path::new("/shared"), &[Study::Defaults]).expect("grid");
        let dir = folder("refused");
        journal(&dir, &other, &[finished(&g.trials[0].id, biker, 2.0)]);
        let e = take(&key(&here), &g, &here.scenes, &dir, &BTreeSet::new()).expect_err("refused");
        let text = e.to_string();
        assert!(text.contains("eval_resolution") && text.contains("trials.jsonl"), "{text}");
        let empty = folder("none");
        let e = take(&key(&here), &g, &here.scenes, &empty, &BTreeSet::new()).expect_err("no journal");
        assert!(e.to_string().contains("trials.jsonl"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
        std::fs::remove_dir_all(&empty).ok();
    }
}
