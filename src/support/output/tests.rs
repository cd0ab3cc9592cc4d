//! The output folder's contract, one behaviour per test.

use super::manifest::{manifest_json, read_manifest, MARKER};
use super::*;
use crate::support::error::Error;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    // Kept: the test removes it when it is done.
    tempfile::Builder::new().prefix(&format!("blendsim-output-{name}-")).tempdir().unwrap().keep()
}

fn listing(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

fn bake(target: &Path, group: &str, files: &[(&str, &str)]) {
    let mut s = Staging::new(target).unwrap();
    s.set_group(group);
    for (n, text) in files {
        s.write(n, text.as_bytes()).unwrap();
    }
    s.commit().unwrap();
}

#[test]
fn atomic_write_replaces_and_leaves_no_temporaries() {
    let d = scratch("atomic");
    let f = d.join("a.txt");
    write_atomic(&f, b"one").unwrap();
    write_atomic(&f, b"two").unwrap();
    assert_eq!(std::fs::read(&f).unwrap(), b"two");
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
    // A temporary of a dead process is swept by the next write of that file.
    std::fs::write(d.join(".a.tmp-999999999-0.txt"), b"x").unwrap();
    write_atomic(&f, b"three").unwrap();
    assert_eq!(listing(&d), ["a.txt"]);
    let e = write_atomic(Path::new("/dev/null"), b"x").unwrap_err().to_string();
    assert!(e.contains("/dev/null: exists and is not a regular file"), "{e}");
    std::fs::create_dir(d.join("sub")).unwrap();
    assert!(write_atomic(&d.join("sub"), b"x").is_err());
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn atomic_write_with_keeps_the_extension_and_cleans_up_on_error() {
    let d = scratch("atomic-with");
    let f = d.join("a.usdc");
    write_atomic_with(&f, |tmp| {
        assert!(tmp.to_string_lossy().ends_with(".usdc") && tmp.parent() == Some(d.as_path()), "{}", tmp.display());
        std::fs::write(tmp, b"one").map_err(|e| Error::io(tmp, &e, "write"))
    })
    .unwrap();
    assert_eq!(std::fs::read(&f).unwrap(), b"one");
    let e = write_atomic_with(&f, |tmp| {
        std::fs::write(tmp, b"half").unwrap();
        Err(Error::general("failed midway", "none"))
    });
    assert!(e.is_err());
    assert_eq!(std::fs::read(&f).unwrap(), b"one", "the old file stays");
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "no temporary left");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn missing_parents_are_removed_after_a_failed_run() {
    let d = scratch("parents");
    let target = d.join("a/b/out");
    {
        let mut s = Staging::new(&target).unwrap();
        s.write("x.glb", b"glTF").unwrap();
    }
    assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0, "a failed run leaves nothing");
    bake(&target, "g", &[("x.glb", "glTF")]);
    assert_eq!(std::fs::read(target.join("x.glb")).unwrap(), b"glTF");
    assert_eq!(listing(&d.join("a/b")), ["out"], "no staging folder or lock left");
    assert_eq!(listing(&target), [MANIFEST, "x.glb"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn uncommitted_staging_leaves_the_old_folder_untouched() {
    let d = scratch("staging");
    let target = d.join("out");
    bake(&target, "g", &[("x.usda", "#usda 1.0")]);
    {
        let mut s = Staging::new(&target).unwrap();
        s.write("x.usda", b"#usda 1.0 new").unwrap();
        assert_eq!(listing(&d).len(), 3, "out, the lock and the staging folder");
    }
    assert_eq!(std::fs::read(target.join("x.usda")).unwrap(), b"#usda 1.0");
    assert_eq!(listing(&d), ["out"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_commit_removes_its_groups_stale_files_and_keeps_everything_else() {
    let d = scratch("groups");
    let target = d.join("out");
    bake(&target, "export:t", &[("t.usda", "a"), ("t.glb", "b"), ("t.outputs.json", "c")]);
    bake(&target, "report", &[("report.md", "r")]);
    std::fs::write(target.join("notes.txt"), "mine").unwrap();
    std::fs::create_dir_all(target.join("renders/deep")).unwrap();
    std::fs::write(target.join("renders/deep/f.png"), "png").unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink("notes.txt", target.join("link")).unwrap();
    use std::os::unix::fs::MetadataExt;
    let inode = std::fs::metadata(target.join("renders/deep/f.png")).unwrap().ino();
    // Fewer formats: t.usda goes, the report and the foreign files stay.
    bake(&target, "export:t", &[("t.glb", "B"), ("t.outputs.json", "C")]);
    assert_eq!(listing(&target), [MANIFEST, "link", "notes.txt", "renders", "report.md", "t.glb", "t.outputs.json"]);
    assert_eq!(std::fs::read_to_string(target.join("t.glb")).unwrap(), "B");
    assert_eq!(std::fs::read_to_string(target.join("notes.txt")).unwrap(), "mine");
    assert_eq!(std::fs::metadata(target.join("renders/deep/f.png")).unwrap().ino(), inode, "the same file, linked");
    assert_eq!(std::fs::read_link(target.join("link")).unwrap(), Path::new("notes.txt"));
    let manifest = read_manifest(&target);
    assert_eq!(manifest.keys().collect::<Vec<_>>(), ["report.md", "t.glb", "t.outputs.json"]);
    assert_eq!(manifest["report.md"], "report");
    assert_eq!(listing(&d), ["out"]);
    std::fs::remove_dir_all(&d).unwrap();
}

/// A run that replaces every group (a bake of a renamed scene) removes the earlier run's
/// files of every group and says which; files that are not blendsim's are kept and listed.
#[test]
fn a_commit_of_every_group_removes_every_earlier_file_it_does_not_write() {
    let d = scratch("every");
    let target = d.join("out");
    bake(&target, "export:old", &[("old.usda", "a"), ("old.glb", "b"), ("shared.png", "t")]);
    bake(&target, "summary", &[("summary.md", "s")]);
    std::fs::write(target.join("notes.txt"), "mine").unwrap();
    std::fs::create_dir(target.join("renders")).unwrap();
    let mut s = Staging::new(&target).unwrap();
    s.replace_every_group();
    s.set_group("export:new");
    s.write("new.glb", b"B").unwrap();
    s.write("shared.png", b"T").unwrap();
    s.set_group("report");
    s.write("report.md", b"r").unwrap();
    let summary = s.commit_with_summary().unwrap();
    assert_eq!(
        summary,
        Committed {
            removed: vec!["old.glb".into(), "old.usda".into(), "summary.md".into()],
            kept: vec!["notes.txt".into(), "renders".into()],
            written: vec!["new.glb".into(), "report.md".into(), "shared.png".into()]
        }
    );
    assert_eq!(
        summary.messages(Path::new("build/x"), "bake"),
        [
            "removed from build/x 3 files of an earlier run that this bake did not write again: old.glb, old.usda, summary.md",
            "kept in build/x 2 entries that blendsim did not write: notes.txt, renders"
        ]
    );
    assert_eq!(listing(&target), [MANIFEST, "new.glb", "notes.txt", "renders", "report.md", "shared.png"]);
    assert_eq!(read_manifest(&target).keys().collect::<Vec<_>>(), ["new.glb", "report.md", "shared.png"]);
    // Without it, a commit keeps the other groups (and has nothing of its own to remove).
    let mut s = Staging::new(&target).unwrap();
    s.set_group("export:other");
    s.write("other.glb", b"O").unwrap();
    let summary = s.commit_with_summary().unwrap();
    assert_eq!(summary.removed, Vec::<String>::new());
    assert!(Committed::default().messages(Path::new("x"), "bake").is_empty());
    let many = Committed { removed: vec![], kept: (0..7).map(|i| format!("f{i}")).chain(["bad\nname".into()]).collect(), written: vec![] };
    assert_eq!(many.messages(Path::new("x"), "bake"), ["kept in x 8 entries that blendsim did not write: f0, f1, f2, f3, f4 and 3 more"]);
    let one = Committed { removed: vec!["a\u{1b}[2J".into()], kept: vec![], written: vec![] };
    assert_eq!(one.messages(Path::new("x"), "bake"), ["removed from x 1 file of an earlier run that this bake did not write again: a\\u{1b}[2J"]);
    assert_eq!(listing(&target), [MANIFEST, "new.glb", "notes.txt", "other.glb", "renders", "report.md", "shared.png"]);
    std::fs::remove_dir_all(&d).unwrap();
}

/// A file written in pieces is staged and committed like a written one; a failed fill is
/// an error naming the file, and nothing of that run is committed.
#[test]
fn a_file_written_in_pieces_is_staged_like_any() {
    let d = scratch("pieces");
    let target = d.join("out");
    let mut s = Staging::new(&target).unwrap();
    s.write_with("big.usda", |f| (0..3).try_for_each(|i| f.write_all(format!("piece {i}\n").as_bytes()))).unwrap();
    s.commit().unwrap();
    assert_eq!(std::fs::read_to_string(target.join("big.usda")).unwrap(), "piece 0\npiece 1\npiece 2\n");
    assert_eq!(read_manifest(&target).keys().collect::<Vec<_>>(), ["big.usda"]);
    let mut s = Staging::new(&target).unwrap();
    let e = s.write_with("big.usda", |_| Err(std::io::Error::other("disk full"))).unwrap_err().to_string();
    assert!(e.contains("big.usda") && e.contains("disk full"), "{e}");
    drop(s);
    assert_eq!(std::fs::read_to_string(target.join("big.usda")).unwrap(), "piece 0\npiece 1\npiece 2\n");
    assert_eq!(listing(&d), ["out"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn what_a_killed_run_left_is_cleaned_and_foreign_files_given_back() {
    let d = scratch("stale");
    let target = d.join("out");
    bake(&target, "g", &[("x.glb", "old")]);
    // An incomplete staging folder (marker present): deleted.
    let incomplete = d.join(".out.blendsim-staging-999999999-0");
    std::fs::create_dir(&incomplete).unwrap();
    std::fs::write(incomplete.join(MARKER), "").unwrap();
    std::fs::write(incomplete.join("x.glb"), "partial").unwrap();
    // An old folder after a swap, holding a foreign file created during the commit.
    let old = d.join(".out.blendsim-old-999999999-1");
    std::fs::create_dir(&old).unwrap();
    std::fs::write(old.join(MANIFEST), manifest_json(&BTreeMap::from([("x.glb".into(), "g".into())]))).unwrap();
    std::fs::write(old.join("x.glb"), "older").unwrap();
    std::fs::write(old.join("late.txt"), "foreign").unwrap();
    // A staging folder of an older blendsim whose process is gone.
    std::fs::create_dir(target.join(".blendsim-staging-999999999-3")).unwrap();
    bake(&target, "g", &[("x.glb", "new")]);
    assert_eq!(listing(&d), ["out"]);
    assert_eq!(listing(&target), [MANIFEST, "late.txt", "x.glb"]);
    assert_eq!(std::fs::read_to_string(target.join("x.glb")).unwrap(), "new");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_fallback_commit_killed_between_its_renames_is_restored() {
    let d = scratch("fallback");
    let target = d.join("out");
    bake(&target, "g", &[("x.glb", "old")]);
    std::fs::rename(&target, d.join(".out.blendsim-old-999999999-0")).unwrap();
    let s = Staging::new(&target).unwrap();
    assert_eq!(std::fs::read_to_string(target.join("x.glb")).unwrap(), "old", "restored before anything else");
    drop(s);
    assert_eq!(listing(&d), ["out"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_busy_folder_fails_at_once_or_waits() {
    let d = scratch("busy");
    let target = d.join("out");
    let first = Staging::new(&target).unwrap();
    let e = Staging::open(&target, LockWait::Fail).unwrap_err().to_string();
    assert!(e.contains(&format!("another blendsim (pid {}) is writing into this output folder", std::process::id())), "{e}");
    let waiter = {
        let target = target.clone();
        std::thread::spawn(move || {
            let mut s = Staging::new(&target).unwrap();
            s.set_group("b");
            s.write("second", b"2").unwrap();
            s.commit().unwrap();
        })
    };
    std::thread::sleep(std::time::Duration::from_millis(100));
    assert!(!waiter.is_finished(), "the second run waits for the first");
    let mut first = first;
    first.set_group("a");
    first.write("first", b"1").unwrap();
    first.commit().unwrap();
    waiter.join().unwrap();
    assert_eq!(listing(&target), [MANIFEST, "first", "second"]);
    assert_eq!(listing(&d), ["out"]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn names_that_are_not_plain_never_leave_the_staging_folder() {
    let d = scratch("names");
    let target = d.join("out");
    let mut s = Staging::new(&target).unwrap();
    for bad in ["../x", "a/b", "..", ".", "", MANIFEST] {
        assert!(s.path(bad).starts_with(&s.dir), "{bad}");
        let e = s.write(bad, b"x").unwrap_err().to_string();
        assert!(e.contains("it is not a plain file name"), "{e}");
    }
    s.record("../escaped");
    assert!(s.commit().unwrap_err().to_string().contains("it is not a plain file name"));
    assert_eq!(listing(&d), Vec::<String>::new());
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_file_or_the_working_folder_is_refused() {
    let d = scratch("refused");
    std::fs::write(d.join("f"), "").unwrap();
    assert!(Staging::new(&d.join("f")).unwrap_err().to_string().contains("exists and is not a folder"));
    let cwd = std::env::current_dir().unwrap();
    assert!(Staging::new(&cwd).unwrap_err().to_string().contains("is the working folder or one of its parents"));
    std::fs::remove_dir_all(&d).unwrap();
}
