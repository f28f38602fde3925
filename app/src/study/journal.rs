//! The trials a run of `gast bench quality` has finished, one JSON line each
//! in `trials.jsonl` of its output folder, written as each trial ends: the
//! same command run again with the same `--out` reads them back and runs
//! only the rest, so a run stopped midway (a killed process, a machine
//! taken back) loses at most the trial it was in.

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::{Value, json};

use super::Record;

/// The journal's file name in the output folder.
pub const JOURNAL: &str = "trials.jsonl";

/// An open journal: its first line names the grid (sizes and studies), each
/// later line is one finished trial's [`Record`].
pub struct Journal {
    path: PathBuf,
    file: File,
}

impl Journal {
    /// Opens `dir/trials.jsonl` for the grid `key`, returning the trials it
    /// holds: none when the file is new; an error that names the file when it
    /// holds another grid's trials. A line that does not parse (a trial cut
    /// off while it was written) is dropped with a warning and its trial runs
    /// again.
    pub fn open(dir: &Path, key: &Value) -> anyhow::Result<(Self, Vec<Record>)> {
        let path = dir.join(JOURNAL);
        let header = json!({ "grid": key });
        let mut records = Vec::new();
        if path.exists() {
            let (found, first, read) = lines_of(&path)?;
            if found.as_ref() != Some(&header) {
                anyhow::bail!(
                    "{}: holds the trials of another grid (its first line should name this command's sizes and \
                     studies, found {}); give another --out, or remove the file to start this grid over",
                    path.display(),
                    match &first {
                        Some(_) if found.is_some() => "another grid's",
                        Some(l) if l.is_empty() => "an empty line",
                        Some(_) => "a line that is not JSON",
                        None => "an empty file",
                    }
                );
            }
            records = read;
        }
        // Rewritten whole (temporary file, then rename): the header and the
        // records that parsed, so a torn last line does not stay in the middle.
        let mut text = format!("{header}\n");
        for r in &records {
            text.push_str(&serde_json::to_string(r)?);
            text.push('\n');
        }
        gast_core::io::write_bytes(&path, text.as_bytes())?;
        let file = OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("could not append to {}", path.display()))?;
        Ok((Self { path, file }, records))
    }

    /// Appends `record`'s line and flushes it to the disk.
    pub fn push(&mut self, record: &Record) -> anyhow::Result<()> {
        let mut line = serde_json::to_string(record)?;
        line.push('\n');
        (self.file.write_all(line.as_bytes()))
            .and_then(|()| self.file.sync_data())
            .with_context(|| format!("could not append to {}", self.path.display()))
    }
}

/// Reads `dir/trials.jsonl` without changing it: the file's path, the grid
/// key its first line names, and its finished trials. An error names the
/// file when there is none or its first line names no grid.
pub fn read(dir: &Path) -> anyhow::Result<(PathBuf, Value, Vec<Record>)> {
    let path = dir.join(JOURNAL);
    if !path.is_file() {
        anyhow::bail!("{}: no such file (expected the journal of a `gast bench quality` run's folder)", path.display());
    }
    let (found, _, records) = lines_of(&path)?;
    match found.as_ref().and_then(|h| h.get("grid")) {
        Some(key) => Ok((path, key.clone(), records)),
        None => anyhow::bail!("{}: its first line names no grid (expected {{\"grid\": …}})", path.display()),
    }
}

/// The journal at `path`: its first line as JSON (when it is), that line,
/// and the later lines that parse as trials (a line that does not, a trial
/// cut off while it was written, is dropped with a warning).
fn lines_of(path: &Path) -> anyhow::Result<(Option<Value>, Option<String>, Vec<Record>)> {
    let reader = BufReader::new(File::open(path).with_context(|| format!("could not read {}", path.display()))?);
    let mut lines = reader.lines();
    let first = lines.next().transpose().with_context(|| format!("could not read {}", path.display()))?;
    let found: Option<Value> = first.as_deref().and_then(|l| serde_json::from_str(l).ok());
    let mut records = Vec::new();
    for (n, line) in lines.enumerate() {
        let line = line.with_context(|| format!("could not read {}", path.display()))?;
        match serde_json::from_str::<Record>(&line) {
            Ok(r) => records.push(r),
            Err(e) => {
                eprintln!("warning: {} line {}: not a finished trial ({e}); it runs again", path.display(), n + 2)
            }
        }
    }
    Ok((found, first, records))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::test_record;
    use gast_core::eval::Measures;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("gast-journal-{name}-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).expect("temp folder");
        dir
    }

    fn record(id: &str, sw: f32) -> Record {
        let m = |v| Measures { sliced_wasserstein: v, ..Measures::default() };
        test_record(id, "wave", m(5.0), m(sw))
    }

    #[test]
    fn the_same_grid_reads_back_every_finished_trial_in_order() {
        let dir = folder("resume");
        let key = json!({ "sizes": { "resolution": 64 }, "studies": ["defaults"] });
        let (mut journal, found) = Journal::open(&dir, &key).expect("new journal");
        assert!(found.is_empty());
        journal.push(&record("000-a", 4.0)).expect("push");
        journal.push(&record("001-b", 3.5)).expect("push");
        drop(journal);
        let (mut journal, found) = Journal::open(&dir, &key).expect("reopened");
        let read: Vec<(&str, f32)> =
            found.iter().map(|r| (r.id.as_str(), r.checkpoints[1].measures.sliced_wasserstein)).collect();
        assert_eq!(read, [("000-a", 4.0), ("001-b", 3.5)]);
        journal.push(&record("002-c", 3.0)).expect("push after resuming");
        drop(journal);
        let (_, found) = Journal::open(&dir, &key).expect("reopened twice");
        assert_eq!(found.iter().map(|r| r.id.as_str()).collect::<Vec<_>>(), ["000-a", "001-b", "002-c"]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn another_grid_is_refused_with_the_file_named_and_left_as_it_was() {
        let dir = folder("other");
        let (mut journal, _) = Journal::open(&dir, &json!({ "sizes": 1 })).expect("new journal");
        journal.push(&record("000-a", 4.0)).expect("push");
        drop(journal);
        let before = std::fs::read(dir.join(JOURNAL)).expect("journal");
        let e = format!("{:#}", Journal::open(&dir, &json!({ "sizes": 2 })).err().expect("another grid"));
        assert!(e.contains(JOURNAL) && e.contains("another grid") && e.contains("--out"), "{e}");
        assert_eq!(std::fs::read(dir.join(JOURNAL)).expect("journal"), before, "the refused file is kept");
        std::fs::write(dir.join(JOURNAL), "not json\n").expect("write");
        let e = format!("{:#}", Journal::open(&dir, &json!({ "sizes": 1 })).err().expect("not a journal"));
        assert!(e.contains("a line that is not JSON"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_trial_cut_off_while_written_is_dropped_and_runs_again() {
        let dir = folder("torn");
        let key = json!({ "sizes": 1 });
        let (mut journal, _) = Journal::open(&dir, &key).expect("new journal");
        journal.push(&record("000-a", 4.0)).expect("push");
        drop(journal);
        let path = dir.join(JOURNAL);
        let whole = serde_json::to_string(&record("001-b", 3.5)).expect("json");
        let mut text = std::fs::read_to_string(&path).expect("journal");
        text.push_str(&whole[..whole.len() / 2]);
        std::fs::write(&path, text).expect("torn line");
        let (mut journal, found) = Journal::open(&dir, &key).expect("reopened");
        assert_eq!(found.iter().map(|r| r.id.as_str()).collect::<Vec<_>>(), ["000-a"]);
        journal.push(&record("001-b", 3.5)).expect("the trial again");
        drop(journal);
        let lines = std::fs::read_to_string(&path).expect("journal").lines().count();
        assert_eq!(lines, 3, "the header and two whole trials, no torn line between them");
        std::fs::remove_dir_all(&dir).ok();
    }
}
