//! README's main job, as README writes it: the HPPA grid replayed over the
//! validation trace through the grid observer the firmware flashes, at 1 ms ticks.
//! The distribution of the library tick's time is printed (run with
//! `--nocapture` to see it) and never asserted: CI machines are shared.

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;
use tempfile::TempDir;

/// The arguments after `--` of README's `cargo run ... --bin coil-thermal --
/// replay ...` line (the first command under "Two commands").
fn readme_main_job() -> Vec<String> {
    let readme = include_str!("../../README.md");
    let section = readme
        .split("## Two commands for a fresh machine")
        .nth(1)
        .expect("README has the two commands");
    let line = section
        .lines()
        .find(|l| l.starts_with("cargo run") && l.contains("--bin coil-thermal --"))
        .expect("README's main job is a `cargo run --bin coil-thermal` line");
    assert!(
        section.contains("cargo test --workspace --release"),
        "README's test command"
    );
    line.split(" -- ")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .map(str::to_string)
        .collect()
}

#[test]
fn readme_main_job_replays_through_the_flashed_grid_observer_and_times_each_tick() {
    let tmp = TempDir::new().unwrap();
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let mut args = readme_main_job();
    assert_eq!(args[0], "replay");
    // Outputs into a temporary directory; inputs relative to the root.
    for (flag, name) in [("--out", "replay.csv"), ("--plot", "replay.png")] {
        let k = args.iter().position(|a| a == flag).unwrap();
        args[k + 1] = tmp.path().join(name).display().to_string();
    }
    let out = cargo_bin_cmd!("coil-thermal")
        .current_dir(root)
        .args(&args)
        .arg("--json")
        .assert()
        .success();
    let j: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    // The grid observer the firmware flashes (`observer_m4`), not a
    // network observer over the grid.
    assert_eq!(j["estimator"], "grid-observer");
    assert_eq!(j["model"], "hppa-7x12");
    let t = &j["step_time"];
    assert_eq!(t["step"], "library tick");
    // 300 s of trace, every 1 ms tick timed.
    assert_eq!(t["steps"], 300_000);
    assert_eq!(t["budget_ns"], 100_000.0);
    let us = |k: &str| t[k].as_f64().unwrap() * 1e-3;
    assert!(us("min_ns") > 0.0);
    assert!(us("min_ns") <= us("p50_ns") && us("p50_ns") <= us("p99_ns"));
    assert!(us("p99_ns") <= us("max_ns"));
    eprintln!(
        "main job: library tick [us] min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 {:.3} of the 0.1 ms budget",
        us("min_ns"),
        us("p50_ns"),
        us("p99_ns"),
        us("max_ns"),
        t["p99_over_budget"].as_f64().unwrap()
    );
    assert!(tmp.path().join("replay.csv").exists());
    assert!(tmp.path().join("replay.png").exists());
}
