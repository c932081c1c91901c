//! Inputs the tool used to take without a word, now refused with a message
//! that names what is wrong; and help texts that speak to the user, not
//! to the project's issue tracker.

use std::fs;
use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use predicates::str::contains;
use tempfile::TempDir;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The two-node coil (`models/two-node-coil.toml`) with each `from`
/// replaced by its `to` (each must be there).
fn two_node_with(dir: &TempDir, name: &str, edits: &[(&str, &str)]) -> PathBuf {
    let mut text = fs::read_to_string(models().join("two-node-coil.toml")).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "`{from}` is not in two-node-coil.toml");
        text = text.replace(from, to);
    }
    let p = dir.path().join(name);
    fs::write(&p, text).unwrap();
    p
}

/// `simulate` of `model` at 1 A for 10 s.
fn simulate(model: &Path, dir: &TempDir) -> assert_cmd::assert::Assert {
    ct().args(["simulate", "--model", s(model), "--current-a", "1"])
        .args(["--duration-s", "10", "--out"])
        .arg(dir.path().join("out.csv"))
        .assert()
}

/// The command fails with each of `needles` in its error, nothing on
/// stdout.
fn refused(a: assert_cmd::assert::Assert, needles: &[&str]) {
    let mut a = a.failure().stdout("");
    for n in needles {
        a = a.stderr(contains(*n));
    }
}

fn stdout_of(args: &[&str]) -> String {
    let out = ct().args(args).output().unwrap();
    assert!(out.status.success(), "coil-thermal {args:?} failed");
    String::from_utf8(out.stdout).unwrap()
}

/// Where `text` names an issue by number (`issue 17`, `Issue 20`).
fn issue_numbers(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    lower
        .match_indices("issue ")
        .filter(|(k, m)| {
            lower[k + m.len()..]
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        })
        .map(|(k, _)| lower[k..].chars().take(40).collect())
        .collect()
}

#[test]
fn issue_numbers_are_found_by_the_help_check() {
    // The check itself: it must see what it is meant to refuse.
    assert_eq!(issue_numbers("Issue 17's fault campaign").len(), 1);
    assert_eq!(issue_numbers("see issue 3").len(), 1);
    assert!(issue_numbers("the issue's goals, issues galore").is_empty());
}

/// `--help` of the tool and of every subcommand it lists names no issue
/// number: a user has no access to the project's tracker.
#[test]
fn no_help_text_names_an_issue_number() {
    let top = stdout_of(&["--help"]);
    let mut found = issue_numbers(&top);
    let commands: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter(|l| l.starts_with("  ") && !l[2..].starts_with(' '))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    for expected in [
        "simulate",
        "replay",
        "limits",
        "calibrate",
        "codegen",
        "faults",
    ] {
        assert!(
            commands.contains(&expected),
            "`{expected}` is not among the commands --help lists: {commands:?}"
        );
    }
    for c in &commands {
        for text in [stdout_of(&[c, "--help"]), stdout_of(&[c, "-h"])] {
            found.extend(
                issue_numbers(&text)
                    .into_iter()
                    .map(|m| format!("{c}: {m}")),
            );
        }
    }
    assert!(found.is_empty(), "help texts name issues: {found:#?}");
}

/// A resistance that reaches 0 ohm inside the model's temperature range
/// (-55 degC to the highest `critical_c` plus 50 K, at least 250 degC) is
/// refused at load, in either form, naming the source, the temperature and
/// the range; it used to run as a coil that makes no heat, or cools itself,
/// below that temperature.
#[test]
fn a_resistance_reaching_zero_in_the_range_is_refused() {
    let dir = TempDir::new().unwrap();
    // Form 1: 5.69 (1 + 0.02 (T - 20)) is 0 at -30 degC.
    let alpha = two_node_with(
        &dir,
        "alpha.toml",
        &[("alpha_per_k = 0.0039", "alpha_per_k = 0.02")],
    );
    refused(
        simulate(&alpha, &dir),
        &[
            "alpha.toml:30:1: [[source]] #1 `coil`",
            "reaches 0 ohm at -30.0 degC",
            "-55 to 250 degC",
            "alpha_per_k",
        ],
    );
    // Form 2: 1 + 0.05 T is 0 at -20 degC.
    let slope = two_node_with(
        &dir,
        "slope.toml",
        &[(
            "r0_ohm = 5.69\nalpha_per_k = 0.0039\nt_ref_c = 20.0",
            "r_at_0c_ohm = 1.0\nslope_ohm_per_k = 0.05",
        )],
    );
    refused(
        simulate(&slope, &dir),
        &[
            "[[source]] #1 `coil`",
            "R(T) = 1 + 0.05 T ohm reaches 0 ohm at -20.0 degC",
            "slope_ohm_per_k",
        ],
    );
    // The range's top follows the highest critical_c (plus 50 K).
    let hot = two_node_with(
        &dir,
        "hot.toml",
        &[
            ("alpha_per_k = 0.0039", "alpha_per_k = 0.02"),
            ("critical_c = 155.0", "critical_c = 260.0"),
        ],
    );
    refused(simulate(&hot, &dir), &["-55 to 310 degC"]);
}

/// The range's bottom: -55 degC, or a colder boundary. 0.0125 1/K puts
/// R = 0 at -60 degC: outside the range of a model at 20 degC (accepted),
/// inside that of one with its ambient at -70 degC (refused).
#[test]
fn the_range_checked_reaches_down_to_the_coldest_boundary() {
    let dir = TempDir::new().unwrap();
    let steep = two_node_with(
        &dir,
        "steep.toml",
        &[("alpha_per_k = 0.0039", "alpha_per_k = 0.0125")],
    );
    simulate(&steep, &dir).success();
    let arctic = two_node_with(
        &dir,
        "arctic.toml",
        &[
            ("alpha_per_k = 0.0039", "alpha_per_k = 0.0125"),
            ("value_c = 20.0", "value_c = -70.0"),
        ],
    );
    refused(
        simulate(&arctic, &dir),
        &["reaches 0 ohm at -60.0 degC", "-70 to 250 degC"],
    );
}

/// A resistance that falls with temperature (a negative `alpha_per_k` or
/// `slope_ohm_per_k`) is refused even where it stays above 0 ohm: a
/// winding's rises, and MODEL_FORMAT.md gives a falling one no meaning.
#[test]
fn a_resistance_falling_with_temperature_is_refused() {
    let dir = TempDir::new().unwrap();
    // 5.69 (1 - 0.001 (T - 20)) is above 0 from -55 to 250 degC.
    let alpha = two_node_with(
        &dir,
        "alpha.toml",
        &[("alpha_per_k = 0.0039", "alpha_per_k = -0.001")],
    );
    refused(
        simulate(&alpha, &dir),
        &[
            "[[source]] #1 `coil`",
            "alpha_per_k = -0.001 1/K makes the resistance fall",
            "give alpha_per_k >= 0",
        ],
    );
    let slope = two_node_with(
        &dir,
        "slope.toml",
        &[(
            "r0_ohm = 5.69\nalpha_per_k = 0.0039\nt_ref_c = 20.0",
            "r_at_0c_ohm = 5.69\nslope_ohm_per_k = -0.002",
        )],
    );
    refused(
        simulate(&slope, &dir),
        &[
            "slope_ohm_per_k = -0.002 ohm/K",
            "give slope_ohm_per_k >= 0",
        ],
    );
}

/// The two-node coil without its `[[source]]`, heated by a fixed 5 W.
fn no_current_input(dir: &TempDir) -> PathBuf {
    let text = fs::read_to_string(models().join("two-node-coil.toml")).unwrap();
    let (head, rest) = text.split_once("[[source]]").unwrap();
    let (_, tail) = rest.split_once("[initial]").unwrap();
    let p = dir.path().join("no-input.toml");
    fs::write(
        &p,
        format!("{head}[[fixed_power]]\nnode = \"coil\"\npower_w = 5.0\n\n[initial]{tail}"),
    )
    .unwrap();
    p
}

/// `--current-a` for a model with no current input is refused (it was
/// dropped without a word); without it, the model runs on its fixed power.
#[test]
fn current_a_for_a_model_without_current_input_is_refused() {
    let dir = TempDir::new().unwrap();
    let model = no_current_input(&dir);
    let out = dir.path().join("out.csv");
    let needle = "--current-a: model `two-node-coil` has no current input (no [[source]])";
    refused(
        ct().args(["simulate", "--model", s(&model), "--current-a", "3"])
            .args(["--duration-s", "10", "--out", s(&out)])
            .assert(),
        &[needle, "leave --current-a out"],
    );
    assert!(!out.exists(), "no result is written");
    refused(
        ct().args(["limits", "--model", s(&model), "--current-a", "3"])
            .assert(),
        &[needle],
    );
    ct().args(["simulate", "--model", s(&model), "--duration-s", "10"])
        .args(["--out", s(&out)])
        .assert()
        .success();
    ct().args(["limits", "--model", s(&model)])
        .assert()
        .success()
        .stdout(contains("coil"));
    // More values than inputs were refused already (one value for every
    // input is the documented broadcast).
    let coil = models().join("two-node-coil.toml");
    refused(
        ct().args(["simulate", "--model", s(&coil), "--current-a", "1,2"])
            .args(["--duration-s", "10", "--out", s(&out)])
            .assert(),
        &["--current-a has 2 values but model `two-node-coil` has 1 current inputs"],
    );
}

/// `codegen --help` says what a model file's codegen needs on the host
/// (cargo, the library's source), how long the first run takes and where
/// the generator is built.
#[test]
fn codegen_help_says_what_it_needs_and_where_it_builds() {
    // Words, not lines: the help is wrapped to the terminal.
    let help = stdout_of(&["codegen", "--help"])
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    for needle in [
        "it needs cargo (on PATH, or $CARGO)",
        "the coil-thermal library's source on this host",
        "The first run compiles the library",
        "$CARGO_TARGET_DIR/coil-thermal-codegen",
        "$XDG_CACHE_HOME/coil-thermal/codegen",
        "never the library's own `target`",
    ] {
        assert!(
            help.contains(needle),
            "codegen --help lacks `{needle}`:\n{help}"
        );
    }
}

/// Where the generator is built: `--target-dir`, then `$CARGO_TARGET_DIR`,
/// then the per-user cache, then the temp directory; never the library's
/// own `target/`.
#[test]
fn the_generator_is_built_in_a_per_user_cache_by_default() {
    use coil_thermal_host::codegen::work_dir;
    use std::ffi::OsString;
    let env = |vars: &'static [(&'static str, &'static str)]| {
        move |name: &str| {
            vars.iter()
                .find(|(k, _)| *k == name)
                .map(|(_, v)| OsString::from(v))
        }
    };
    let all: &[(&str, &str)] = &[
        ("CARGO_TARGET_DIR", "/ct"),
        ("XDG_CACHE_HOME", "/xdg"),
        ("HOME", "/home/u"),
    ];
    assert_eq!(
        work_dir(Some(Path::new("/given")), env(all)),
        Path::new("/given/coil-thermal-codegen")
    );
    assert_eq!(
        work_dir(None, env(all)),
        Path::new("/ct/coil-thermal-codegen")
    );
    assert_eq!(
        work_dir(
            None,
            env(&[("XDG_CACHE_HOME", "/xdg"), ("HOME", "/home/u")])
        ),
        Path::new("/xdg/coil-thermal/codegen")
    );
    // A relative XDG_CACHE_HOME is ignored (the XDG rule), as is an empty
    // variable.
    assert_eq!(
        work_dir(
            None,
            env(&[
                ("CARGO_TARGET_DIR", ""),
                ("XDG_CACHE_HOME", "rel"),
                ("HOME", "/home/u")
            ])
        ),
        Path::new("/home/u/.cache/coil-thermal/codegen")
    );
    assert_eq!(
        work_dir(None, env(&[])),
        std::env::temp_dir().join("coil-thermal-codegen")
    );
}

fn codegen(model: &Path) -> assert_cmd::Command {
    let mut c = ct();
    c.args(["codegen", "--model", s(model), "--out", "-"]);
    c
}

/// No cargo: said so, with how to fix it (it was "cannot run cargo for the
/// generator").
#[test]
fn codegen_without_cargo_says_so() {
    let dir = TempDir::new().unwrap();
    refused(
        codegen(&models().join("drive-3node-fitted.toml"))
            .env_remove("CARGO")
            .env("PATH", dir.path())
            .assert(),
        &[
            "cargo not found on PATH (and CARGO is not set)",
            "https://rustup.rs",
            "set CARGO=/path/to/cargo",
        ],
    );
}

/// No coil-thermal source at `--library`: the path and what is expected.
#[test]
fn codegen_names_a_library_path_without_the_source() {
    let dir = TempDir::new().unwrap();
    let model = models().join("drive-3node-fitted.toml");
    let nowhere = dir.path().join("nowhere");
    refused(
        codegen(&model).args(["--library", s(&nowhere)]).assert(),
        &[
            &format!("--library {}: no such directory", nowhere.display()),
            "expected a directory holding coil-thermal's Cargo.toml",
        ],
    );
    let other = dir.path().join("other");
    fs::create_dir_all(&other).unwrap();
    fs::write(
        other.join("Cargo.toml"),
        "[package]\nname = \"other\"\nversion = \"0.1.0\"\n",
    )
    .unwrap();
    refused(
        codegen(&model).args(["--library", s(&other)]).assert(),
        &[
            "its Cargo.toml is package `other`",
            "expected a directory holding coil-thermal's Cargo.toml",
        ],
    );
}

/// A generator that does not compile (here against a coil-thermal with
/// nothing in it) is told as such, with the crate's directory: by default
/// in the per-user cache, not in the library's `target/`.
#[test]
fn codegen_tells_a_compile_failure_and_builds_outside_the_library() {
    let dir = TempDir::new().unwrap();
    let fake = dir.path().join("fake");
    fs::create_dir_all(fake.join("src")).unwrap();
    fs::write(
        fake.join("Cargo.toml"),
        "[package]\nname = \"coil-thermal\"\nversion = \"0.1.0\"\nedition = \"2021\"\n\n[workspace]\n",
    )
    .unwrap();
    fs::write(fake.join("src/lib.rs"), "").unwrap();
    let cache = dir.path().join("cache");
    let out = codegen(&models().join("drive-3node-fitted.toml"))
        .args(["--library", s(&fake)])
        .env_remove("CARGO_TARGET_DIR")
        .env("XDG_CACHE_HOME", &cache)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    let crates = cache.join("coil-thermal").join("codegen");
    for needle in [
        format!("compiling the generator (in {}", crates.display()),
        format!(
            "against the coil-thermal library at {}",
            fake.canonicalize().unwrap().display()
        ),
        "cargo said:".to_string(),
    ] {
        assert!(stderr.contains(&needle), "no `{needle}` in:\n{stderr}");
    }
    assert!(!stderr.contains("refuses the model"), "{stderr}");
    assert!(
        crates.join("target").is_dir(),
        "built in {}",
        crates.display()
    );
    assert!(
        !fake.join("target").exists(),
        "built in the library's target/"
    );
}

/// The library's builder refusing the model is told apart from a compile
/// failure, with its error and what to change in the model file; each
/// change it names is then accepted.
#[test]
fn codegen_names_the_builders_refusal_with_its_fix() {
    let dir = TempDir::new().unwrap();
    // Two phases, one housing thermocouple, phase b cooled by the ambient
    // alone: a heat bias named on b (`bias_sources`) is one the sensor
    // cannot see at all. (Two phases both under the housing build: they
    // share one heat bias by default.)
    let phases = "name = \"two-phases\"\n\
        [[node]]\nname = \"phase_a\"\ncapacity_j_per_k = 100.0\ncritical_c = 155.0\n\
        [[node]]\nname = \"phase_b\"\ncapacity_j_per_k = 100.0\ncritical_c = 155.0\n\
        [[node]]\nname = \"housing\"\ncapacity_j_per_k = 900.0\n\
        [[boundary]]\nname = \"ambient\"\nvalue_c = 20.0\n\
        [[conductance]]\nbetween = [\"phase_a\", \"housing\"]\ng_w_per_k = 1.0\n\
        [[conductance]]\nbetween = [\"phase_b\", \"ambient\"]\ng_w_per_k = 1.0\n\
        [[conductance]]\nbetween = [\"housing\", \"ambient\"]\ng_w_per_k = 0.5\n\
        [[source]]\nname = \"a\"\nnode = \"phase_a\"\nr0_ohm = 2.0\nalpha_per_k = 0.0039\n\
        [[source]]\nname = \"b\"\nnode = \"phase_b\"\nr0_ohm = 2.0\nalpha_per_k = 0.0039\n\
        [observer]\nsensors = [\"housing\"]\n";
    let model = dir.path().join("phases.toml");
    fs::write(&model, format!("{phases}bias_sources = [\"b\"]\n")).unwrap();
    let out = codegen(&model).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    for needle in [
        "phases.toml: the coil-thermal library's observer builder refuses the model: \
         `steady_state_gain` did not converge",
        "in `[observer] bias_sources`",
        "`[observer] bias_noise_w2_per_s = 0`",
    ] {
        assert!(stderr.contains(needle), "no `{needle}` in:\n{stderr}");
    }
    assert!(!stderr.contains("compiling the generator"), "{stderr}");
    for (name, fix) in [
        (
            "frozen.toml",
            "bias_sources = [\"b\"]\nbias_noise_w2_per_s = 0.0\n",
        ),
        ("one-bias.toml", "bias_sources = [\"a\"]\n"),
    ] {
        let fixed = dir.path().join(name);
        fs::write(&fixed, format!("{phases}{fix}")).unwrap();
        codegen(&fixed)
            .assert()
            .success()
            .stdout(contains("pub const PARTS"));
    }
}

/// The one text of what to change for a builder's refusal: the bias
/// advice only when there are bias states to blame.
#[test]
fn the_build_hint_names_the_fix_for_its_error_only() {
    use coil_thermal::BuildError;
    use coil_thermal_host::codegen::build_hint::observer_build_hint;
    let gain = BuildError::NotConverged {
        name: "steady_state_gain",
    };
    let hint = observer_build_hint(&gain, 1e-3).expect("a hint for the gain");
    assert!(hint.contains("[observer] bias_sources"), "{hint}");
    assert!(hint.contains("bias_noise_w2_per_s = 0"), "{hint}");
    assert_eq!(observer_build_hint(&gain, 0.0), None);
    let unseen = BuildError::Unobservable {
        node: 1,
        sigma_k: 30.0,
    };
    assert!(observer_build_hint(&unseen, 0.0)
        .expect("a hint for an unobservable node")
        .contains("[observer] sensors"));
    assert_eq!(observer_build_hint(&BuildError::Singular, 1e-3), None);
}

/// The host's row-rate filter is gone (the flashed `NetworkObserver` is
/// what `replay --measure` runs): its flags are refused by the parser, by
/// name, never taken and ignored.
#[test]
fn the_row_rate_filters_flags_are_refused() {
    let dir = TempDir::new().unwrap();
    let model = models().join("two-node-coil.toml");
    let trace = dir.path().join("rec.csv");
    fs::write(&trace, "time_s,current,T_housing\n0,1,20\n1,1,20.1\n").unwrap();
    for (flag, value) in [
        ("--disturbance", "coil"),
        ("--disturbance-std-w", "50"),
        ("--disturbance-tau-s", "1800"),
        ("--disturbance-floor-share", "0"),
        ("--boundary-offset", "ambient"),
        ("--boundary-offset-std-k", "2"),
        ("--boundary-offset-tau-s", "7200"),
        ("--boundary-offset-floor-k", "0"),
        ("--gate", "10.83"),
        ("--initial-std-k", "2"),
        ("--noise-half-window-rows", "10"),
        ("--noise-memory-rows", "600"),
    ] {
        refused(
            ct().args(["replay", "--model", s(&model), "--trace", s(&trace)])
                .args(["--measure", "T_housing=housing", flag, value])
                .assert(),
            &[&format!("unexpected argument '{flag}'")],
        );
    }
}

/// A rotor whose conductance to the coolant changes with speed: `replay`
/// runs it open loop on the explicit stepper (no filter).
const SPEED_DEPENDENT: &str = r#"
name = "speed-dependent"
[[node]]
name = "stator"
capacity_j_per_k = 400.0
[[node]]
name = "rotor"
capacity_j_per_k = 300.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["stator", "coolant"]
g_w_per_k = 10.0
[[conductance]]
between = ["rotor", "coolant"]
r_k_per_w = 0.05
[conductance.speed]
column = "speed"
reference = 4000.0
a1 = 0.5
r_exp_k_per_w = 0.2
exp_rate = 1.5
[[source]]
name = "winding"
node = "stator"
input = "current"
r0_ohm = 0.5
alpha_per_k = 0.0039
t_ref_c = 20.0
"#;

/// The filter's noise flags set the firmware's observer; a model run open
/// loop on the explicit stepper has no filter, so they are refused by name
/// rather than dropped (and the same replay without them runs).
#[test]
fn noise_flags_are_refused_where_no_filter_runs() {
    let dir = TempDir::new().unwrap();
    let model = dir.path().join("speed.toml");
    fs::write(&model, SPEED_DEPENDENT).unwrap();
    let trace = dir.path().join("trace.csv");
    let rows: String = (0..20)
        .map(|t| format!("{t},2.0,{}\n", 1000 * (t % 4)))
        .collect();
    fs::write(&trace, format!("time_s,current,speed\n{rows}")).unwrap();
    let replay = || {
        let mut c = ct();
        c.args(["replay", "--model", s(&model), "--trace", s(&trace)]);
        c
    };
    replay().assert().success();
    for (flag, value) in [
        ("--measurement-noise-k", "0.5"),
        ("--process-noise-k2-per-s", "1e-3"),
    ] {
        refused(
            replay().args([flag, value]).assert(),
            &[flag, "explicit stepper"],
        );
    }
}
