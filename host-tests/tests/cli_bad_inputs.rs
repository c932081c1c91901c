//! Issue 19's bad inputs: every one that used to hang, abort (an 80 TB
//! allocation) or pass a NaN or an absurd temperature as a result with exit
//! 0 now ends quickly with a non-zero exit and an error that says what to
//! change. Each test names the case.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;

use assert_cmd::cargo::cargo_bin_cmd;
use predicates::str::contains;
use serde_json::Value;
use tempfile::TempDir;

/// No bad input may take longer than this (each used to hang or abort).
const BOUND: Duration = Duration::from_secs(60);

fn ct() -> assert_cmd::Command {
    let mut c = cargo_bin_cmd!("coil-thermal");
    c.timeout(BOUND);
    c
}

fn model() -> String {
    format!("{}/models/two-node-coil.toml", env!("CARGO_MANIFEST_DIR"))
}

fn write(dir: &TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    fs::write(&p, text).unwrap();
    p
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The two-node coil with one line of its model file replaced.
fn model_with(dir: &TempDir, name: &str, from: &str, to: &str) -> PathBuf {
    let text = fs::read_to_string(model()).unwrap();
    assert!(text.contains(from), "{from}");
    write(dir, name, &text.replace(from, to))
}

/// 101 rows, 1 s apart, at `current_a`.
fn steady_trace(dir: &TempDir, current_a: f64) -> PathBuf {
    let mut text = String::from("time_s,current\n");
    for k in 0..=100 {
        text.push_str(&format!("{k},{current_a}\n"));
    }
    write(dir, "steady.csv", &text)
}

/// The command fails, within [`BOUND`], with every one of `needles` in
/// its error and nothing on stdout.
fn refused(cmd: &mut assert_cmd::Command, needles: &[&str]) {
    let mut a = cmd.assert().failure().code(1).stdout("");
    for n in needles {
        a = a.stderr(contains(*n));
    }
}

#[test]
fn a_row_at_1e300_s_is_refused_at_its_line_not_stepped_for_ever() {
    let dir = TempDir::new().unwrap();
    let trace = write(&dir, "far.csv", "time_s,current\n0,1\n1,1\n1e300,1\n");
    for cmd in ["simulate", "replay"] {
        refused(
            ct().args([cmd, "--model", &model(), "--trace", s(&trace)])
                .args(["--out", s(&dir.path().join("o.csv"))]),
            &["far.csv:4:1", "1e300 s", "at most 1e8 s", "a typo?"],
        );
    }
}

#[test]
fn a_stiff_model_is_refused_before_it_runs_naming_the_parameters() {
    let dir = TempDir::new().unwrap();
    let trace = steady_trace(&dir, 2.0);
    for (name, from, to) in [
        (
            "tiny_c.toml",
            "capacity_j_per_k = 200.0",
            "capacity_j_per_k = 1e-12",
        ),
        ("huge_g.toml", "g_w_per_k = 1.5", "g_w_per_k = 1e15"),
    ] {
        let m = model_with(&dir, name, from, to);
        refused(
            ct().args(["simulate", "--model", s(&m), "--trace", s(&trace)])
                .args(["--out", s(&dir.path().join("o.csv"))]),
            &[
                "internal steps",
                "at most 2e8",
                "capacity_j_per_k",
                "g_w_per_k",
            ],
        );
        refused(
            ct().args(["calibrate", "--model", s(&m), "--trace", s(&trace)])
                .args(["--measure", "current=coil", "--params", "capacity.coil"])
                .args(["--out", s(&dir.path().join("f.toml"))]),
            &["steady.csv", "internal steps", "stable step"],
        );
    }
}

#[test]
fn huge_output_periods_and_durations_are_refused_before_allocating() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("o.csv");
    // 1e300 s in 101 rows of 1e298 s: few rows, astronomically many steps.
    refused(
        ct().args(["simulate", "--model", &model(), "--current-a", "1"])
            .args(["--duration-s", "1e300", "--dt-s", "1e298", "--out", s(&out)]),
        &["internal steps", "widest gap 1.000e298 s"],
    );
    // These asked for an 80 TB allocation (exit 134).
    for (duration, dt) in [("10", "1e-12"), ("1e12", "1")] {
        refused(
            ct().args(["simulate", "--model", &model(), "--current-a", "1"])
                .args(["--duration-s", duration, "--dt-s", dt, "--out", s(&out)]),
            &["output rows", "at most 20000000 rows", "raise --dt-s"],
        );
    }
    let trace = steady_trace(&dir, 1.0);
    refused(
        ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
            .args(["--resample-s", "1e-9", "--out", s(&out)]),
        &["--resample-s 1e-9 s", "1.000e11 rows", "raise --resample-s"],
    );
    assert!(!out.exists(), "nothing written");
}

#[test]
fn a_plot_of_values_no_axis_can_span_is_refused() {
    let dir = TempDir::new().unwrap();
    let est = write(&dir, "est.csv", "time_s,coil\n0,1e308\n1,-1e308\n");
    refused(
        ct().args(["plot", "--estimate", s(&est)])
            .args(["--out", s(&dir.path().join("p.png"))]),
        &["series `coil` holds 1e308 at t = 0 s", "a runaway?"],
    );
}

#[test]
fn a_run_that_goes_non_finite_or_absurd_exits_non_zero_naming_node_time_and_cause() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("o.csv");
    // All NaN at 1e4 A; it printed "hot spot 20.000 degC" and exit 0.
    refused(
        ct().args(["simulate", "--model", "omnimagnet", "--current-a", "1e4"])
            .args(["--duration-s", "100", "--out", s(&out)]),
        &[
            "model `omnimagnet` ran away",
            "is NaN degC at t = 1 s",
            "runaway current",
        ],
    );
    // A steep alpha_per_k: thermal runaway (alpha 0.5 at 3 A printed
    // 61486402 degC, exit 0). 0.013 1/K keeps R above 0 down to -55 degC,
    // which a model file must (0.5 is refused at load: R = 0 at 18 degC),
    // and 30 A runs away within the replay's 100 s.
    let alpha = model_with(
        &dir,
        "alpha.toml",
        "alpha_per_k = 0.0039",
        "alpha_per_k = 0.013",
    );
    refused(
        ct().args(["simulate", "--model", s(&alpha), "--current-a", "30"])
            .args(["--duration-s", "3600", "--out", s(&out)]),
        &[
            "ran away: node `coil`",
            "alpha_per_k",
            "no result is written",
        ],
    );
    assert!(!out.exists(), "no result is written");
    let trace = steady_trace(&dir, 30.0);
    refused(
        ct().args(["replay", "--model", s(&alpha), "--trace", s(&trace)]),
        &["replay: model `two-node-coil` ran away: node `coil`"],
    );
}

#[test]
fn non_finite_and_overflowing_column_expressions_are_refused() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("o.csv");
    let trace = steady_trace(&dir, 10.0);
    for k in ["nan", "inf"] {
        refused(
            ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
                .args(["--current", &format!("scale(current,{k})=current")])
                .args(["--out", s(&out)]),
            &[&format!("the factor `{k}` is not a finite number")],
        );
    }
    refused(
        ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
            .args([
                "--current",
                "scale(current,1e308)=current",
                "--out",
                s(&out),
            ]),
        &["steady.csv:2: `scale(current,1e308)` overflows to inf at this row"],
    );
    // hypot of two 1e200 A columns is 1.41e200 A, finite (no squares that
    // overflow), and a coil at that current runs away: refused, not NaN.
    let big = write(
        &dir,
        "big.csv",
        "time_s,a,b\n0,1e200,1e200\n1,1e200,1e200\n",
    );
    refused(
        ct().args(["simulate", "--model", &model(), "--trace", s(&big)])
            .args(["--current", "hypot(a,b)=current", "--out", s(&out)]),
        &["ran away"],
    );
}

#[test]
fn replay_of_a_sparse_trace_alarms_at_the_firmwares_tick() {
    // Rows 600 s apart: the coil is at 166 degC on one row only. A
    // debounce counted in rows (three of them) would need 1200 s beyond
    // the limit and printed "alarm events: none"; the firmware's observer
    // ticks every 1 ms between the rows and alarms where it crosses.
    let dir = TempDir::new().unwrap();
    let trace = write(
        &dir,
        "sparse.csv",
        "time_s,current\n0,3.7\n600,3.7\n1200,0\n1800,0\n",
    );
    let out = ct()
        .args([
            "replay",
            "--model",
            &model(),
            "--trace",
            s(&trace),
            "--json",
        ])
        .assert()
        .success();
    let j: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let hot = j["hot_spot"]["max_c"].as_f64().unwrap();
    assert!(hot > 155.0, "the crossing this test needs: {hot}");
    assert_eq!(j["alarm"]["shutdown_latched"], true, "{j}");
    let latched: Vec<&Value> = j["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["level"] == "shutdown")
        .collect();
    assert_eq!(latched.len(), 1, "{j}");
    // The firmware ticks every 1 ms between the rows: it latches where its
    // bound crosses the limit, inside the first 600 s row, not at a row.
    let at = latched[0]["time_s"].as_f64().unwrap();
    assert!(at > 0.0 && at < 600.0 && at.fract() != 0.0, "{j}");
    // The host alarm's debounce does not apply to the firmware's observer.
    refused(
        ct().args(["replay", "--model", &model(), "--trace", s(&trace)])
            .args(["--debounce-s", "3"]),
        &["drop --debounce-s"],
    );
}

/// `calibrate` holds its traces (it iterates over them), so it bounds
/// their size; the streamed subcommands do not (their memory does not grow
/// with the trace, see `a_long_trace_streams_in_constant_memory`).
#[test]
fn a_trace_too_large_for_memory_is_refused_before_reading() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("huge.csv");
    let f = fs::File::create(&path).unwrap();
    // Sparse: no disk is written, but the size is what the tool checks.
    f.set_len(1100 << 20).unwrap();
    refused(
        ct().args(["calibrate", "--model", &model(), "--trace", s(&path)])
            .args(["--measure", "t=coil", "--params", "capacity.coil"])
            .args(["--out", s(&dir.path().join("o.toml"))]),
        &[
            "huge.csv:1: the trace is 1100 MiB",
            "up to 1024 MiB",
            "decimate",
        ],
    );
}

#[test]
fn a_non_numeric_cell_in_an_unused_column_is_reported() {
    let dir = TempDir::new().unwrap();
    let trace = write(
        &dir,
        "note.csv",
        "time_s,current,note\n0,1,1\n1,1,door open\n2,1,3\n",
    );
    ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
        .args(["--out", s(&dir.path().join("o.csv"))])
        .assert()
        .success()
        .stderr(contains("warning: "))
        .stderr(contains(
            "note.csv:3:3: column `note` holds `door open`, not a number",
        ));
    // Used, it is an error at the same place.
    refused(
        ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
            .args(["--current", "note=current"])
            .args(["--out", s(&dir.path().join("o.csv"))]),
        &["note.csv:3:3: column `note`: `door open` is not a number"],
    );
}

#[test]
fn lists_and_mappings_are_read_item_by_item() {
    let dir = TempDir::new().unwrap();
    let trace = write(&dir, "t.csv", "time_s,current,a,b\n0,1,20,20\n1,1,20,20\n");
    // The second item names a node the model lacks: the error quotes that
    // item, not the whole list.
    refused(
        ct().args(["replay", "--model", &model(), "--trace", s(&trace)])
            .args(["--truth", "a=coil,b=winding"]),
        &["--truth `b=winding`: model `two-node-coil` has no node `winding`"],
    );
    refused(
        ct().args(["replay", "--model", &model(), "--trace", s(&trace)])
            .args(["--measure", "a=coil,"]),
        &["--measure ``: expected COL=NODE"],
    );
    for bad in ["0:1,0:2", "0:1,x:2", "0:1,2"] {
        refused(
            ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
                .args(["--current", &format!("{bad}=current")])
                .args(["--out", s(&dir.path().join("o.csv"))]),
            &["step profile"],
        );
    }
}

#[test]
fn a_step_profile_starting_after_the_trace_is_refused() {
    let dir = TempDir::new().unwrap();
    let trace = steady_trace(&dir, 1.0);
    refused(
        ct().args(["simulate", "--model", &model(), "--trace", s(&trace)])
            .args(["--current", "5:1,40:0=current"])
            .args(["--out", s(&dir.path().join("o.csv"))]),
        &["step profile `5:1,40:0` starts at 5 s, after the first row (0 s)"],
    );
}

#[test]
fn a_bad_time_window_is_refused_naming_the_flags() {
    let dir = TempDir::new().unwrap();
    let trace = steady_trace(&dir, 2.0);
    let out = dir.path().join("o.csv");
    for cmd in ["simulate", "replay"] {
        for (window, needles) in [
            (
                ["--from-s", "50", "--to-s", "50"],
                ["--from-s below --to-s", "50 s"],
            ),
            (
                ["--from-s", "60", "--to-s", "10"],
                ["--from-s below --to-s", "60 s"],
            ),
            (
                ["--from-s", "NaN", "--to-s", "10"],
                ["--from-s must be a finite time", "NaN"],
            ),
            (
                ["--from-s", "0", "--to-s", "inf"],
                ["--to-s must be a finite time", "inf"],
            ),
            (
                ["--from-s", "200", "--to-s", "300"],
                ["holds no row", "0 s .. 100 s"],
            ),
        ] {
            refused(
                ct().args([cmd, "--model", &model(), "--trace", s(&trace)])
                    .args(window)
                    .args(["--out", s(&out)]),
                &needles,
            );
        }
    }
}

/// The peak resident memory \[kB\] of the tool run with `args`, read with
/// `/usr/bin/time`.
fn peak_kb(time: &Path, args: &[&str]) -> f64 {
    let out = std::process::Command::new(time)
        .args(["-f", "peak_kb=%M"])
        .arg(env!("CARGO_BIN_EXE_coil-thermal"))
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("peak_kb="))
        .unwrap_or_else(|| panic!("{stderr}"))
        .trim()
        .parse()
        .unwrap()
}

/// Traces stream in constant memory: `simulate --trace` and `replay` of a
/// 1-million-row trace (16 MB) peak within 4 MB and 25 % of the same runs
/// on a 10 times shorter one (measured: 7.2 and 9.5 MB at 2e5 and at 2e6
/// rows), and under 32 MB. Holding the trace, as the tool did before, took
/// about 100 bytes a row (`simulate` of 2e6 rows peaked at 211 MB, of 2e5
/// at 28 MB): both bounds fail on that code. Skipped where
/// `/usr/bin/time` is missing.
#[test]
fn a_long_trace_streams_in_constant_memory() {
    let time = Path::new("/usr/bin/time");
    if !time.exists() {
        eprintln!("skipped: no /usr/bin/time to read the peak memory");
        return;
    }
    let dir = TempDir::new().unwrap();
    let trace = |rows: u32| {
        let path = dir.path().join(format!("long-{rows}.csv"));
        let mut text = String::with_capacity(rows as usize * 17);
        text.push_str("time_s,current,note,temp\n");
        for k in 0..rows {
            let i = if (k / 1000) % 2 == 1 { "2.5" } else { "0" };
            text.push_str(&format!("{k},{i},{}.25,{}\n", k % 7, 20 + k % 50));
        }
        fs::write(&path, text).unwrap();
        path
    };
    let (short, long) = (trace(100_000), trace(1_000_000));
    let out = dir.path().join("o.csv");
    let model = model();
    for args in [
        vec!["simulate", "--model", &model, "--out", s(&out)],
        vec![
            "replay",
            "--model",
            &model,
            "--out",
            s(&out),
            "--tick-us",
            "1000000",
            "--truth",
            "temp=coil",
        ],
    ] {
        let peak = |path: &Path| {
            let mut all = args.clone();
            all.extend(["--trace", s(path)]);
            peak_kb(time, &all)
        };
        let (short_kb, long_kb) = (peak(&short), peak(&long));
        assert!(
            long_kb <= 1.25 * short_kb + 4e3 && long_kb < 32e3,
            "{}: peak {long_kb} kB for 1e6 rows, {short_kb} kB for 1e5",
            args[0]
        );
        assert!(
            short_kb > 2e3,
            "peak {short_kb} kB: the measurement is not the run's"
        );
    }
}
