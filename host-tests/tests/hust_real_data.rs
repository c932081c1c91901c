//! Opt-in: the HUST motor on its real recordings (set `COIL_THERMAL_HUST_DIR`
//! to the folder holding `id_N.csv` and run with `--ignored`; `.ci/run`
//! does when shared/ exists). Every test is `#[ignore]`d, so the default
//! test command reports them as not run (never as passed) on a machine
//! without the data. The data is read at run time, never copied.
//!
//! Split (README "The real motor", docs/hust.md): the six-node model is
//! fitted on profiles 1 3 5 9 11, the seven-node one on 0 (its EMA
//! smoothing inverted) 1 3 5 9 11; both are scored on 2 4 8 10 12 13 too.

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal_host::calibrate::access_param;
use coil_thermal_host::model_file::ModelFile;
use serde_json::Value;
use tempfile::TempDir;

const FIT: [u32; 5] = [1, 3, 5, 9, 11];
const SCORED: [u32; 6] = [2, 4, 8, 10, 12, 13];
const ALL: [u32; 12] = [0, 1, 2, 3, 4, 5, 8, 9, 10, 11, 12, 13];

/// The HUST recordings (`COIL_THERMAL_HUST_DIR`). Every test here is
/// `#[ignore]`d, so that `cargo test` reports it as not run rather than
/// passed; `.ci/run` runs them with `--ignored` when `../shared` has the
/// data, and a run with `--ignored` but without the variable fails here.
fn data_dir() -> PathBuf {
    match std::env::var("COIL_THERMAL_HUST_DIR") {
        Ok(d) => PathBuf::from(d),
        Err(_) => panic!(
            "COIL_THERMAL_HUST_DIR is not set: point it at shared/data/hust-ipmsm to run the real-data checks"
        ),
    }
}

fn here(rel: &str) -> String {
    format!("{}/{rel}", env!("CARGO_MANIFEST_DIR"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `(MSE, max error)` of activewind_1 for one replay.
fn replay(
    dir: &Path,
    n: u32,
    model: &str,
    node: &str,
    extra: &[&str],
    tmp: &TempDir,
) -> (f64, f64) {
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &here(model), "--trace"])
        .arg(dir.join(format!("id_{n}.csv")))
        .args(["--sample-period-s", "1", "--json", "--truth"])
        .arg(format!("activewind_1={node}"))
        .args(extra)
        .args(["--out", s(&tmp.path().join("est.csv"))])
        .assert()
        .success();
    let j: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let t = &j["truth"][0];
    (
        t["mse_k2"].as_f64().unwrap(),
        t["max_abs_error_k"].as_f64().unwrap(),
    )
}

/// Profile `n`'s trace; profile 0 with its EMA smoothing inverted (data
/// README: `x[k] = (y[k] - 0.95 y[k-1]) / 0.05`, back on the 0.1 degC grid;
/// the rotor column is on no grid), written into `tmp`.
fn trace_path(dir: &Path, n: u32, tmp: &TempDir) -> PathBuf {
    let path = dir.join(format!("id_{n}.csv"));
    if n != 0 {
        return path;
    }
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let temps = [
        "water_outlet",
        "bearing",
        "ambient",
        "rotor",
        "endwind_1",
        "endwind_2",
        "slotside",
        "slotopen",
        "slotbottom",
        "activewind_1",
        "activewind_2",
        "outer_yoke",
        "endcap",
    ];
    let mut out = format!("{header}\n");
    let mut prev: Vec<f64> = Vec::new();
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let y: Vec<f64> = line.split(',').map(|v| v.trim().parse().unwrap()).collect();
        let row: Vec<String> = y
            .iter()
            .enumerate()
            .map(|(c, v)| {
                if prev.is_empty() || !temps.contains(&names[c]) {
                    return v.to_string();
                }
                let x = (v - 0.95 * prev[c]) / 0.05;
                if names[c] == "rotor" {
                    x.to_string()
                } else {
                    format!("{x:.1}")
                }
            })
            .collect();
        out.push_str(&row.join(","));
        out.push('\n');
        prev = y;
    }
    let raw = tmp.path().join("id_0_raw.csv");
    std::fs::write(&raw, out).unwrap();
    raw
}

/// `(MSE, max error)` of every `--truth` of one replay of trace `path`.
fn scores(path: &Path, model: &str, args: &[&str], tmp: &TempDir) -> Vec<(f64, f64)> {
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &here(model), "--trace", s(path)])
        .args(["--sample-period-s", "1", "--json"])
        .args(args)
        .args(["--out", s(&tmp.path().join("scores.csv"))])
        .assert()
        .success();
    let j: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    j["truth"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["mse_k2"].as_f64().unwrap(),
                t["max_abs_error_k"].as_f64().unwrap(),
            )
        })
        .collect()
}

const PUBLISHED_ARGS: [&str; 10] = [
    "--init",
    "mean(activewind_1,activewind_2)=winding",
    "--init",
    "mean(slotbottom,outer_yoke)=stator",
    "--init",
    "rotor=rotor",
    "--truth",
    "activewind_1=winding",
    "--truth",
    "activewind_2=winding",
];

/// Every node with a sensor starts at its first reading (the teeth at the
/// authors' stator reading); activewind_1 and activewind_2 scored.
const SEVEN_ARGS: [&str; 14] = [
    "--init",
    "endwind_1=end_winding",
    "--init",
    "mean(slotbottom,outer_yoke)=stator_teeth",
    "--init",
    "outer_yoke=stator_yoke",
    "--init",
    "rotor=rotor",
    "--init",
    "endcap=endcap",
    "--truth",
    "activewind_1=active_winding",
    "--truth",
    "activewind_2=slot_centre",
];

/// Issue 18's first goal: open loop, the calibrated seven-node model beats
/// the authors' full published network on both active-winding sensors on
/// every profile, fitted (0 inverted, 1 3 5 9 11) and held out alike.
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn seven_node_model_beats_the_full_published_network_open_loop_on_every_profile() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    for n in ALL {
        let path = trace_path(&dir, n, &tmp);
        let base = scores(&path, "models/hust-published.toml", &PUBLISHED_ARGS, &tmp);
        let ours = scores(
            &path,
            "models/hust_motor_slot_fitted.toml",
            &SEVEN_ARGS,
            &tmp,
        );
        for (k, (b, o)) in base.iter().zip(&ours).enumerate() {
            eprintln!(
                "profile {n} activewind_{}: published {:.3} K^2, seven-node open loop {:.3} K^2",
                k + 1,
                b.0,
                o.0
            );
            assert!(
                o.0 < b.0,
                "profile {n} activewind_{}: {o:?} vs {b:?}",
                k + 1
            );
        }
    }
}

/// The firmware's observer (the library's `NetworkObserver` at 1 ms,
/// steady gain, `f32`) fusing endwind_1 as `codegen` flashes it, every
/// setting the model file's `[observer]` table (no replay flag: 0.5 K of
/// sensor noise, the copper's heat bias on the active winding at the
/// library's default bias noise, 1.5e-3 K^2/s of node noise, the coolant
/// offset at 2 K and 7200 s): within issue 18's goals (1 K^2 and 3 K) on
/// both active-winding sensors of every profile, and better than open loop
/// on both (docs/hust-trials.md, "The firmware's observer").
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn the_firmware_observer_fusing_endwind_1_meets_the_goals_on_every_profile() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    let model = "models/hust_motor_slot_fitted.toml";
    for n in ALL {
        let path = trace_path(&dir, n, &tmp);
        let open = scores(&path, model, &SEVEN_ARGS, &tmp);
        let mut args = SEVEN_ARGS.to_vec();
        args.extend(["--measure", "endwind_1=end_winding"]);
        let fused = scores(&path, model, &args, &tmp);
        eprintln!("profile {n}: firmware observer {fused:?}, open loop {open:?}");
        for (k, ((mse, max), (open_mse, _))) in fused.iter().zip(&open).enumerate() {
            assert!(
                mse < open_mse,
                "profile {n}: activewind_{} fused {mse} against open loop {open_mse} K^2",
                k + 1
            );
            assert!(
                *mse <= 1.0 && *max <= 3.0,
                "profile {n}, as flashed: activewind_{} {mse} K^2, {max} K",
                k + 1
            );
        }
    }
}

/// The six-node model of the earlier table against the full published
/// network on activewind_1, open loop, every node with a sensor started at
/// its reading.
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn six_node_model_beats_the_full_published_network_on_activewind_1() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    let args = [
        "--init",
        "endwind_1=end_winding",
        "--init",
        "mean(slotbottom,outer_yoke)=stator_teeth",
        "--init",
        "outer_yoke=stator_yoke",
        "--init",
        "rotor=rotor",
        "--init",
        "endcap=endcap",
        "--truth",
        "activewind_1=active_winding",
    ];
    for n in FIT.into_iter().chain(SCORED) {
        let path = trace_path(&dir, n, &tmp);
        let base = scores(&path, "models/hust-published.toml", &PUBLISHED_ARGS, &tmp);
        let ours = scores(&path, "models/hust_motor_fitted.toml", &args, &tmp);
        eprintln!(
            "profile {n}: published {:.3}, six-node {:.3} K^2",
            base[0].0, ours[0].0
        );
        assert!(ours[0].0 < base[0].0, "profile {n}");
    }
}

/// The committed fitted model is what `reproduce.sh`'s calibration command
/// gives (same command, same bounds from `hust/params.txt`).
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn calibration_reproduces_the_committed_fitted_model() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    let params_txt = std::fs::read_to_string(here("hust/params.txt")).unwrap();
    let params: Vec<&str> = params_txt
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    let out = tmp.path().join("fitted.toml");
    let mut cmd = cargo_bin_cmd!("coil-thermal");
    cmd.args(["calibrate", "--model", &here("models/hust_motor.toml")]);
    for n in FIT {
        cmd.arg("--trace").arg(dir.join(format!("id_{n}.csv")));
    }
    cmd.args(["--sample-period-s", "1"])
        .args(["--measure", "activewind_1=active_winding"])
        .args(["--measure", "endwind_1=end_winding"])
        .args(["--measure", "outer_yoke=stator_yoke"])
        .args(["--measure", "rotor=rotor"])
        .args(["--measure", "endcap=endcap"])
        .args(["--params", &params.join(",")])
        .args(["--stride", "10", "--max-iterations", "60", "--no-progress"])
        .args(["--out", s(&out)])
        .assert()
        .success();
    let mut fitted = ModelFile::load(&out).unwrap();
    let mut committed = ModelFile::load(Path::new(&here("models/hust_motor_fitted.toml"))).unwrap();
    for p in &params {
        let name = p.split('=').next().unwrap();
        let a = access_param(&mut fitted, name, None).unwrap();
        let b = access_param(&mut committed, name, None).unwrap();
        assert!(
            (a - b).abs() <= 1e-6 * b.abs().max(1e-3),
            "{name}: refitted {a} vs committed {b}"
        );
    }
}

/// The columns of a HUST profile by name (plain CSV, every field a number).
fn columns(path: &Path) -> std::collections::HashMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let names: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|h| h.trim().to_string())
        .collect();
    let mut cols = vec![Vec::new(); names.len()];
    for line in lines.filter(|l| !l.trim().is_empty()) {
        for (c, v) in cols.iter_mut().zip(line.split(',')) {
            c.push(v.trim().parse::<f64>().unwrap());
        }
    }
    names.into_iter().zip(cols).collect()
}

/// The authors' network re-implemented from the transcription in the data
/// README, line by line, without the library or the model file: explicit
/// Euler at 1 s, the inputs of row k for the step that ends at row k, the
/// states starting at the first row's measured values. The winding
/// temperature at every row.
fn published_winding_c(d: &std::collections::HashMap<String, Vec<f64>>) -> Vec<f64> {
    let col = |n: &str| &d[n];
    let mean = |a: &str, b: &str| 0.5 * (col(a)[0] + col(b)[0]);
    let (mut tw, mut ts, mut tr) = (
        mean("activewind_1", "activewind_2"),
        mean("slotbottom", "outer_yoke"),
        col("rotor")[0],
    );
    let rows = col("speed").len();
    let mut out = Vec::with_capacity(rows);
    out.push(tw);
    for k in 1..rows {
        let i = col("IdRef")[k].hypot(col("IqRef")[k]) / 370.0;
        let f = col("speed")[k] / 4000.0;
        let (tc, ta) = (col("water_outlet")[k], col("ambient")[k]);
        let r_sr = 0.5769 * (-0.7913 / 4000.0 * f).exp() + 0.007967;
        let r_ra = 5.00 * (-0.3128 / 4000.0 * f).exp() + 0.0117;
        let p_w = 1.5
            * 4.67e-3
            * (370.0 * i).powi(2)
            * (1.0 + 0.0039 * (tw - 20.0))
            * (1.0 + 0.02174 * f + 0.38740 * f * f);
        let p_res = 4.656e-6 * i + 247.8 * f + 1151.47 * i * f;
        let a = (0.8910 + 0.0231 * i - 0.0397 * f - 0.009 * i * f).clamp(0.0, 1.0);
        let q_ws = (tw - ts) / 0.01375;
        let q_sc = (ts - tc) / 0.01879;
        let q_sr = (ts - tr) / r_sr;
        let q_ra = (tr - ta) / r_ra;
        tw += (p_w - q_ws) / 3716.15;
        ts += (a * p_res + q_ws - q_sc - q_sr) / 5616.32;
        tr += ((1.0 - a) * p_res + q_sr - q_ra) / 5329.69;
        out.push(tw);
    }
    out
}

/// The published baseline's model file, replayed by the tool, is the
/// transcription: its winding is an independent re-implementation's to
/// within 0.01 K^2 (mean square difference) on every profile, and it scores
/// the figures the issue quotes for the authors' model (profile 12:
/// 4.97 K^2; profile 2: 29.21 K^2 on activewind_1).
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn published_model_file_replays_the_transcription() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    let init = [
        "--init",
        "mean(activewind_1,activewind_2)=winding",
        "--init",
        "mean(slotbottom,outer_yoke)=stator",
        "--init",
        "rotor=rotor",
    ];
    for n in ALL {
        let path = dir.join(format!("id_{n}.csv"));
        let (mse, _) = replay(
            &dir,
            n,
            "models/hust-published.toml",
            "winding",
            &init,
            &tmp,
        );
        let replayed = columns(&tmp.path().join("est.csv"))["winding"].clone();
        let d = columns(&path);
        let reference = published_winding_c(&d);
        assert_eq!(replayed.len(), reference.len());
        let diff = replayed
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / reference.len() as f64;
        let own = reference
            .iter()
            .zip(&d["activewind_1"])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / reference.len() as f64;
        eprintln!("profile {n}: replay vs transcription {diff:.2e} K^2; activewind_1 MSE {mse:.2} (reference {own:.2}) K^2");
        assert!(diff <= 0.01, "profile {n}: {diff} K^2");
        assert!((mse - own).abs() <= 0.01, "profile {n}: {mse} vs {own}");
        match n {
            12 => assert!((mse - 4.97).abs() < 0.01, "profile 12: {mse}"),
            2 => assert!((mse - 29.21).abs() < 0.01, "profile 2: {mse}"),
            _ => {}
        }
    }
}

/// The committed seven-node fitted model is what `reproduce.sh` gives
/// (profiles 0 inverted, 1 3 5 9 11; bounds from `hust/params_slot.txt`),
/// in under a minute, and every parameter the refit leaves on a bound has
/// a physical reason written beside it in the committed file.
#[test]
#[ignore = "needs the HUST recordings: COIL_THERMAL_HUST_DIR=shared/data/hust-ipmsm, run with --ignored"]
fn seven_node_calibration_reproduces_the_committed_fitted_model() {
    let dir = data_dir();
    let tmp = TempDir::new().unwrap();
    let params_txt = std::fs::read_to_string(here("hust/params_slot.txt")).unwrap();
    let params: Vec<&str> = params_txt
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    let out = tmp.path().join("fitted.toml");
    let mut cmd = cargo_bin_cmd!("coil-thermal");
    cmd.args(["calibrate", "--model", &here("models/hust_motor_slot.toml")]);
    for n in [0, 1, 3, 5, 9, 11] {
        cmd.arg("--trace").arg(trace_path(&dir, n, &tmp));
    }
    let start = std::time::Instant::now();
    cmd.args(["--sample-period-s", "1"])
        .args(["--measure", "activewind_1=active_winding"])
        .args(["--measure", "endwind_1=end_winding"])
        .args(["--measure", "outer_yoke=stator_yoke"])
        .args(["--measure", "rotor=rotor"])
        .args(["--measure", "endcap=endcap"])
        .args(["--measure", "activewind_2=slot_centre"])
        .args(["--init", "mean(slotbottom,outer_yoke)=stator_teeth"])
        .args(["--params", &params.join(",")])
        .args(["--stride", "10", "--max-iterations", "120"])
        .args(["--weighting", "traces", "--no-progress"])
        .args(["--out", s(&out)])
        .assert()
        .success();
    eprintln!(
        "seven-node calibration: {:.1} s",
        start.elapsed().as_secs_f64()
    );
    let mut fitted = ModelFile::load(&out).unwrap();
    // The copper loss is the electrical one, not a fitted number.
    assert_eq!(
        access_param(&mut fitted, "conductor.winding.scale", None).unwrap(),
        1.5
    );
    let committed_path = here("models/hust_motor_slot_fitted.toml");
    let mut committed = ModelFile::load(Path::new(&committed_path)).unwrap();
    let mut at_bound = Vec::new();
    for p in &params {
        let (name, range) = p.rsplit_once('=').unwrap();
        let a = access_param(&mut fitted, name, None).unwrap();
        let b = access_param(&mut committed, name, None).unwrap();
        assert!(
            (a - b).abs() <= 1e-6 * b.abs().max(1e-3),
            "{name}: refitted {a} vs committed {b}"
        );
        let (lo, hi) = range.split_once(':').unwrap();
        let on = |bound: &str| {
            let bound: f64 = bound.parse().unwrap();
            (a - bound).abs() <= 1e-9 * bound.abs().max(1e-6)
        };
        if on(lo) || on(hi) {
            at_bound.push(name);
        }
    }
    // Issue 18's third goal: every fitted parameter that ends on a bound has
    // its physical reason written beside it in the committed file, and none
    // is marked as compensating for something the network lacks.
    let text = std::fs::read_to_string(&committed_path).unwrap();
    let reasons = text.matches("BOUND, physical:").count();
    eprintln!("seven-node parameters on a bound: {at_bound:?}");
    assert_eq!(
        reasons,
        at_bound.len(),
        "{} parameters on a bound ({at_bound:?}), {reasons} physical reasons written",
        at_bound.len()
    );
    assert!(!text.contains("COMPENSATING"));
}
