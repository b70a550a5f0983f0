//! `holo dataset --shard I/N`, `--shard auto` and `--merge` (docs/DATASET.md, "On many machines"): parts
//! written by concurrent processes equal a one-process run byte for byte; an interrupted run resumes with
//! the shards it had finished; a merge with a missing or foreign shard names it and writes nothing.

mod common;

use common::{holo, stderr};

use std::path::Path;
use std::process::{Command, Output, Stdio};

const SHARDS: [&str; 6] = [
    "train-00000.npz",
    "train-00001.npz",
    "train-00002.npz",
    "val-00000.npz",
    "val-00001.npz",
    "test-00000.npz",
];

/// 6 train, 3 val, 2 test samples of `size`² with `levels` planes, in shards of 2: 3 + 2 + 1 = 6 shards.
fn config(size: &'static str, levels: &'static str) -> [&'static str; 14] {
    [
        "--train",
        "6",
        "--val",
        "3",
        "--test",
        "2",
        "--size",
        size,
        "--levels",
        levels,
        "--shard-size",
        "2",
        "--previews",
        "0",
    ]
}

/// The quick dataset: 24×24, 12 planes.
const CONFIG: (&str, &str) = ("24", "12");

/// As `CONFIG`, with samples slow enough (96×96, 512 planes: about 0.1 s each) to kill a run half-way.
const SLOW_CONFIG: (&str, &str) = ("96", "512");

fn dataset_args<'a>(out: &'a Path, extra: &[&'a str]) -> Vec<&'a str> {
    config_args(CONFIG, out, extra)
}

fn config_args<'a>(
    (size, levels): (&'static str, &'static str),
    out: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec!["dataset"];
    args.extend_from_slice(&config(size, levels));
    args.extend_from_slice(&["--threads=1", "--out", out.to_str().unwrap()]);
    args.extend_from_slice(extra);
    args
}

fn run(out: &Path, extra: &[&str]) -> Output {
    holo(&dataset_args(out, extra))
}

fn manifest(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap()
}

/// The manifest less what differs between runs of one dataset: when, by which command line, timings.
fn content(dir: &Path) -> serde_json::Value {
    let mut m = manifest(dir);
    m["created_unix_s"] = serde_json::Value::Null;
    m["generator"]["command"] = serde_json::Value::Null;
    for k in ["mean_sample_seconds", "wall_seconds", "threads"] {
        m["statistics"][k] = serde_json::Value::Null;
    }
    m
}

#[test]
fn two_concurrent_parts_then_merge_equal_a_one_process_run() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one");
    let o = run(&one, &[]);
    assert!(o.status.success(), "{}", stderr(&o));

    let parts = dir.path().join("parts");
    let spawn = |part: &str| {
        Command::new(env!("CARGO_BIN_EXE_holo"))
            .args(dataset_args(&parts, &["--shard", part]))
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn("0/2"), spawn("1/2"));
    for child in [a, b] {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
    // Part 0 wrote shards 0, 2, 4 and part 1 shards 1, 3, 5; neither wrote a manifest.
    assert!(!parts.join("manifest.json").exists());
    for (j, file) in SHARDS.iter().enumerate() {
        let record: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(parts.join(format!("{file}.shard.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(record["ordinal"], j, "{file}");
        assert_eq!(record["selection"]["index"], j % 2, "{file}");
    }
    merge_and_compare(&one, &parts);
    assert_eq!(manifest(&parts)["statistics"]["samples"], 11);

    // Three parts through the Slurm and Kubernetes variables give the same shards too.
    let auto = dir.path().join("auto");
    for (i, env) in [
        (
            0,
            vec![
                ("SLURM_ARRAY_TASK_ID", "4"),
                ("SLURM_ARRAY_TASK_MIN", "4"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ],
        ),
        (
            1,
            vec![
                ("SLURM_ARRAY_TASK_ID", "5"),
                ("SLURM_ARRAY_TASK_MIN", "4"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ],
        ),
        (2, vec![("JOB_COMPLETION_INDEX", "2")]),
    ] {
        let mut extra = vec!["--shard", "auto"];
        if i == 2 {
            extra.extend(["--shard-count", "3"]);
        }
        let o = Command::new(env!("CARGO_BIN_EXE_holo"))
            .args(dataset_args(&auto, &extra))
            .env("RUST_LOG", "warn")
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .envs(env)
            .output()
            .unwrap();
        assert!(o.status.success(), "part {i}: {}", stderr(&o));
    }
    merge_and_compare(&one, &auto);
}

/// `holo dataset --merge` in `parts`, then every shard and the manifest's content equal the one-process run's.
fn merge_and_compare(one: &Path, parts: &Path) {
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    for file in SHARDS {
        assert_eq!(
            std::fs::read(one.join(file)).unwrap(),
            std::fs::read(parts.join(file)).unwrap(),
            "{file} differs between the one-process run and {}",
            parts.display()
        );
    }
    assert_eq!(content(one), content(parts));
}

#[test]
fn a_merge_with_a_missing_or_foreign_shard_names_it_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("parts");
    // Only part 1 of 3 ran: shards 1 and 4 are there.
    let o = run(&parts, &["--shard", "1/3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    for missing in [
        "train-00000.npz",
        "train-00002.npz",
        "val-00000.npz",
        "test-00000.npz",
    ] {
        assert!(e.contains(missing), "{missing}: {e}");
    }
    assert!(e.contains("misses 4 of 6 shards"), "{e}");
    // The exact commands that write them: parts 0 and 2 of 3.
    assert!(
        e.contains("--shard 0/3") && e.contains("--shard 2/3"),
        "{e}"
    );
    assert!(!e.contains("--shard 1/3"), "{e}");
    assert!(!parts.join("manifest.json").exists());

    // Running the named parts completes it.
    for part in ["0/3", "2/3"] {
        let o = run(&parts, &["--shard", part]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A rerun of the merge replaces its own manifest; a hand-edited one only with --force.
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let path = parts.join("manifest.json");
    let edited = std::fs::read_to_string(&path).unwrap().replacen(
        "\"seed\": 1,",
        "\"seed\": 1, \"note\": \"checked by hand\",",
        1,
    );
    assert!(edited.contains("checked by hand"));
    std::fs::write(&path, &edited).unwrap();
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("manifest.json") && e.contains("--force"), "{e}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), edited);
    let o = holo(&[
        "dataset",
        "--merge",
        "--force",
        "--out",
        parts.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!std::fs::read_to_string(&path)
        .unwrap()
        .contains("checked by hand"));
    std::fs::remove_file(&path).unwrap();

    // A shard of another configuration (another seed) copied in: named, with the key that differs.
    let other = dir.path().join("other");
    let o = run(&other, &["--seed", "9", "--shard", "1/3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for suffix in ["", ".shard.json"] {
        std::fs::copy(
            other.join(format!("val-00001.npz{suffix}")),
            parts.join(format!("val-00001.npz{suffix}")),
        )
        .unwrap();
    }
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("val-00001.npz") && e.contains("seed: 9 here, 1 in the others"),
        "{e}"
    );
    assert!(!parts.join("manifest.json").exists());

    // A truncated shard is not complete: named as missing.
    let o = run(&parts, &["--shard", "1/3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let file = parts.join("train-00001.npz");
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() / 2]).unwrap();
    let o = holo(&["dataset", "--merge", "--out", parts.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("misses 1 of 6 shards: train-00001.npz"),
        "{}",
        stderr(&o)
    );
    // ... and the part that owns it rewrites only that one.
    let o = run(&parts, &["--shard", "1/3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&file).unwrap(), bytes);

    // Bad parts are refused before anything is written.
    for (shard, want) in [
        ("3/3", "parts are numbered 0 to 2"),
        ("0/0", "at least 1"),
        ("1", "expected I/N"),
        ("auto", "neither a Slurm job array"),
    ] {
        let out = dir.path().join(format!("bad{}", shard.replace('/', "_")));
        let o = Command::new(env!("CARGO_BIN_EXE_holo"))
            .args(dataset_args(&out, &["--shard", shard]))
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        assert!(!o.status.success(), "{shard}");
        assert!(stderr(&o).contains(want), "{shard}: {}", stderr(&o));
        assert!(!out.exists(), "{shard}");
    }
    // A job array's bad variables are named, a step of 0 refused.
    for (vars, want) in [
        (
            &[("SLURM_ARRAY_TASK_ID", "1"), ("SLURM_ARRAY_TASK_STEP", "0")][..],
            "SLURM_ARRAY_TASK_STEP=0",
        ),
        (&[("SLURM_ARRAY_TASK_ID", "one")][..], "SLURM_ARRAY_TASK_ID"),
        (
            &[("JOB_COMPLETION_INDEX", "-2")][..],
            "JOB_COMPLETION_INDEX",
        ),
    ] {
        let out = dir.path().join("bad_env");
        let o = Command::new(env!("CARGO_BIN_EXE_holo"))
            .args(dataset_args(
                &out,
                &["--shard", "auto", "--shard-count", "3"],
            ))
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .envs(vars.iter().copied())
            .output()
            .unwrap();
        assert!(!o.status.success(), "{vars:?}");
        assert!(stderr(&o).contains(want), "{vars:?}: {}", stderr(&o));
        assert!(!out.exists(), "{vars:?}");
    }
}

#[cfg(unix)]
#[test]
fn a_killed_run_resumes_with_the_shards_it_had_finished() {
    let dir = tempfile::tempdir().unwrap();
    let reference = dir.path().join("reference");
    let o = holo(&config_args(SLOW_CONFIG, &reference, &[]));
    assert!(o.status.success(), "{}", stderr(&o));

    // kill -9 once the first shard's record is there (shards are written while the next ones compute).
    let out = dir.path().join("killed");
    let mut child = Command::new(env!("CARGO_BIN_EXE_holo"))
        .args(config_args(SLOW_CONFIG, &out, &[]))
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let first = out.join("train-00000.npz.shard.json");
    let t = std::time::Instant::now();
    while !first.exists() && t.elapsed().as_secs() < 120 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().ok(); // SIGKILL
    child.wait().unwrap();
    let finished: Vec<(&str, std::time::SystemTime)> = SHARDS
        .iter()
        .filter(|f| out.join(format!("{f}.shard.json")).exists())
        .map(|f| {
            (
                *f,
                std::fs::metadata(out.join(f)).unwrap().modified().unwrap(),
            )
        })
        .collect();
    assert!(!finished.is_empty());
    assert!(
        finished.len() < SHARDS.len(),
        "the run finished before the kill: nothing left to resume"
    );
    // Make a partial shard the rerun must replace: a shard without its record.
    let unfinished = SHARDS
        .iter()
        .find(|f| !out.join(format!("{f}.shard.json")).exists());
    if let Some(f) = unfinished {
        std::fs::write(out.join(f), b"partial").unwrap();
    }
    // A run that finished before the kill has its manifest: what it must not do is rewrite finished shards.
    let _ = std::fs::remove_file(out.join("manifest.json"));
    std::thread::sleep(std::time::Duration::from_millis(20));

    let o = holo(&config_args(SLOW_CONFIG, &out, &[]));
    assert!(o.status.success(), "{}", stderr(&o));
    // The finished shards were kept as they were, and everything equals the uninterrupted run.
    for (f, modified) in &finished {
        assert_eq!(
            std::fs::metadata(out.join(f)).unwrap().modified().unwrap(),
            *modified,
            "{f} was rewritten"
        );
    }
    for file in SHARDS {
        assert_eq!(
            std::fs::read(reference.join(file)).unwrap(),
            std::fs::read(out.join(file)).unwrap(),
            "{file}"
        );
    }
    assert_eq!(content(&reference), content(&out));
}
